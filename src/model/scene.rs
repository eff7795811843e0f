//! Scene files: the TOML schema of a scene and its loading and saving.
//!
//! Every length is in the scene's units (SI in the built-in SI scenes); `h` is the kernel's
//! support radius, so a particle interacts with everything closer than `h`, as in the seed report.
//! Validation is in [`super::check`], the resolved constants in [`super::params`], the particles
//! at t = 0 in [`super::initial`].

use super::lattice::{lattice_size, wall_axis};
use super::mesh::{MeshSurface, Placement, Triangle};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

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

pub(crate) fn err(origin: &SceneOrigin, field: impl Into<String>, message: impl Into<String>) -> SceneError {
    SceneError { origin: origin.to_string(), field: field.into(), message: message.into() }
}

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
    /// When a run stops or warns because the fluid left the weakly compressible regime.
    #[serde(default, skip_serializing_if = "Limits::is_default")]
    pub limits: Limits,
    /// Probes sampled during a run (`[[probe]]` tables; see [`super::probes`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub probe: Vec<ProbeSpec>,
}

/// The weakly compressible regime a run must stay in: a run stops at the first step whose
/// largest density or speed passes a `max_` level, and warns at its end when one passed a
/// `warn_` level. Weakly compressible SPH stands in for an incompressible liquid only while
/// density varies by a few per cent, which needs flow speeds well below the speed of sound:
/// rho/rho0 - 1 is about (|v|/c0)^2 = Ma^2 (Monaghan 1994, Sec. 3). `inf` turns a check off.
///
/// The defaults: warn above 1.1 rho0 and Mach 0.3, where density errors reach 10 % and the
/// assumption of a nearly incompressible fluid no longer holds; stop above 1.5 rho0, where the
/// Tait pressure is 16 times the stiffness (far beyond any flow the speed of sound was chosen
/// for), and above Mach 1, where the flow outruns its own pressure waves. Measured before
/// choosing them (docs/validation.md): the built-in scenes (except the seed, which sets its
/// own) and the validation cases reach at most 1.2 rho0 and Mach 0.39, at their default and
/// their coarsest resolutions.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Limits {
    /// Stop when a particle's density passes this multiple of rest_density.
    #[serde(default = "default_max_density_ratio")]
    pub max_density_ratio: f64,
    /// Warn when a particle's density passed this multiple of rest_density.
    #[serde(default = "default_warn_density_ratio")]
    pub warn_density_ratio: f64,
    /// Stop when a particle's speed passes this multiple of the speed of sound.
    #[serde(default = "default_max_mach")]
    pub max_mach: f64,
    /// Warn when a particle's speed passed this multiple of the speed of sound.
    #[serde(default = "default_warn_mach")]
    pub warn_mach: f64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_density_ratio: default_max_density_ratio(),
            warn_density_ratio: default_warn_density_ratio(),
            max_mach: default_max_mach(),
            warn_mach: default_warn_mach(),
        }
    }
}

impl Limits {
    pub fn is_default(&self) -> bool {
        *self == Limits::default()
    }

    /// Each stop level above 1 (density) or 0 (Mach), `inf` for none; each warning level at most
    /// its stop level.
    pub fn validate(&self, origin: &SceneOrigin) -> Result<(), SceneError> {
        use super::numbers::short;
        for (field, v, lowest) in [("limits.max_density_ratio", self.max_density_ratio, 1.0), ("limits.warn_density_ratio", self.warn_density_ratio, 1.0), ("limits.max_mach", self.max_mach, 0.0), ("limits.warn_mach", self.warn_mach, 0.0)] {
            if v.is_nan() || v <= lowest {
                return Err(err(origin, field, format!("is {}; must be a number > {lowest}, or inf for no limit", short(v))));
            }
        }
        for (warn, stop, field) in [(self.warn_density_ratio, self.max_density_ratio, "limits.warn_density_ratio"), (self.warn_mach, self.max_mach, "limits.warn_mach")] {
            if warn > stop {
                return Err(err(origin, field, format!("is {}, above the stop level {}; must be at most it", short(warn), short(stop))));
            }
        }
        Ok(())
    }
}

fn default_max_density_ratio() -> f64 {
    1.5
}
fn default_warn_density_ratio() -> f64 {
    1.1
}
fn default_max_mach() -> f64 {
    1.0
}
fn default_warn_mach() -> f64 {
    0.3
}

/// A perspective camera for rendered frames; a field not given is chosen automatically (the
/// target: the middle of the tank and fluid; the eye: in front, a little above, as far as
/// the field of view needs to show them).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub eye: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target: Option<[f64; 3]>,
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
    /// p_i / rho_i^2 + p_w / rho_w^2 with each wall particle's own pressure p_w extrapolated
    /// from the fluid around it, hydrostatic term included, and its density rho_w from the
    /// inverse equation of state (the generalised wall of Adami, Hu & Adams 2012): a pressure
    /// that a sensor on the wall can read.
    Adami,
}

