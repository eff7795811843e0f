//! Scene files: the TOML format, its validation, the built-in scenes and the initial particles.
//!
//! Every length is in the scene's units (SI in the built-in SI scenes); `h` is the kernel's
//! support radius, so a particle interacts with everything closer than `h`, as in the seed report.

use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Where a scene came from, for error messages.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SceneOrigin {
    BuiltIn(String),
    File(PathBuf),
    Text,
}

impl std::fmt::Display for SceneOrigin {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SceneOrigin::BuiltIn(n) => write!(f, "built-in scene '{n}'"),
            SceneOrigin::File(p) => write!(f, "{}", p.display()),
            SceneOrigin::Text => write!(f, "scene text"),
        }
    }
}

/// A scene that cannot be used: names the file, the field and what is allowed.
#[derive(Debug, thiserror::Error)]
#[error("{origin}: {field}: {message}")]
pub struct SceneError {
    pub origin: String,
    pub field: String,
    pub message: String,
}

fn err(origin: &SceneOrigin, field: impl Into<String>, message: impl Into<String>) -> SceneError {
    SceneError { origin: origin.to_string(), field: field.into(), message: message.into() }
}

/// The built-in scenes: (name, one-line description, TOML text). The same files ship in scenes/.
pub const BUILTIN_SCENES: &[(&str, &str, &str)] = &[
    (
        "seed",
        "the seed report's scene: 3000 particles in an open box, h = 0.1, k = 2, g = 0.23, dt = 0.05",
        include_str!("../scenes/seed.toml"),
    ),
    (
        "dam_break",
        "a 0.4 m x 0.8 m water column collapsing in a closed 1.6 m x 1 m tank (SI, Tait EOS, c0 = 40 m/s)",
        include_str!("../scenes/dam_break.toml"),
    ),
    (
        "hydrostatic",
        "water at rest in a closed tank, settling to hydrostatic pressure (SI, Tait EOS)",
        include_str!("../scenes/hydrostatic.toml"),
    ),
];

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// Short name used in outputs.
    #[serde(default = "default_name")]
    pub name: String,
    #[serde(default)]
    pub description: String,
    /// Seed of the random jitter of fluid particles.
    #[serde(default = "default_seed")]
    pub seed: u64,
    pub domain: Domain,
    pub physics: Physics,
    pub time: Time,
    #[serde(default)]
    pub fluid: Vec<FluidBlock>,
    #[serde(default)]
    pub boundary: Vec<Boundary>,
    /// Camera of rendered frames; default: framed automatically around the tank and fluid.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera: Option<CameraSpec>,
}

/// A perspective camera for rendered frames.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    pub eye: [f64; 3],
    pub target: [f64; 3],
    #[serde(default = "default_up")]
    pub up: [f64; 3],
    /// Vertical field of view in degrees.
    #[serde(default = "default_fov")]
    pub fov_degrees: f64,
}

fn default_up() -> [f64; 3] {
    [0.0, 1.0, 0.0]
}
fn default_fov() -> f64 {
    40.0
}

fn default_name() -> String {
    "scene".into()
}
fn default_seed() -> u64 {
    1
}

/// The simulation domain: an axis-aligned box. A fluid particle that leaves it has escaped.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Domain {
    pub min: [f64; 3],
    pub max: [f64; 3],
}

/// The pressure a wall particle pushes a fluid particle with.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum BoundaryPressure {
    /// The wall mirrors the fluid particle: 2 max(p_i, 0) / rho_i^2 (p_w = p_i, rho_w = rho_i).
    #[default]
    Mirror,
    /// p_i / rho_i^2: the gradient of the elastic energy that the density summation over wall
    /// particles defines, so that walls neither create nor destroy energy (Akinci et al. 2012).
    Consistent,
}

#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Kernel {
    /// Mueller et al. 2003: poly6 density, spiky gradient, viscosity Laplacian.
    Mueller,
    /// Monaghan's cubic spline (support h) with the Morris/Monaghan viscosity term.
    CubicSpline,
}

#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum EquationOfState {
    /// p = k (rho/rho0 - 1), report Eq. 8.
    Linear,
    /// p = k ((rho/rho0)^7 - 1), report Eq. 9 (Tait, Monaghan 1994).
    Tait,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Physics {
    /// Kernel support radius h.
    pub smoothing_length: f64,
    /// Rest density rho0 of the fluid.
    #[serde(default = "default_rest_density")]
    pub rest_density: f64,
    /// Lattice spacing of the fluid particles.
    pub particle_spacing: f64,
    /// Mass of one fluid particle; default rest_density * particle_spacing^3.
    #[serde(default)]
    pub particle_mass: Option<f64>,
    #[serde(default = "default_kernel")]
    pub kernel: Kernel,
    #[serde(default = "default_eos")]
    pub equation_of_state: EquationOfState,
    /// Stiffness k of the equation of state (Pa). Give this or speed_of_sound.
    #[serde(default)]
    pub stiffness: Option<f64>,
    /// Speed of sound c0: sets k = rho0 c0^2 (linear) or rho0 c0^2 / 7 (Tait).
    #[serde(default)]
    pub speed_of_sound: Option<f64>,
    /// Clamp negative pressures to zero (no tensile forces at a free surface).
    #[serde(default)]
    pub clamp_negative_pressure: bool,
    /// Kinematic viscosity nu (m^2/s) at t = 0.
    #[serde(default)]
    pub viscosity: f64,
    /// Changes of viscosity over time, applied from their time on.
    #[serde(default)]
    pub viscosity_schedule: Vec<ViscosityChange>,
    /// Scales the viscosity term between fluid and wall particles: 1 = no-slip, 0 = free slip.
    #[serde(default = "default_boundary_friction")]
    pub boundary_friction: f64,
    /// The wall particles' pressure term (see `BoundaryPressure`).
    #[serde(default)]
    pub boundary_pressure: BoundaryPressure,
    #[serde(default = "default_gravity")]
    pub gravity: [f64; 3],
}

