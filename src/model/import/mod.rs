//! Loading a scene by name: a built-in scene, a wgsph TOML file, or a file of another
//! simulator's format, chosen by its extension from [`IMPORTERS`].

pub mod splishsplash;

use super::builtin::BUILTIN_SCENES;
use super::scene::{err, Scene, SceneError, SceneOrigin};
use std::path::Path;

/// A reader of another simulator's scene format: the file's text, the scene's name (the file
/// stem) and where it came from, for error messages. Besides the scene it returns its notes:
/// one line for each setting it imported as the nearest wgsph has (a caller shows them).
pub type Importer = fn(text: &str, name: &str, origin: &SceneOrigin) -> Result<(Scene, Vec<String>), SceneError>;

/// The foreign formats, by file extension (compared without regard to case).
pub const IMPORTERS: &[(&str, Importer)] = &[("json", splishsplash::scene_from_json)];

impl Scene {
    /// A built-in name, a path to a TOML file, or a file of a format in [`IMPORTERS`]
    /// (a SPlisHSPlasH scene, `*.json`).
    pub fn load(name_or_path: &str) -> Result<Scene, SceneError> {
        Scene::load_noting(name_or_path).map(|(scene, _)| scene)
    }

    /// [`Scene::load`], with the notes of an import (what it imported as the nearest wgsph
    /// has; none for a wgsph scene).
    pub fn load_noting(name_or_path: &str) -> Result<(Scene, Vec<String>), SceneError> {
        if let Some(s) = Scene::builtin(name_or_path) {
            return Ok((s, Vec::new()));
        }
        let path = Path::new(name_or_path);
        let origin = SceneOrigin::File(path.to_path_buf());
        if !path.exists() {
            let names: Vec<_> = BUILTIN_SCENES.iter().map(|s| s.0).collect();
            return Err(err(&origin, "scene", format!("no such file, and not a built-in scene (built-in: {})", names.join(", "))));
        }
        let text = std::fs::read_to_string(path).map_err(|e| err(&origin, "scene", format!("cannot read the file: {e}")))?;
        let extension = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
        if let Some((_, import)) = IMPORTERS.iter().find(|(ext, _)| *ext == extension) {
            let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            return import(&text, &name, &origin);
        }
        Ok((Scene::from_toml_str(&text, &origin)?, Vec::new()))
    }
}