#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum Kernel {
    /// Mueller et al. 2003: poly6 density, spiky gradient, viscosity Laplacian.
    Mueller,
    /// Monaghan's cubic spline (support h) with the Morris/Monaghan viscosity term.
    CubicSpline,
    /// Wendland's C2 function (support h; the 3D normalisation of Dehnen & Aly 2012), free of
    /// the pairing instability, with the Morris/Monaghan viscosity term.
    Wendland,
}

impl Kernel {
    /// Every kernel, in the order of its number on the GPU (`KERNEL` in wgsl/shared/common.wgsl).
    pub const ALL: [Kernel; 3] = [Kernel::Mueller, Kernel::CubicSpline, Kernel::Wendland];

    /// Whether viscosity is the Morris/Monaghan term built on grad W (the cubic spline's and
    /// Wendland's: their Laplacians change sign) rather than Mueller's viscosity Laplacian.
    pub fn gradient_viscosity(self) -> bool {
        self != Kernel::Mueller
    }
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
    /// Scales the viscosity and artificial viscosity terms between fluid and wall particles:
    /// 1 = no-slip, 0 = free slip.
    #[serde(default = "default_boundary_friction")]
    pub boundary_friction: f64,
    /// The wall particles' pressure term (see `BoundaryPressure`).
    #[serde(default)]
    pub boundary_pressure: BoundaryPressure,
    #[serde(default = "default_gravity")]
    pub gravity: [f64; 3],
    /// The pressure solver: weakly compressible (an equation of state) or DFSPH.
    #[serde(default, skip_serializing_if = "PressureSolver::is_default")]
    pub solver: PressureSolver,
    /// How a wall particle's mass is found: its lattice cell, or Akinci et al.'s volume.
    #[serde(default, skip_serializing_if = "BoundaryVolume::is_default")]
    pub boundary_volume: BoundaryVolume,
    /// Tolerances and iteration limits of DFSPH (`solver = "dfsph"` only).
    #[serde(default, skip_serializing_if = "DfsphSettings::is_default")]
    pub dfsph: DfsphSettings,
    /// How each particle's density is found: kernel summation, or carried by the continuity
    /// equation (see docs/pressure.md).
    #[serde(default, skip_serializing_if = "DensityMethod::is_default")]
    pub density: DensityMethod,
    /// delta of the delta-SPH density diffusion (Molteni & Colagrossi 2009, with the hydrostatic
    /// correction of Fourtakas et al. 2019); 0 = off. Needs `density = "continuity"`.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub density_diffusion: f64,
    /// alpha of Monaghan's artificial viscosity (Monaghan 1992), acting on approaching pairs
    /// only; 0 = off. Beside `viscosity`, which acts on every pair.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub artificial_viscosity: f64,
    /// gamma of Akinci et al.'s surface tension (2013): cohesion between fluid particles and a
    /// term that shrinks the surface's curvature; 0 = off. SPlisHSPlasH's default is 0.05.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub surface_tension: f64,
    /// beta of Akinci et al.'s adhesion (2013): wall particles pull the fluid near them;
    /// 0 = off. SPlisHSPlasH's default is 0.01.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub wall_adhesion: f64,
    /// The density and pressure of the fluid at t = 0: at rest, or hydrostatic (continuity
    /// density only).
    #[serde(default, skip_serializing_if = "InitialPressure::is_default")]
    pub initial_pressure: InitialPressure,
}

impl Physics {
    /// Water of rest density 1000 with support `smoothing_length` on a lattice of
    /// `particle_spacing`, every other setting at a scene file's default (as if only those two
    /// were given): Mueller kernel, linear equation of state with neither stiffness nor speed of
    /// sound (a scene sets one), no viscosity, no-slip mirrored walls, gravity 9.81 m/s^2 down,
    /// WCSPH with summation density, no diffusion, surface tension or adhesion. Set the others
    /// with struct update syntax: `Physics { kernel: Kernel::Wendland, ..Physics::new(h, s) }`.
    pub fn new(smoothing_length: f64, particle_spacing: f64) -> Physics {
        Physics {
            smoothing_length,
            rest_density: default_rest_density(),
            particle_spacing,
            particle_mass: None,
            kernel: default_kernel(),
            equation_of_state: default_eos(),
            stiffness: None,
            speed_of_sound: None,
            clamp_negative_pressure: false,
            viscosity: 0.0,
            viscosity_schedule: Vec::new(),
            boundary_friction: default_boundary_friction(),
            boundary_pressure: Default::default(),
            gravity: default_gravity(),
            solver: Default::default(),
            boundary_volume: Default::default(),
            dfsph: Default::default(),
            density: Default::default(),
            density_diffusion: 0.0,
            artificial_viscosity: 0.0,
            surface_tension: 0.0,
            wall_adhesion: 0.0,
            initial_pressure: Default::default(),
        }
    }

    /// The mass of a fluid particle: `particle_mass`, or rho0 s^3 (a lattice cell of water).
    pub fn fluid_mass(&self) -> f64 {
        self.particle_mass.unwrap_or(self.rest_density * self.particle_spacing.powi(3))
    }
}