fn default_rest_density() -> f64 {
    1000.0
}
fn default_kernel() -> Kernel {
    Kernel::Mueller
}
fn default_eos() -> EquationOfState {
    EquationOfState::Linear
}
fn default_boundary_friction() -> f64 {
    1.0
}
fn default_gravity() -> [f64; 3] {
    [0.0, -9.81, 0.0]
}

#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ViscosityChange {
    pub time: f64,
    pub viscosity: f64,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Time {
    /// Time step.
    pub dt: f64,
    /// Simulated time at which `wgsph run` stops by default.
    pub end_time: f64,
    /// Adaptive time stepping: dt from the CFL, force and viscous conditions every step.
    #[serde(default, skip_serializing_if = "is_false")]
    pub adaptive: bool,
    /// C_cfl in dt <= C_cfl h / (c0 + |v|max) (adaptive only).
    #[serde(default = "default_cfl_number")]
    pub cfl_number: f64,
    /// C_f in dt <= C_f sqrt(h / |a|max) (adaptive only).
    #[serde(default = "default_force_number")]
    pub force_number: f64,
    /// C_visc in dt <= C_visc h^2 / nu (adaptive only).
    #[serde(default = "default_viscous_number")]
    pub viscous_number: f64,
    /// Smallest adaptive dt; default dt / 1000.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dt_min: Option<f64>,
    /// Largest adaptive dt; default dt.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dt_max: Option<f64>,
    /// Rebuild the neighbour grid every this many steps (1 or 2; between rebuilds particles
    /// keep the cells of the last rebuild).
    #[serde(default = "default_rebuild_every")]
    pub neighbour_rebuild_every: u32,
}

impl Time {
    /// A fixed time step of `dt` up to `end_time`, every other setting at its default.
    pub fn fixed(dt: f64, end_time: f64) -> Time {
        Time {
            dt,
            end_time,
            adaptive: false,
            cfl_number: default_cfl_number(),
            force_number: default_force_number(),
            viscous_number: default_viscous_number(),
            dt_min: None,
            dt_max: None,
            neighbour_rebuild_every: default_rebuild_every(),
        }
    }
}

fn is_false(b: &bool) -> bool {
    !*b
}
fn default_cfl_number() -> f64 {
    0.25
}
fn default_force_number() -> f64 {
    0.25
}
fn default_viscous_number() -> f64 {
    0.125
}
fn default_rebuild_every() -> u32 {
    1
}

/// Adaptive time stepping, resolved: dt = clamp(min(C_cfl h / (c0 + |v|max),
/// C_f sqrt(h / |a|max), C_visc h^2 / nu), dt_min, dt_max) (Monaghan 1992; Morris et al. 1997
/// for the viscous condition).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdaptiveDt {
    pub cfl_number: f64,
    pub force_number: f64,
    pub viscous_number: f64,
    pub dt_min: f64,
    pub dt_max: f64,
}

impl AdaptiveDt {
    /// The step for the largest speed and acceleration: the same formula on the CPU and in
    /// wgsl/integrate.wgsl `choose_dt`.
    pub fn dt(&self, h: f64, c0: f64, max_speed: f64, max_accel: f64, nu: f64) -> f64 {
        let mut dt = self.cfl_number * h / (c0 + max_speed);
        if max_accel > 0.0 {
            dt = dt.min(self.force_number * (h / max_accel).sqrt());
        }
        if nu > 0.0 {
            dt = dt.min(self.viscous_number * h * h / nu);
        }
        // NaN (a blown-up state) falls to dt_min; the health check reports it.
        if dt.is_nan() { self.dt_min } else { dt.clamp(self.dt_min, self.dt_max) }
    }
}

/// A box of fluid filled on a lattice of the physics spacing, with seeded random offsets.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct FluidBlock {
    pub min: [f64; 3],
    pub max: [f64; 3],
    /// Random offset of each particle, as a fraction of the spacing (uniform in +-jitter).
    #[serde(default = "default_jitter")]
    pub jitter: f64,
    #[serde(default)]
    pub velocity: [f64; 3],
}

fn default_jitter() -> f64 {
    0.05
}

