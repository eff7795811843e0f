//! The built-in scenes, whose TOML files ship in scenes/.

use super::scene::{Scene, SceneOrigin};

/// The built-in scenes: (name, one-line description, TOML text). The same files ship in scenes/.
pub const BUILTIN_SCENES: &[(&str, &str, &str)] = &[
    (
        "seed",
        "the seed report's scene: 3000 particles in an open box, h = 0.1, k = 2, g = 0.23, dt = 0.05",
        include_str!("../../scenes/seed.toml"),
    ),
    (
        "dam_break",
        "a 0.4 m x 0.8 m water column collapsing in a closed 1.6 m x 1 m tank (SI, Tait EOS, c0 = 40 m/s)",
        include_str!("../../scenes/dam_break.toml"),
    ),
    (
        "hydrostatic",
        "water at rest in a closed tank, settling to hydrostatic pressure (SI, Tait EOS)",
        include_str!("../../scenes/hydrostatic.toml"),
    ),
];

impl Scene {
    /// A built-in scene by name.
    pub fn builtin(name: &str) -> Option<Scene> {
        BUILTIN_SCENES.iter().find(|s| s.0 == name).map(|s| {
            Scene::from_toml_str(s.2, &SceneOrigin::BuiltIn(name.into()))
                .expect("built-in scenes are valid (tested)")
        })
    }

}