/// How a particle's density is found.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum DensityMethod {
    /// rho_i = sum_k m_k W_ik, evaluated anew every step.
    #[default]
    Summation,
    /// d rho_i / dt = sum_k m_k (u_i - u_k) . grad W_ik, integrated with the particle (as
    /// DualSPHysics does); the only method that density diffusion applies to.
    Continuity,
}

impl DensityMethod {
    fn is_default(&self) -> bool {
        *self == DensityMethod::default()
    }
}

/// The fluid's density and pressure at t = 0.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum InitialPressure {
    /// Rest density, zero pressure: a still column rings as gravity compresses it.
    #[default]
    Zero,
    /// p = rho0 |g| d at depth d below the top of the particle's fluid block, and the density
    /// the equation of state gives it.
    Hydrostatic,
}

impl InitialPressure {
    fn is_default(&self) -> bool {
        *self == InitialPressure::default()
    }
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

/// How pressure is found.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum PressureSolver {
    /// Weakly compressible SPH: pressure from the equation of state.
    #[default]
    Wcsph,
    /// Divergence-free SPH (Bender & Koschier 2015, 2017): pressure from two implicit solves
    /// per step, one keeping the density at rest density, one the velocity divergence-free.
    Dfsph,
}

impl PressureSolver {
    fn is_default(&self) -> bool {
        *self == PressureSolver::default()
    }
}

/// The mass a wall particle stands for.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum BoundaryVolume {
    /// rest_density x spacing^3: right for walls as thick as the kernel support.
    #[default]
    Lattice,
    /// Akinci et al. 2012, Eq. 5: psi_b = rho0 / sum_k W_bk over the wall particles k near b,
    /// so that thin walls (one layer) and irregular samplings give the right density.
    Akinci,
}

impl BoundaryVolume {
    fn is_default(&self) -> bool {
        *self == BoundaryVolume::default()
    }
}

/// The tolerances and iteration limits of the DFSPH solves (`[physics.dfsph]`).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct DfsphSettings {
    /// The constant-density solve stops once the average predicted density error
    /// (rho* / rho0 - 1 where compressed) is at most this (0.0001 = 0.01 %, SPlisHSPlasH's default).
    #[serde(default = "default_density_error")]
    pub density_error: f64,
    /// The divergence solve stops once the average density change over one step
    /// (dt Drho/Dt / rho0 where compressing) is at most this (0.001 = 0.1 %).
    #[serde(default = "default_divergence_error")]
    pub divergence_error: f64,
    #[serde(default = "default_min_iterations")]
    pub min_iterations: u32,
    #[serde(default = "default_max_iterations")]
    pub max_iterations: u32,
    #[serde(default = "default_min_divergence_iterations")]
    pub min_divergence_iterations: u32,
    #[serde(default = "default_max_iterations")]
    pub max_divergence_iterations: u32,
    /// Run the divergence solve at all (SPlisHSPlasH's `enableDivergenceSolver`).
    #[serde(default = "default_true")]
    pub divergence_solve: bool,
    /// Start each solve from the stiffness of the previous step's.
    #[serde(default = "default_true")]
    pub warm_start: bool,
}

impl Default for DfsphSettings {
    fn default() -> Self {
        DfsphSettings {
            density_error: default_density_error(),
            divergence_error: default_divergence_error(),
            min_iterations: default_min_iterations(),
            max_iterations: default_max_iterations(),
            min_divergence_iterations: default_min_divergence_iterations(),
            max_divergence_iterations: default_max_iterations(),
            divergence_solve: true,
            warm_start: true,
        }
    }
}

impl DfsphSettings {
    pub(crate) fn is_default(&self) -> bool {
        *self == DfsphSettings::default()
    }
}

fn default_density_error() -> f64 {
    1e-4
}
fn default_divergence_error() -> f64 {
    1e-3
}
fn default_min_iterations() -> u32 {
    2
}
fn default_min_divergence_iterations() -> u32 {
    1
}
fn default_max_iterations() -> u32 {
    100
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
    /// C_cfl in dt <= C_cfl h / (c0 + |v|max) (adaptive only; DFSPH has no c0). Default 0.25
    /// with a weakly compressible fluid, 0.4 with DFSPH ([`Time::cfl_number_for`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cfl_number: Option<f64>,
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
            cfl_number: None,
            force_number: default_force_number(),
            viscous_number: default_viscous_number(),
            dt_min: None,
            dt_max: None,
            neighbour_rebuild_every: default_rebuild_every(),
        }
    }
}

impl Time {
    /// C_cfl of a run with `solver`: the scene's, else 0.25 where the speed of sound bounds
    /// the step (weakly compressible), 0.4 where only the flow speed does (DFSPH: the
    /// lambda ~ 0.4 of Ihmsen et al. 2014, "SPH Fluids in Computer Graphics").
    pub fn cfl_number_for(&self, solver: PressureSolver) -> f64 {
        self.cfl_number.unwrap_or(match solver {
            PressureSolver::Wcsph => 0.25,
            PressureSolver::Dfsph => 0.4,
        })
    }
}