/// A solid boundary.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum Boundary {
    /// A tank of wall particles around the box [min, max]; the walls lie outside the box.
    Container {
        min: [f64; 3],
        max: [f64; 3],
        #[serde(default = "default_true")]
        open_top: bool,
        #[serde(flatten)]
        walls: WallParticles,
    },
    /// A solid obstacle: wall particles filling a shell inside [min, max].
    Box {
        min: [f64; 3],
        max: [f64; 3],
        #[serde(flatten)]
        walls: WallParticles,
    },
    /// An infinite analytic plane; fluid stays on the side the normal points to.
    Plane {
        point: [f64; 3],
        normal: [f64; 3],
        /// Fraction of the normal speed kept on impact (0 = inelastic).
        #[serde(default)]
        restitution: f64,
    },
}

fn default_true() -> bool {
    true
}

/// How a particle boundary is sampled.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, Default)]
#[serde(deny_unknown_fields)]
pub struct WallParticles {
    /// Layers of particles; default ceil(h / spacing), enough that a fluid particle at the wall
    /// sees a full kernel support of wall.
    #[serde(default)]
    pub layers: Option<u32>,
    /// Lattice spacing of the wall particles; default the fluid spacing.
    #[serde(default)]
    pub spacing: Option<f64>,
    /// Rest density of the wall particles (their mass is rest_density * spacing^3); default the
    /// fluid's. The seed report uses 2500 so that walls push harder.
    #[serde(default)]
    pub rest_density: Option<f64>,
}

/// Most particles a scene may hold: indices are u32 on the GPU and the CPU.
pub const MAX_PARTICLES: u64 = 1 << 31;
/// Most grid cells a scene may have.
pub const MAX_CELLS: u64 = 1 << 30;
/// Host bytes per particle the CPU path needs at most (f64 state, sort buffers, snapshot copy).
pub const CPU_BYTES_PER_PARTICLE: u64 = 200;

/// Plane in the form normal . x = offset, with a unit normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    pub normal: [f64; 3],
    pub offset: f64,
    pub restitution: f64,
}

/// A solid region (inside of an obstacle or of a tank's walls) that fluid must never enter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolidRegion {
    pub min: [f64; 3],
    pub max: [f64; 3],
}

/// The physical and numerical constants of a scene, resolved (defaults filled, k derived).
#[derive(Clone, Debug, PartialEq)]
pub struct Params {
    pub h: f64,
    pub rest_density: f64,
    pub fluid_mass: f64,
    pub kernel: Kernel,
    pub eos: EquationOfState,
    pub stiffness: f64,
    pub clamp_negative_pressure: bool,
    /// (start time, nu) pairs in time order; the first starts at 0.
    pub viscosity: Vec<(f64, f64)>,
    pub boundary_friction: f64,
    pub boundary_pressure: BoundaryPressure,
    pub gravity: [f64; 3],
    pub dt: f64,
    pub end_time: f64,
    /// Adaptive time stepping, when the scene asks for it (`dt` is then its largest step).
    pub adaptive: Option<AdaptiveDt>,
    /// Rebuild the neighbour grid every this many steps.
    pub rebuild_every: u32,
    pub domain_min: [f64; 3],
    pub domain_max: [f64; 3],
    pub planes: Vec<Plane>,
    pub grid: Grid,
}

impl Params {
    /// Kinematic viscosity in force during the step that starts at `step` (evaluated at the
    /// step's midpoint so that a change time on a step boundary is never a float tie).
    pub fn viscosity_at_step(&self, step: u64) -> f64 {
        let t = (step as f64 + 0.5) * self.dt;
        viscosity_at(&self.viscosity, t)
    }
    /// Whether any viscosity of the scene (its schedule included) is above zero.
    pub fn uses_viscosity(&self) -> bool {
        self.viscosity.iter().any(|&(_, nu)| nu > 0.0)
    }
    pub fn uses_gravity(&self) -> bool {
        self.gravity.iter().any(|&g| g != 0.0)
    }
    /// The speed of sound implied by the equation of state: c0^2 = dp/drho at rho0.
    pub fn speed_of_sound(&self) -> f64 {
        match self.eos {
            EquationOfState::Linear => (self.stiffness / self.rest_density).sqrt(),
            EquationOfState::Tait => (7.0 * self.stiffness / self.rest_density).sqrt(),
        }
    }
}

/// nu at time t from a (start time, nu) schedule.
pub fn viscosity_at(schedule: &[(f64, f64)], t: f64) -> f64 {
    let mut nu = schedule.first().map(|s| s.1).unwrap_or(0.0);
    for &(start, value) in schedule {
        if t >= start {
            nu = value;
        }
    }
    nu
}

/// The uniform neighbour grid over the domain, cell size h (report Sec. V).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid {
    pub origin: [f64; 3],
    pub cell_size: f64,
    pub dims: [u32; 3],
}