fn is_false(b: &bool) -> bool {
    !*b
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

/// A box of fluid filled on a lattice of the physics spacing, with seeded random offsets; or
/// the part of that lattice inside a shape inscribed in the box.
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
    /// The shape the box's lattice is cut to (the whole box by default).
    #[serde(default, skip_serializing_if = "FluidShape::is_box")]
    pub shape: FluidShape,
}

impl FluidBlock {
    /// A box of fluid at rest, with the default jitter.
    pub fn new(min: [f64; 3], max: [f64; 3]) -> Self {
        FluidBlock { min, max, jitter: default_jitter(), velocity: [0.0; 3], shape: FluidShape::Box }
    }
}

/// The shape of a fluid block, inscribed in its box `min..max`: the lattice points of the box
/// inside it are the block's particles.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum FluidShape {
    /// The whole box.
    #[default]
    Box,
    /// The ellipsoid touching the box's faces (a sphere in a cube): a drop.
    Ellipsoid,
    /// The cylinder along x, y or z touching the box's faces across it (a circle in a square
    /// cross-section): a jet, a column.
    CylinderX,
    CylinderY,
    CylinderZ,
}

impl FluidShape {
    fn is_box(&self) -> bool {
        *self == FluidShape::Box
    }

    /// Its name in a scene file.
    pub fn name(self) -> &'static str {
        match self {
            FluidShape::Box => "box",
            FluidShape::Ellipsoid => "ellipsoid",
            FluidShape::CylinderX => "cylinder_x",
            FluidShape::CylinderY => "cylinder_y",
            FluidShape::CylinderZ => "cylinder_z",
        }
    }

    /// Whether `x` lies inside the shape inscribed in `min..max` (on its surface counts).
    pub fn contains(self, min: [f64; 3], max: [f64; 3], x: [f64; 3]) -> bool {
        // The squared distance from the axis (or centre) along axis a, in half-extents.
        let term = |a: usize| {
            let (centre, half) = (0.5 * (min[a] + max[a]), 0.5 * (max[a] - min[a]));
            let d = (x[a] - centre) / half;
            d * d
        };
        let across = |along: usize| (0..3).filter(|&a| a != along).map(term).sum::<f64>();
        match self {
            FluidShape::Box => true,
            FluidShape::Ellipsoid => (0..3).map(term).sum::<f64>() <= 1.0,
            FluidShape::CylinderX => across(0) <= 1.0,
            FluidShape::CylinderY => across(1) <= 1.0,
            FluidShape::CylinderZ => across(2) <= 1.0,
        }
    }
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
    /// Wall particles lining a closed triangle mesh read from a file: an obstacle of any shape,
    /// or a tank holding the fluid inside it.
    Mesh(MeshWall),
}

/// A `[[boundary]] type = "mesh"` table: the file, where its triangles sit in the scene, and
/// on which side the fluid is (see [`super::mesh`] for how its walls are sampled).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MeshWall {
    /// A Wavefront OBJ or STL file; a relative path is taken from the scene file's folder,
    /// and the scene is written back with the absolute path.
    pub file: String,
    /// The file's coordinates are multiplied by this per axis first (e.g. 0.001 for a file in
    /// millimetres).
    #[serde(default = "unit_scale")]
    pub scale: [f64; 3],
    /// Then turned by `rotation_degrees` about this axis (right-handed)...
    #[serde(default = "default_rotation_axis")]
    pub rotation_axis: [f64; 3],
    #[serde(default)]
    pub rotation_degrees: f64,
    /// ... and moved by this.
    #[serde(default)]
    pub translate: [f64; 3],
    /// `false` (default): a solid obstacle, the fluid around it and the walls inside its
    /// surface; `true`: a tank, the fluid inside the surface and the walls outside it.
    #[serde(default)]
    pub fluid_inside: bool,
    /// The file's CRC-32 (8 hex digits) when it was read: a run's `scene.toml` and checkpoints
    /// record it, so that a resumed run refuses a mesh file changed since. Optional in a scene.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub crc32: Option<String>,
    #[serde(flatten)]
    pub walls: WallParticles,
    /// The file's triangles (in its own coordinates), read with the scene.
    #[serde(skip)]
    pub surface: MeshSurface,
}

impl MeshWall {
    pub fn placement(&self) -> Placement {
        Placement { scale: self.scale, axis: self.rotation_axis, degrees: self.rotation_degrees, translate: self.translate }
    }

    /// Its triangles in the scene's coordinates (none before the file is read).
    pub fn placed_triangles(&self) -> Vec<Triangle> {
        self.surface.triangles().map(|t| self.placement().apply_all(t)).unwrap_or_default()
    }

    /// The box around its placed surface.
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        super::mesh::bounds(&self.placed_triangles())
    }
}

fn unit_scale() -> [f64; 3] {
    [1.0; 3]
}

fn default_rotation_axis() -> [f64; 3] {
    [0.0, 1.0, 0.0]
}

fn default_true() -> bool {
    true
}

impl Boundary {
    /// How a particle boundary's walls are sampled (none for a plane).
    pub fn walls(&self) -> Option<&WallParticles> {
        match self {
            Boundary::Container { walls, .. } | Boundary::Box { walls, .. } => Some(walls),
            Boundary::Mesh(m) => Some(&m.walls),
            Boundary::Plane { .. } => None,
        }
    }

    fn walls_mut(&mut self) -> Option<&mut WallParticles> {
        match self {
            Boundary::Container { walls, .. } | Boundary::Box { walls, .. } => Some(walls),
            Boundary::Mesh(m) => Some(&mut m.walls),
            Boundary::Plane { .. } => None,
        }
    }
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

impl Scene {
    /// Parses and validates a scene.
    pub fn from_toml_str(text: &str, origin: &SceneOrigin) -> Result<Scene, SceneError> {
        let mut scene: Scene = toml::from_str(text).map_err(|e| {
            let field = e.span().map(|span| parse_error_place(text, span, e.message())).unwrap_or_else(|| "toml".into());
            err(origin, field, readable_parse_error(e.message()))
        })?;
        scene.read_meshes(origin)?;
        scene.validate(origin)?;
        Ok(scene)
    }

    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).expect("a scene serialises")
    }

    pub(crate) fn wall_layers(&self, walls: &WallParticles) -> u32 {
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
            if let Some(sp) = b.walls_mut().and_then(|w| w.spacing.as_mut()) {
                *sp *= factor;
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

    /// The region a container's, a box's or a mesh's wall particles occupy: a container's
    /// walls lie outside its faces, `layers` spacings deep; a box's inside it; a mesh's inside
    /// its surface's box, or outside it by as much when the fluid is inside the mesh.
    pub fn wall_span(&self, b: &Boundary) -> Option<([f64; 3], [f64; 3])> {
        let grown = |min: [f64; 3], max: [f64; 3], d: f64| ([min[0] - d, min[1] - d, min[2] - d], [max[0] + d, max[1] + d, max[2] + d]);
        match b {
            Boundary::Container { min, max, walls, .. } => Some(grown(*min, *max, self.wall_thickness(walls))),
            Boundary::Box { min, max, .. } => Some((*min, *max)),
            Boundary::Mesh(m) => {
                let (min, max) = m.bounds();
                Some(if m.fluid_inside { grown(min, max, self.wall_thickness(&m.walls)) } else { (min, max) })
            }
            Boundary::Plane { .. } => None,
        }
    }

    /// How deep a particle boundary's walls are: `layers` of its spacing.
    pub fn wall_thickness(&self, walls: &WallParticles) -> f64 {
        self.wall_layers(walls) as f64 * walls.spacing.unwrap_or(self.physics.particle_spacing)
    }

    /// The scene refined or coarsened to about `fluid_particles` fluid particles.
    pub fn with_fluid_particles(&self, fluid_particles: u64) -> Scene {
        self.with_resolution(self.factor_for(fluid_particles, f64::INFINITY))
    }

    /// The factor on the spacings that gives about `fluid_particles`, at most `coarsest`. The
    /// count is a step function of the factor (whole layers per block), so the factor that
    /// scales the volume per particle is only where the search starts: factors within 15 % of
    /// it are tried, and the one whose count comes nearest is kept (the nearest to the start
    /// among equals).
    fn factor_for(&self, fluid_particles: u64, coarsest: f64) -> f64 {
        let now = self.fluid_particle_count().max(1) as f64;
        let target = fluid_particles.max(1);
        let start = (now / target as f64).cbrt().min(coarsest);
        if start == 1.0 {
            return start;
        }
        (-15..=15)
            .map(|k: i32| (k.abs(), (start * (1.0 + 0.01 * k as f64)).min(coarsest)))
            .min_by_key(|&(k, f)| (self.with_resolution(f).fluid_particle_count().abs_diff(target), k))
            .map_or(start, |(_, f)| f)
    }

    /// The coarsest resolution `--particles` may ask for, as a factor on the spacings: every
    /// fluid block at least one smoothing length h and two particle spacings thick on every
    /// axis, so that a particle has neighbours in the layers beside it. A scene as written is
    /// always allowed (1 at least).
    pub fn coarsest_factor(&self) -> f64 {
        let thinnest_allowed = self.physics.smoothing_length.max(2.0 * self.physics.particle_spacing);
        let thinnest = self.fluid.iter().flat_map(|b| (0..3).map(move |a| b.max[a] - b.min[a])).fold(f64::INFINITY, f64::min);
        (thinnest / thinnest_allowed).max(1.0)
    }

    /// The fewest fluid particles `--particles` may ask for: the count at
    /// [`Scene::coarsest_factor`].
    pub fn fewest_fluid_particles(&self) -> u64 {
        self.with_resolution(self.coarsest_factor()).fluid_particle_count().min(self.fluid_particle_count())
    }

    /// [`Scene::with_fluid_particles`] for a user's request: refused, with the fewest the scene
    /// allows, where the scene would be coarser than [`Scene::coarsest_factor`].
    pub fn at_fluid_particles(&self, fluid_particles: u64) -> Result<Scene, String> {
        let fewest = self.fewest_fluid_particles();
        if fluid_particles < fewest {
            let h = self.physics.smoothing_length;
            let (i, axis, thickness) = self
                .fluid
                .iter()
                .enumerate()
                .flat_map(|(i, b)| (0..3).map(move |a| (i, a, b.max[a] - b.min[a])))
                .fold((0, 0, f64::INFINITY), |best, x| if x.2 < best.2 { x } else { best });
            return Err(format!(
                "the scene '{}' allows at least {fewest} fluid particles: with fewer, fluid[{i}] ({} thick along {}) would be thinner than one smoothing length h or two particle spacings (both grow as the particles get fewer; h is {} now)",
                self.name,
                super::numbers::short(thickness),
                ["x", "y", "z"][axis],
                super::numbers::short(h)
            ));
        }
        Ok(self.with_resolution(self.factor_for(fluid_particles, self.coarsest_factor())))
    }

    /// One line for each fluid block whose sides are not whole numbers of particle spacings,
    /// saying how its lattice differs from the stated block and why (see [`super::lattice`]).
    pub fn lattice_changes(&self) -> Vec<String> {
        use super::numbers::short;
        let s = self.physics.particle_spacing;
        let mut out = Vec::new();
        // A shape's particles are those of its box's lattice inside it: the box's sides need
        // not be whole spacings.
        for (i, b) in self.fluid.iter().enumerate().filter(|(_, b)| b.shape == FluidShape::Box) {
            let axes = self.fluid_lattice(i);
            let stated: [f64; 3] = std::array::from_fn(|a| b.max[a] - b.min[a]);
            if (0..3).all(|a| super::lattice::whole_spacings(stated[a], s).is_some()) {
                continue;
            }
            let filled: [f64; 3] = std::array::from_fn(|a| axes[a].length());
            let sides = |v: [f64; 3]| v.map(short).join(" x ");
            let change: Vec<String> = (0..3)
                .filter(|&a| (filled[a] - stated[a]).abs() > 1e-9 * s)
                .map(|a| format!("{} {:+.1} %", ["x", "y", "z"][a], 100.0 * (filled[a] - stated[a]) / stated[a]))
                .collect();
            out.push(format!(
                "fluid[{i}] is {} but not a whole number of particle spacings ({}): filled as {} ({}; {} particles; never nearer than half a spacing to a wall), so that the fluid keeps its spacing and starts at its rest density",
                sides(stated),
                short(s),
                sides(filled),
                change.join(", "),
                lattice_size(axes.iter().map(|x| x.count))
            ));
        }
        out
    }

    /// Fluid particles of the scene, counted from the lattice sizes without creating them.
    pub fn fluid_particle_count(&self) -> u64 {
        (0..self.fluid.len()).fold(0u64, |n, i| n.saturating_add(self.fluid_block_count(i)))
    }

    /// Fluid particles of block `i`: the box's lattice, or the part of it inside its shape,
    /// counted row by row along x (a convex shape holds an interval of each row, around the
    /// point nearest its centre), so that a block of a billion particles is counted in a
    /// million binary searches.
    pub fn fluid_block_count(&self, i: usize) -> u64 {
        let axes = self.fluid_lattice(i);
        let b = &self.fluid[i];
        let cut = self.mesh_cut(i);
        let box_size = lattice_size(axes.iter().map(|a| a.count));
        // Far above the particle limit (2^31, `check::MAX_PARTICLES`) the box's lattice is the
        // count (an upper bound): asking each of its points, or each row, would take as long
        // as creating them.
        if box_size > 1 << 33 {
            return box_size;
        }
        if !cut.is_empty() {
            // Beside a mesh each point is asked (in rows of z, in parallel).
            use rayon::prelude::*;
            return (0..axes[2].count)
                .into_par_iter()
                .map(|k| {
                    let z = axes[2].point(k);
                    let mut n = 0;
                    for j in 0..axes[1].count {
                        for i in 0..axes[0].count {
                            let q = [axes[0].point(i), axes[1].point(j), z];
                            n += (b.shape.contains(b.min, b.max, q) && cut.keeps(q)) as u64;
                        }
                    }
                    n
                })
                .sum();
        }
        if b.shape == FluidShape::Box {
            return box_size;
        }
        let x = axes[0];
        if x.count == 0 {
            return 0;
        }
        let centre = ((0.5 * (b.min[0] + b.max[0]) - x.origin) / x.spacing - 0.5).round().clamp(0.0, (x.count - 1) as f64) as u64;
        let mut n = 0;
        for k in 0..axes[2].count {
            for j in 0..axes[1].count {
                let (y, z) = (axes[1].point(j), axes[2].point(k));
                let inside = |i: u64| b.shape.contains(b.min, b.max, [x.point(i), y, z]);
                if !inside(centre) {
                    continue;
                }
                let first = crate::model::lattice::first_index(0, centre, |i| inside(i));
                let end = crate::model::lattice::first_index(centre, x.count, |i| !inside(i));
                n += end - first;
            }
        }
        n
    }

    /// Particle count (fluid and walls, walls over-estimated by the full shell of their box,
    /// top included) computed from the lattice sizes, without creating the particles.
    pub fn estimated_particle_count(&self) -> u64 {
        let s = self.physics.particle_spacing;
        let mut n = self.fluid_particle_count();
        for b in &self.boundary {
            match b {
                Boundary::Container { min, max, walls, .. } | Boundary::Box { min, max, walls } => {
                    let ws = walls.spacing.unwrap_or(s);
                    let l = self.wall_layers(walls) as f64 * ws;
                    let (lo, hi) = ([min[0] - l, min[1] - l, min[2] - l], [max[0] + l, max[1] + l, max[2] + l]);
                    let outer = [0, 1, 2].map(|a| wall_axis(lo[a], hi[a], ws).count);
                    let inner = [0, 1, 2].map(|a| wall_axis(min[a], max[a], ws).count.saturating_sub(2));
                    n = n.saturating_add(shell_size(outer, inner));
                }
                // The surface's area times the walls' depth, in lattice cells (an estimate:
                // a curved or slanted surface takes a little more).
                Boundary::Mesh(m) => {
                    let ws = m.walls.spacing.unwrap_or(s);
                    let area: f64 = m.placed_triangles().iter().map(super::mesh::area).sum();
                    n = n.saturating_add((area * self.wall_thickness(&m.walls) / ws.powi(3)).ceil() as u64);
                }
                Boundary::Plane { .. } => {}
            }
        }
        n
    }

    /// The box worth looking at: the solids and the fluid blocks, within the domain (the
    /// domain alone when the scene has neither).
    pub fn view_bounds(&self) -> ([f64; 3], [f64; 3]) {
        let mut boxes: Vec<([f64; 3], [f64; 3])> = self.solid_regions().iter().map(|r| (r.min, r.max)).collect();
        boxes.extend(self.boundary.iter().filter(|b| matches!(b, Boundary::Mesh(_))).filter_map(|b| self.wall_span(b)));
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
            .filter_map(|b| b.walls().map(|w| w.spacing.unwrap_or(self.physics.particle_spacing)))
            .reduce(f64::min)
            .unwrap_or(self.physics.particle_spacing)
    }
}

/// A `[[probe]]` table of a scene: a name, a type and the fields of that type's geometry (a
/// field of another type is refused, naming the probe).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ProbeSpec {
    /// The file name of its time series: probes/NAME.csv.
    pub name: String,
    #[serde(rename = "type")]
    pub kind: ProbeType,
    /// point: the point; gauge: the bottom of its vertical line (the height is measured from
    /// its y).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position: Option<[f64; 3]>,
    /// gauge: the y of the line's top; default the domain's top.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub top: Option<f64>,
    /// point, gauge: with `count`, a row of `count` probes evenly spaced from `position` to
    /// `to` (both included), named NAME_0, NAME_1, ... (zero-padded), each with its own file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub to: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub count: Option<u32>,
    /// force: the index of the solid in the scene's `[[boundary]]` list (a box or a container).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub boundary: Option<usize>,
    /// force: only the wall particles inside [min, max] count (default: all of the boundary's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min: Option<[f64; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max: Option<[f64; 3]>,
    /// force: the point the moment is taken about; default the boundary's centre.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub moment_about: Option<[f64; 3]>,
    /// front: the direction the front advances along (default +x).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub direction: Option<[f64; 3]>,
    /// front: the y of the floor; default the bottom of the lowest fluid block.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub floor: Option<f64>,
    /// front: fluid counts when its y is below floor + height; default h.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height: Option<f64>,
    /// Sample every this many steps (default 1 when `every_seconds` is not given).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub every_steps: Option<u64>,
    /// Sample at the first step reaching each multiple of this simulated time.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub every_seconds: Option<f64>,
}