impl Grid {
    pub fn cell_count(&self) -> usize {
        self.dims.iter().map(|&d| d as usize).product()
    }
    /// Integer cell coordinates of a point, clamped into the grid so that a particle outside the
    /// domain still has a valid cell (it is counted as escaped elsewhere).
    pub fn cell_coords(&self, p: [f64; 3]) -> [u32; 3] {
        let mut c = [0u32; 3];
        for a in 0..3 {
            let f = ((p[a] - self.origin[a]) / self.cell_size).floor();
            let max = (self.dims[a] - 1) as f64;
            c[a] = if f.is_nan() { 0.0 } else { f.clamp(0.0, max) } as u32;
        }
        c
    }
    pub fn cell_key(&self, c: [u32; 3]) -> u32 {
        c[0] + self.dims[0] * (c[1] + self.dims[1] * c[2])
    }
}

/// Particles of a scene at t = 0.
#[derive(Clone, Debug, Default)]
pub struct InitialState {
    pub fluid_positions: Vec<[f64; 3]>,
    pub fluid_velocities: Vec<[f64; 3]>,
    pub wall_positions: Vec<[f64; 3]>,
    pub wall_masses: Vec<f64>,
}

impl Scene {
    /// A built-in scene by name.
    pub fn builtin(name: &str) -> Option<Scene> {
        BUILTIN_SCENES.iter().find(|s| s.0 == name).map(|s| {
            Scene::from_toml_str(s.2, &SceneOrigin::BuiltIn(name.into()))
                .expect("built-in scenes are valid (tested)")
        })
    }