/// What a probe measures.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ProbeType {
    Point,
    Gauge,
    Force,
    Front,
}

impl ProbeType {
    /// The geometry fields a probe of this type may have.
    pub(crate) fn fields(self) -> &'static [&'static str] {
        match self {
            ProbeType::Point => &["position", "to", "count"],
            ProbeType::Gauge => &["position", "top", "to", "count"],
            ProbeType::Force => &["boundary", "min", "max", "moment_about"],
            ProbeType::Front => &["direction", "floor", "height"],
        }
    }
}

impl ProbeSpec {
    /// The geometry fields this table gives.
    pub(crate) fn given(&self) -> Vec<&'static str> {
        let mut g = Vec::new();
        let mut add = |name: &'static str, present: bool| {
            if present {
                g.push(name);
            }
        };
        add("position", self.position.is_some());
        add("top", self.top.is_some());
        add("to", self.to.is_some());
        add("count", self.count.is_some());
        add("boundary", self.boundary.is_some());
        add("min", self.min.is_some());
        add("max", self.max.is_some());
        add("moment_about", self.moment_about.is_some());
        add("direction", self.direction.is_some());
        add("floor", self.floor.is_some());
        add("height", self.height.is_some());
        g
    }

    /// The probes this table declares, by name and position: one, or the row from `position`
    /// to `to` where `count` is given (the positions of the table's other geometry: its own
    /// position, unset where it has none).
    pub fn row(&self) -> Vec<(String, Option<[f64; 3]>)> {
        match (self.position, self.to, self.count) {
            (Some(a), Some(b), Some(n)) if n >= 2 => {
                let width = (n - 1).to_string().len();
                (0..n)
                    .map(|k| {
                        let t = k as f64 / (n - 1) as f64;
                        // The ends exactly as given.
                        let x = std::array::from_fn(|i| if k == n - 1 { b[i] } else { a[i] + t * (b[i] - a[i]) });
                        (format!("{}_{k:0width$}", self.name), Some(x))
                    })
                    .collect()
            }
            _ => vec![(self.name.clone(), self.position)],
        }
    }

    /// A point probe at `position` sampled every `every_steps` steps.
    pub fn point(name: &str, position: [f64; 3], every_steps: u64) -> Self {
        ProbeSpec { position: Some(position), every_steps: Some(every_steps), ..ProbeSpec::of(name, ProbeType::Point) }
    }

    /// A probe of type `kind` with no geometry given (every default).
    pub fn of(name: &str, kind: ProbeType) -> Self {
        ProbeSpec {
            name: name.into(),
            kind,
            position: None,
            top: None,
            to: None,
            count: None,
            boundary: None,
            min: None,
            max: None,
            moment_about: None,
            direction: None,
            floor: None,
            height: None,
            every_steps: None,
            every_seconds: None,
        }
    }
}

/// A reader's message in the scene file's words: the reader names the type it expected
/// (`expected struct DfsphSettings`), which a scene's author never sees; a table is what the
/// file gives there.
/// Where in `text` a parse error lies: its line, with the key whose value it is about. The
/// reader's span is the value itself for a plain field, and the whole table for one of a
/// `[[boundary]]` or `[[probe]]` array (read through its `type`): there the key is the one
/// line of the table that holds the value the message quotes (`string "x"`, ``integer `-1` ``).
fn parse_error_place(text: &str, span: std::ops::Range<usize>, message: &str) -> String {
    let start = span.start.min(text.len());
    let line_of = |at: usize| text[..at].lines().count().max(1) + usize::from(at > 0 && text.as_bytes()[at - 1] == b'\n');
    let key_of = |line: &str| -> Option<String> {
        let key = line.split_once('=')?.0.trim();
        (!key.is_empty() && key.chars().all(|c| c.is_ascii_alphanumeric() || "_.-".contains(c))).then(|| key.to_string())
    };
    let line_start = text[..start].rfind('\n').map_or(0, |i| i + 1);
    let first_line = text[line_start..].lines().next().unwrap_or("");
    if let Some(key) = key_of(first_line) {
        return format!("line {} ({key})", line_of(line_start));
    }
    // The value the message quotes, searched among the lines that follow.
    let quoted = ["string ", "integer `", "floating point `", "boolean `"].iter().find_map(|kind| {
        let rest = &message[message.find(kind)? + kind.len()..];
        if kind.ends_with('`') {
            rest.split('`').next().map(str::to_string)
        } else {
            rest.strip_prefix('"').and_then(|r| r.split('"').next()).map(|v| format!("\"{v}\""))
        }
    });
    if let Some(value) = quoted {
        // From the span's line on (the reader's span may end before the table does): a value
        // that does not fit is rarely written twice.
        let mut offset = line_start;
        let mut found = Vec::new();
        for line in text[line_start..].split_inclusive('\n') {
            if let Some((key, v)) = line.split_once('=') {
                let v = v.split('#').next().unwrap_or("").trim();
                if v == value && key_of(line).is_some() {
                    found.push((line_of(offset), key.trim().to_string()));
                }
            }
            offset += line.len();
        }
        if let [(line, key)] = found.as_slice() {
            return format!("line {line} ({key})");
        }
    }
    format!("line {}", line_of(line_start))
}

pub(crate) fn readable_parse_error(message: &str) -> String {
    match message.split_once("expected struct ") {
        Some((before, after)) => {
            let rest = after.trim_start_matches(|c: char| c.is_alphanumeric() || c == '_');
            format!("{before}expected a table of fields ([section] or {{ key = value, ... }}){rest}")
        }
        None => message.to_string(),
    }
}

/// The points of a lattice shell: an outer box of `outer` points along each axis less an inner
/// one of `inner`. A shell holds at least every point of its outer edges, so one axis of more
/// than 2^32 points saturates at `u64::MAX`; below that the two sizes fit in 128 bits.
fn shell_size(outer: [u64; 3], inner: [u64; 3]) -> u64 {
    if outer.iter().any(|&count| count > u32::MAX as u64) {
        return u64::MAX;
    }
    let size = |counts: [u64; 3]| counts.iter().map(|&count| count as u128).product::<u128>();
    u64::try_from(size(outer).saturating_sub(size(inner))).unwrap_or(u64::MAX)
}