    /// A built-in name, a path to a TOML file, or a SPlisHSPlasH scene (`*.json`).
    pub fn load(name_or_path: &str) -> Result<Scene, SceneError> {
        if let Some(s) = Scene::builtin(name_or_path) {
            return Ok(s);
        }
        let path = Path::new(name_or_path);
        let origin = SceneOrigin::File(path.to_path_buf());
        if !path.exists() {
            let names: Vec<_> = BUILTIN_SCENES.iter().map(|s| s.0).collect();
            return Err(err(
                &origin,
                "scene",
                format!("no such file, and not a built-in scene (built-in: {})", names.join(", ")),
            ));
        }
        let text = std::fs::read_to_string(path)
            .map_err(|e| err(&origin, "scene", format!("cannot read the file: {e}")))?;
        if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("json")) {
            let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            return crate::splishsplash::scene_from_json(&text, &name, &origin);
        }
        Scene::from_toml_str(&text, &origin)
    }

    /// Parses and validates a scene.
    pub fn from_toml_str(text: &str, origin: &SceneOrigin) -> Result<Scene, SceneError> {
        let scene: Scene = toml::from_str(text).map_err(|e| {
            let field = e
                .span()
                .map(|s| {
                    let line = text[..s.start.min(text.len())].lines().count().max(1);
                    format!("line {line}")
                })
                .unwrap_or_else(|| "toml".into());
            err(origin, field, e.message().to_string())
        })?;
        scene.validate(origin)?;
        Ok(scene)
    }

    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).expect("a scene serialises")
    }

    /// Checks every field against what is allowed, before any work.
    pub fn validate(&self, origin: &SceneOrigin) -> Result<(), SceneError> {
        let positive = |field: &str, v: f64| -> Result<(), SceneError> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(err(origin, field, format!("is {v}; must be a finite number > 0")))
            }
        };
        let finite3 = |field: &str, v: [f64; 3]| -> Result<(), SceneError> {
            if v.iter().all(|c| c.is_finite()) {
                Ok(())
            } else {
                Err(err(origin, field, format!("is {v:?}; every component must be finite")))
            }
        };
        let ordered = |field: &str, min: [f64; 3], max: [f64; 3]| -> Result<(), SceneError> {
            finite3(&format!("{field}.min"), min)?;
            finite3(&format!("{field}.max"), max)?;
            if (0..3).all(|a| max[a] > min[a]) {
                Ok(())
            } else {
                Err(err(origin, field, format!("min {min:?} must be below max {max:?} on every axis")))
            }
        };
        let p = &self.physics;
        positive("physics.smoothing_length", p.smoothing_length)?;
        positive("physics.rest_density", p.rest_density)?;
        positive("physics.particle_spacing", p.particle_spacing)?;
        if let Some(m) = p.particle_mass {
            positive("physics.particle_mass", m)?;
        }
        match (p.stiffness, p.speed_of_sound) {
            (Some(k), None) => positive("physics.stiffness", k)?,
            (None, Some(c)) => positive("physics.speed_of_sound", c)?,
            _ => {
                return Err(err(origin, "physics.stiffness", "give exactly one of stiffness and speed_of_sound"))
            }
        }
        if !(p.viscosity.is_finite() && p.viscosity >= 0.0) {
            return Err(err(origin, "physics.viscosity", format!("is {}; must be finite and >= 0", p.viscosity)));
        }
        let mut last = 0.0;
        for (i, c) in p.viscosity_schedule.iter().enumerate() {
            let f = format!("physics.viscosity_schedule[{i}]");
            if !(c.time.is_finite() && c.time >= last) {
                return Err(err(origin, format!("{f}.time"), format!("is {}; times must be finite, >= 0 and increasing", c.time)));
            }
            if !(c.viscosity.is_finite() && c.viscosity >= 0.0) {
                return Err(err(origin, format!("{f}.viscosity"), format!("is {}; must be finite and >= 0", c.viscosity)));
            }
            last = c.time;
        }
        if !(p.boundary_friction.is_finite() && p.boundary_friction >= 0.0) {
            return Err(err(origin, "physics.boundary_friction", format!("is {}; must be finite and >= 0", p.boundary_friction)));
        }
        finite3("physics.gravity", p.gravity)?;
        if let Some(c) = &self.camera {
            finite3("camera.eye", c.eye)?;
            finite3("camera.target", c.target)?;
            finite3("camera.up", c.up)?;
            let d = [c.target[0] - c.eye[0], c.target[1] - c.eye[1], c.target[2] - c.eye[2]];
            let dn = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            if dn == 0.0 {
                return Err(err(origin, "camera.target", format!("is {:?}, the same point as camera.eye; they must differ", c.target)));
            }
            let un = (c.up[0] * c.up[0] + c.up[1] * c.up[1] + c.up[2] * c.up[2]).sqrt();
            let cross = [d[1] * c.up[2] - d[2] * c.up[1], d[2] * c.up[0] - d[0] * c.up[2], d[0] * c.up[1] - d[1] * c.up[0]];
            let cn = (cross[0] * cross[0] + cross[1] * cross[1] + cross[2] * cross[2]).sqrt();
            if !(un > 0.0 && cn > 1e-6 * dn * un) {
                return Err(err(origin, "camera.up", format!("is {:?}; must be non-zero and not parallel to the viewing direction", c.up)));
            }
            if !(c.fov_degrees.is_finite() && c.fov_degrees > 1.0 && c.fov_degrees < 170.0) {
                return Err(err(origin, "camera.fov_degrees", format!("is {}; must be between 1 and 170", c.fov_degrees)));
            }
        }
        positive("time.dt", self.time.dt)?;
        positive("time.end_time", self.time.end_time)?;
        self.validate_time_options(origin)?;
        ordered("domain", self.domain.min, self.domain.max)?;
        let inside = |q: [f64; 3]| (0..3).all(|a| q[a] >= self.domain.min[a] && q[a] <= self.domain.max[a]);

        if self.fluid.is_empty() {
            return Err(err(origin, "fluid", "the scene has no fluid block; add at least one [[fluid]] with min and max"));
        }
        for (i, b) in self.fluid.iter().enumerate() {
            let f = format!("fluid[{i}]");
            ordered(&f, b.min, b.max)?;
            if !inside(b.min) || !inside(b.max) {
                return Err(err(origin, &f, format!(
                    "block {:?}..{:?} is not inside the domain {:?}..{:?}", b.min, b.max, self.domain.min, self.domain.max)));
            }
            if !(b.jitter.is_finite() && (0.0..0.5).contains(&b.jitter)) {
                return Err(err(origin, format!("{f}.jitter"), format!("is {}; must be in [0, 0.5)", b.jitter)));
            }
            finite3(&format!("{f}.velocity"), b.velocity)?;
            if lattice_counts(b.min, b.max, p.particle_spacing).iter().any(|&n| n == 0) {
                return Err(err(origin, &f, format!("is thinner than one particle spacing ({}) on some axis", p.particle_spacing)));
            }
        }
        for (i, b) in self.boundary.iter().enumerate() {
            let f = format!("boundary[{i}]");
            match b {
                Boundary::Container { min, max, walls, .. } | Boundary::Box { min, max, walls } => {
                    ordered(&f, *min, *max)?;
                    let s = walls.spacing.unwrap_or(p.particle_spacing);
                    positive(&format!("{f}.spacing"), s)?;
                    if let Some(rd) = walls.rest_density {
                        positive(&format!("{f}.rest_density"), rd)?;
                    }
                    if walls.layers == Some(0) {
                        return Err(err(origin, format!("{f}.layers"), "is 0; must be at least 1"));
                    }
                    let (lo, hi) = self.wall_span(b).expect("a container or a box");
                    if !inside(lo) || !inside(hi) {
                        return Err(err(origin, &f, format!(
                            "its wall particles span {lo:?}..{hi:?}, outside the domain {:?}..{:?}; enlarge the domain",
                            self.domain.min, self.domain.max)));
                    }
                }
                Boundary::Plane { point, normal, restitution } => {
                    finite3(&format!("{f}.point"), *point)?;
                    finite3(&format!("{f}.normal"), *normal)?;
                    if normal.iter().map(|c| c * c).sum::<f64>() < 1e-12 {
                        return Err(err(origin, format!("{f}.normal"), "is zero; must be a non-zero vector"));
                    }
                    if !(restitution.is_finite() && (0.0..=1.0).contains(restitution)) {
                        return Err(err(origin, format!("{f}.restitution"), format!("is {restitution}; must be in [0, 1]")));
                    }
                }
            }
        }
        if self.boundary.iter().filter(|b| matches!(b, Boundary::Plane { .. })).count() > MAX_PLANES {
            return Err(err(origin, "boundary", format!("has more than {MAX_PLANES} planes")));
        }
        let grid = self.grid();
        let cells: u64 = grid.dims.iter().map(|&d| d as u64).product();
        if cells > MAX_CELLS {
            return Err(err(origin, "domain", format!(
                "needs {cells} grid cells of size h = {}; at most {MAX_CELLS} are allowed (shrink the domain or grow h)",
                p.smoothing_length)));
        }
        let count = self.estimated_particle_count();
        if count > MAX_PARTICLES {
            return Err(err(origin, "fluid", format!("would create {count} particles; at most {MAX_PARTICLES} are allowed")));
        }
        if let Some(avail) = available_memory_bytes() {
            let need = count * CPU_BYTES_PER_PARTICLE + cells * 8;
            if need > avail {
                return Err(err(origin, "fluid", format!(
                    "{count} particles (fluid and walls) and {cells} cells need about {} MiB of host memory; {} MiB are available",
                    need >> 20, avail >> 20)));
            }
        }
        Ok(())
    }

    /// Adaptive dt and the neighbour rebuild interval.
    fn validate_time_options(&self, origin: &SceneOrigin) -> Result<(), SceneError> {
        let t = &self.time;
        if !(1..=2).contains(&t.neighbour_rebuild_every) {
            return Err(err(origin, "time.neighbour_rebuild_every", format!("is {}; must be 1 or 2", t.neighbour_rebuild_every)));
        }
        for (field, v) in [("time.cfl_number", t.cfl_number), ("time.force_number", t.force_number), ("time.viscous_number", t.viscous_number)] {
            if !(v.is_finite() && v > 0.0 && v <= 1.0) {
                return Err(err(origin, field, format!("is {v}; must be in (0, 1]")));
            }
        }
        for (field, v) in [("time.dt_min", t.dt_min), ("time.dt_max", t.dt_max)] {
            if let Some(v) = v {
                if !(v.is_finite() && v > 0.0) {
                    return Err(err(origin, field, format!("is {v}; must be a finite number > 0")));
                }
            }
        }
        if !t.adaptive && (t.dt_min.is_some() || t.dt_max.is_some()) {
            return Err(err(origin, "time.dt_min", "dt_min and dt_max need adaptive = true"));
        }
        if t.adaptive {
            let (lo, hi) = (t.dt_min.unwrap_or(t.dt * 1e-3), t.dt_max.unwrap_or(t.dt));
            if lo > hi {
                return Err(err(origin, "time.dt_min", format!("is {lo}, above dt_max {hi}; must be <= dt_max")));
            }
            if !self.physics.viscosity_schedule.is_empty() {
                return Err(err(
                    origin,
                    "physics.viscosity_schedule",
                    "cannot be combined with time.adaptive = true (the GPU picks its step itself, so the host cannot time a viscosity change); use one viscosity or a fixed dt",
                ));
            }
        }
        Ok(())
    }

    fn wall_layers(&self, walls: &WallParticles) -> u32 {
        let s = walls.spacing.unwrap_or(self.physics.particle_spacing);
        walls.layers.unwrap_or(((self.physics.smoothing_length / s) - 1e-9).ceil().max(1.0) as u32)
    }

    /// The same scene at another resolution: particle and wall spacings, h and dt multiplied by
    /// `factor` (dt with h keeps the CFL number), so the particle count changes by 1/factor^3.
    pub fn with_resolution(&self, factor: f64) -> Scene {
        let mut s = self.clone();
        s.physics.particle_spacing *= factor;
        s.physics.smoothing_length *= factor;
        s.time.dt *= factor;
        s.time.dt_min = s.time.dt_min.map(|d| d * factor);
        s.time.dt_max = s.time.dt_max.map(|d| d * factor);
        if let Some(m) = &mut s.physics.particle_mass {
            *m *= factor.powi(3);
        }
        for b in &mut s.boundary {
            if let Boundary::Container { walls, .. } | Boundary::Box { walls, .. } = b {
                if let Some(sp) = &mut walls.spacing {
                    *sp *= factor;
                }
            }
        }
        // Coarser wall layers are thicker: the domain grows where they would stick out of it.
        for b in &s.boundary {
            if let Some((lo, hi)) = s.wall_span(b) {
                for a in 0..3 {
                    s.domain.min[a] = s.domain.min[a].min(lo[a]);
                    s.domain.max[a] = s.domain.max[a].max(hi[a]);
                }
            }
        }
        s
    }

    /// The region a container's or a box's wall particles occupy: a container's walls lie
    /// outside its faces, `layers` spacings deep; a box's inside it.
    pub fn wall_span(&self, b: &Boundary) -> Option<([f64; 3], [f64; 3])> {
        match b {
            Boundary::Container { min, max, walls, .. } => {
                let d = self.wall_layers(walls) as f64 * walls.spacing.unwrap_or(self.physics.particle_spacing);
                Some(([min[0] - d, min[1] - d, min[2] - d], [max[0] + d, max[1] + d, max[2] + d]))
            }
            Boundary::Box { min, max, .. } => Some((*min, *max)),
            _ => None,
        }
    }

    /// The scene refined or coarsened to about `fluid_particles` fluid particles.
    pub fn with_fluid_particles(&self, fluid_particles: u64) -> Scene {
        let now = self.fluid_particle_count().max(1) as f64;
        self.with_resolution((now / fluid_particles.max(1) as f64).cbrt())
    }

    /// Fluid particles of the scene, counted from the lattice sizes without creating them.
    pub fn fluid_particle_count(&self) -> u64 {
        let s = self.physics.particle_spacing;
        self.fluid.iter().map(|b| lattice_counts(b.min, b.max, s).iter().product::<u64>()).sum()
    }

    /// Particle count (fluid and walls, walls over-estimated by the full shell of their box,
    /// top included) computed from the lattice sizes, without creating the particles.
    pub fn estimated_particle_count(&self) -> u64 {
        let s = self.physics.particle_spacing;
        let mut n = self.fluid_particle_count();
        for b in &self.boundary {
            if let Boundary::Container { min, max, walls, .. } | Boundary::Box { min, max, walls } = b {
                let ws = walls.spacing.unwrap_or(s);
                let l = self.wall_layers(walls) as f64 * ws;
                let (lo, hi) = ([min[0] - l, min[1] - l, min[2] - l], [max[0] + l, max[1] + l, max[2] + l]);
                let outer = lattice_counts(lo, hi, ws).iter().product::<u64>();
                let inner = lattice_counts(*min, *max, ws).iter().map(|&c| c.saturating_sub(2)).product::<u64>();
                n += outer.saturating_sub(inner);
            }
        }
        n
    }

    pub fn grid(&self) -> Grid {
        let h = self.physics.smoothing_length;
        let mut dims = [1u32; 3];
        for a in 0..3 {
            let n = ((self.domain.max[a] - self.domain.min[a]) / h).ceil().max(1.0);
            dims[a] = n.min(u32::MAX as f64) as u32;
        }
        Grid { origin: self.domain.min, cell_size: h, dims }
    }

    /// The resolved constants of the scene.
    pub fn params(&self) -> Params {
        let p = &self.physics;
        let stiffness = match (p.stiffness, p.speed_of_sound) {
            (Some(k), _) => k,
            (None, Some(c)) => match p.equation_of_state {
                EquationOfState::Linear => p.rest_density * c * c,
                EquationOfState::Tait => p.rest_density * c * c / 7.0,
            },
            (None, None) => unreachable!("validated"),
        };
        let mut viscosity = vec![(0.0, p.viscosity)];
        viscosity.extend(p.viscosity_schedule.iter().map(|c| (c.time, c.viscosity)));
        let planes = self
            .boundary
            .iter()
            .filter_map(|b| match b {
                Boundary::Plane { point, normal, restitution } => {
                    let len = normal.iter().map(|c| c * c).sum::<f64>().sqrt();
                    let n = [normal[0] / len, normal[1] / len, normal[2] / len];
                    let offset = n[0] * point[0] + n[1] * point[1] + n[2] * point[2];
                    Some(Plane { normal: n, offset, restitution: *restitution })
                }
                _ => None,
            })
            .collect();
        Params {
            h: p.smoothing_length,
            rest_density: p.rest_density,
            fluid_mass: p.particle_mass.unwrap_or(p.rest_density * p.particle_spacing.powi(3)),
            kernel: p.kernel,
            eos: p.equation_of_state,
            stiffness,
            clamp_negative_pressure: p.clamp_negative_pressure,
            viscosity,
            boundary_friction: p.boundary_friction,
            boundary_pressure: p.boundary_pressure,
            gravity: p.gravity,
            dt: self.time.dt,
            end_time: self.time.end_time,
            adaptive: self.time.adaptive.then(|| AdaptiveDt {
                cfl_number: self.time.cfl_number,
                force_number: self.time.force_number,
                viscous_number: self.time.viscous_number,
                dt_min: self.time.dt_min.unwrap_or(self.time.dt * 1e-3),
                dt_max: self.time.dt_max.unwrap_or(self.time.dt),
            }),
            rebuild_every: self.time.neighbour_rebuild_every,
            domain_min: self.domain.min,
            domain_max: self.domain.max,
            planes,
            grid: self.grid(),
        }
    }

    /// Regions fluid must never enter: the wall shells of containers and the obstacle boxes.
    /// The box worth looking at: the solids and the fluid blocks, within the domain (the
    /// domain alone when the scene has neither).
    pub fn view_bounds(&self) -> ([f64; 3], [f64; 3]) {
        let mut boxes: Vec<([f64; 3], [f64; 3])> = self.solid_regions().iter().map(|r| (r.min, r.max)).collect();
        boxes.extend(self.fluid.iter().map(|f| (f.min, f.max)));
        if boxes.is_empty() {
            return (self.domain.min, self.domain.max);
        }
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for (a, b) in boxes {
            for k in 0..3 {
                lo[k] = lo[k].min(a[k]).max(self.domain.min[k]);
                hi[k] = hi[k].max(b[k]).min(self.domain.max[k]);
            }
        }
        (lo, hi)
    }

    /// Lattice spacing of the wall particles (the smallest over the particle boundaries).
    pub fn wall_spacing(&self) -> f64 {
        self.boundary
            .iter()
            .filter_map(|b| match b {
                Boundary::Container { walls, .. } | Boundary::Box { walls, .. } => Some(walls.spacing.unwrap_or(self.physics.particle_spacing)),
                Boundary::Plane { .. } => None,
            })
            .reduce(f64::min)
            .unwrap_or(self.physics.particle_spacing)
    }

    pub fn solid_regions(&self) -> Vec<SolidRegion> {
        let mut out = Vec::new();
        for b in &self.boundary {
            match b {
                Boundary::Box { min, max, .. } => out.push(SolidRegion { min: *min, max: *max }),
                Boundary::Container { min, max, open_top, walls } => {
                    let s = walls.spacing.unwrap_or(self.physics.particle_spacing);
                    let l = self.wall_layers(walls) as f64 * s;
                    let top = if *open_top { max[1] } else { max[1] + l };
                    let slab = |a: usize, lo: f64, hi: f64| {
                        let mut r = SolidRegion { min: [min[0] - l, min[1] - l, min[2] - l], max: [max[0] + l, top, max[2] + l] };
                        r.min[a] = lo;
                        r.max[a] = hi;
                        r
                    };
                    out.push(slab(0, min[0] - l, min[0]));
                    out.push(slab(0, max[0], max[0] + l));
                    out.push(slab(1, min[1] - l, min[1]));
                    if !*open_top {
                        out.push(slab(1, max[1], max[1] + l));
                    }
                    out.push(slab(2, min[2] - l, min[2]));
                    out.push(slab(2, max[2], max[2] + l));
                }
                Boundary::Plane { .. } => {}
            }
        }
        out
    }

    /// The particles at t = 0: fluid on jittered lattices, walls on regular lattices.
    pub fn initial_state(&self) -> InitialState {
        let s = self.physics.particle_spacing;
        let mut rng = rand_pcg::Pcg64::seed_from_u64(self.seed);
        let mut st = InitialState::default();
        for b in &self.fluid {
            let j = b.jitter * s;
            for q in lattice(b.min, b.max, s) {
                let mut q = q;
                if j > 0.0 {
                    for c in q.iter_mut() {
                        *c += rng.random_range(-j..=j);
                    }
                }
                st.fluid_positions.push(q);
                st.fluid_velocities.push(b.velocity);
            }
        }
        for b in &self.boundary {
            let (min, max, walls, open_top, hollow_box) = match b {
                Boundary::Container { min, max, walls, open_top } => (min, max, walls, *open_top, false),
                Boundary::Box { min, max, walls } => (min, max, walls, false, true),
                Boundary::Plane { .. } => continue,
            };
            let ws = walls.spacing.unwrap_or(s);
            let l = self.wall_layers(walls) as f64 * ws;
            let mass = walls.rest_density.unwrap_or(self.physics.rest_density) * ws.powi(3);
            let inner = |q: &[f64; 3], lo: [f64; 3], hi: [f64; 3]| (0..3).all(|a| q[a] > lo[a] && q[a] < hi[a]);
            if hollow_box {
                // Obstacle: a shell of `layers` inside its faces; the core is never reached.
                let lo = [min[0] + l, min[1] + l, min[2] + l];
                let hi = [max[0] - l, max[1] - l, max[2] - l];
                for q in lattice(*min, *max, ws) {
                    if !inner(&q, lo, hi) {
                        st.wall_positions.push(q);
                        st.wall_masses.push(mass);
                    }
                }
            } else {
                let lo = [min[0] - l, min[1] - l, min[2] - l];
                let top = if open_top { max[1] } else { max[1] + l };
                let hi = [max[0] + l, top, max[2] + l];
                // The walls' first layer sits half a spacing outside the container's faces.
                let cavity_hi = [max[0], if open_top { f64::INFINITY } else { max[1] }, max[2]];
                for q in lattice(lo, hi, ws) {
                    if !inner(&q, *min, cavity_hi) {
                        st.wall_positions.push(q);
                        st.wall_masses.push(mass);
                    }
                }
            }
        }
        st
    }
}

/// Most analytic planes a scene may have (they live in the GPU's parameter block).
pub const MAX_PLANES: usize = 8;

fn lattice_counts(min: [f64; 3], max: [f64; 3], s: f64) -> [u64; 3] {
    // A small tolerance so that a block an exact multiple of s wide gets that many layers.
    let mut n = [0u64; 3];
    for a in 0..3 {
        n[a] = ((max[a] - min[a]) / s + 1e-6).floor().max(0.0) as u64;
    }
    n
}

/// Points at min + (i + 0.5) s, filling [min, max] on every axis; x runs fastest.
fn lattice(min: [f64; 3], max: [f64; 3], s: f64) -> impl Iterator<Item = [f64; 3]> {
    let n = lattice_counts(min, max, s);
    (0..n[2]).flat_map(move |k| {
        (0..n[1]).flat_map(move |j| {
            (0..n[0]).map(move |i| {
                [
                    min[0] + (i as f64 + 0.5) * s,
                    min[1] + (j as f64 + 0.5) * s,
                    min[2] + (k as f64 + 0.5) * s,
                ]
            })
        })
    })
}

/// Host memory available to this process, where the platform tells.
pub fn available_memory_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}
