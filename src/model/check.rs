//! Scene validation: every field checked against what is allowed before any work, with an
//! error that names the file, the field, the value and the allowed range.

use super::lattice::lattice_size;
use super::numbers::{short, short3};
use super::params::{MAX_PLANES, MAX_SOLID_BOXES};
use super::scene::{err, Boundary, BoundaryPressure, BoundaryVolume, DensityMethod, DfsphSettings, EquationOfState, InitialPressure, Limits, Physics, PressureSolver, Scene, SceneError, SceneOrigin, Time};

/// Most particles a scene may hold: indices are u32 on the GPU and the CPU.
pub const MAX_PARTICLES: u64 = 1 << 31;
/// Most grid cells a scene may have.
pub const MAX_CELLS: u64 = 1 << 30;
/// Most iterations a DFSPH solve may take per step (the GPU records that many per step).
pub const MAX_SOLVER_ITERATIONS: u32 = 1000;
/// The largest turn of a mesh boundary, in degrees (about 2,800 revolutions).
pub const MAX_ROTATION_DEGREES: f64 = 1e6;
/// Host bytes per particle the CPU path needs at most (f64 state, sort buffers, snapshot copy,
/// and the neighbour lists of the lane path: about 550 bytes per fluid particle in all on the
/// block workload, measured by `wgsph bench`).
pub const CPU_BYTES_PER_PARTICLE: u64 = 600;
/// Host bytes per particle that building any scene needs (the generated particles, the sorted
/// upload and the readback copies), whatever backend then runs it: the GPU path's peak resident
/// set grew by 152 bytes per particle from 1.8 M to 5.9 M particles of the dam break on a
/// software adapter (which keeps the GPU's 60 bytes in host memory too), and peaked at 129 bytes
/// per particle for the 286 M particles of a 256 M dam break on an H200's host. The CPU backend
/// checks its own, larger figure when it starts.
pub const SCENE_BYTES_PER_PARTICLE: u64 = 200;

/// The magnitudes a scene's constants may have, in the scene's units. No liquid in SI, cgs or
/// millimetre units comes near these bounds (water: rho0 = 1000 kg/m^3 or 1e-6 kg/mm^3, c0 =
/// 1480 m/s or 1.5e6 mm/s, nu = 1e-6 m^2/s, g = 9.81 m/s^2 or 9810 mm/s^2; pitch, one of the most
/// viscous liquids, about 2e5 m^2/s), and within them the GPU's f32 arithmetic cannot overflow:
/// the stiffness rho0 c0^2 stays below 1e25, so even the Tait pressure at ten times the rest
/// density (1e7 k) is far below f32's largest number, 3.4e38.
pub const REST_DENSITY_RANGE: (f64, f64) = (1e-9, 1e9);
/// The speed of sound, given or implied by the stiffness (see [`REST_DENSITY_RANGE`]).
pub const SPEED_OF_SOUND_RANGE: (f64, f64) = (1e-6, 1e8);
/// The allowed delta of density diffusion (0 = off) and alpha of artificial viscosity.
pub const DENSITY_DIFFUSION_RANGE: (f64, f64) = (0.0, 1.0);
pub const ARTIFICIAL_VISCOSITY_RANGE: (f64, f64) = (0.0, 1.0);
/// gamma of surface tension and beta of adhesion (Akinci et al. 2013). Both act as
/// accelerations that do not change with the particle size; at 100 the cohesion outweighs
/// gravity a hundred times over.
pub const SURFACE_TENSION_RANGE: (f64, f64) = (0.0, 100.0);
/// The largest kinematic viscosity and the largest |gravity| (see [`REST_DENSITY_RANGE`]).
pub const MAX_VISCOSITY: f64 = 1e9;
/// The smallest time step, fixed or adaptive (`dt_min`): f32's normal numbers end at 1.2e-38,
/// and the margin keeps what the GPU computes from the step (products with speeds and
/// accelerations) normal too.
pub const MIN_DT: f64 = 1e-30;
/// The largest time step: the GPU's products of dt with speeds, accelerations and dt itself
/// (dt^2 a) stay far inside f32's range (3.4e38), and no liquid in any usual units needs a
/// step of more than about 3 years.
pub const MAX_DT: f64 = 1e8;
/// The most wall layers a boundary may ask for: the kernel's support is a few spacings deep.
pub const MAX_WALL_LAYERS: u32 = 16;
/// The most wall layers a boundary gets by default (h / spacing): beyond, a smoothing length
/// of dozens of wall spacings is a mistake of units, and the layers' count would overflow.
pub const MAX_DEFAULT_WALL_LAYERS: u32 = 64;
/// How far a given particle mass may be from rest_density x particle_spacing^3, as a factor.
pub const PARTICLE_MASS_FACTOR: f64 = 1e3;
/// The largest boundary friction: a scale of the viscosity between fluid and walls (1 no-slip).
pub const MAX_BOUNDARY_FRICTION: f64 = 100.0;
pub const MAX_GRAVITY: f64 = 1e9;

/// Whether two boxes share a volume (more than `tolerance` deep on every axis).
fn boxes_overlap(a: ([f64; 3], [f64; 3]), b: ([f64; 3], [f64; 3]), tolerance: f64) -> bool {
    (0..3).all(|k| a.1[k].min(b.1[k]) - a.0[k].max(b.0[k]) > tolerance)
}

impl Scene {
    /// Checks every field against what is allowed, before any work.
    pub fn validate(&self, origin: &SceneOrigin) -> Result<(), SceneError> {
        let positive = |field: &str, v: f64| -> Result<(), SceneError> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(err(origin, field, format!("is {}; must be a finite number > 0", short(v))))
            }
        };
        let finite3 = |field: &str, v: [f64; 3]| -> Result<(), SceneError> {
            if v.iter().all(|c| c.is_finite()) {
                Ok(())
            } else {
                Err(err(origin, field, format!("is {}; every component must be finite", short3(v))))
            }
        };
        let ordered = |field: &str, min: [f64; 3], max: [f64; 3]| -> Result<(), SceneError> {
            finite3(&format!("{field}.min"), min)?;
            finite3(&format!("{field}.max"), max)?;
            if (0..3).all(|a| max[a] > min[a]) {
                Ok(())
            } else {
                Err(err(origin, field, format!("min {} must be below max {} on every axis", short3(min), short3(max))))
            }
        };
        let in_range = |field: &str, v: f64, (lo, hi): (f64, f64), what: &str| -> Result<(), SceneError> {
            if (lo..=hi).contains(&v) {
                Ok(())
            } else {
                Err(err(origin, field, format!(
                    "is {}; must be between {} and {} ({what}: beyond these no liquid in any usual units, and the GPU's f32 arithmetic would overflow)",
                    short(v), short(lo), short(hi))))
            }
        };
        let p = &self.physics;
        positive("physics.smoothing_length", p.smoothing_length)?;
        positive("physics.rest_density", p.rest_density)?;
        positive("physics.particle_spacing", p.particle_spacing)?;
        if let Some(m) = p.particle_mass {
            positive("physics.particle_mass", m)?;
        }
        in_range("physics.rest_density", p.rest_density, REST_DENSITY_RANGE, "kg/m^3 in SI")?;
        if let Some(m) = p.particle_mass {
            // Against the mass that fills a lattice cell at rest density: a factor of a thousand
            // either way is no fluid at rest, and further the GPU's f32 densities over- or
            // underflow.
            let lattice = p.rest_density * p.particle_spacing.powi(3);
            let (lo, hi) = (lattice / PARTICLE_MASS_FACTOR, lattice * PARTICLE_MASS_FACTOR);
            if !(lo..=hi).contains(&m) {
                return Err(err(origin, "physics.particle_mass", format!(
                    "is {}; must be between {} and {} (within a factor of {} of rest_density x particle_spacing^3 = {}, the mass that fills the particle's lattice cell; leave it out to use that)",
                    short(m), short(lo), short(hi), short(PARTICLE_MASS_FACTOR), short(lattice))));
            }
        }
        if p.smoothing_length < p.particle_spacing {
            return Err(err(origin, "physics.smoothing_length", format!(
                "is {}, below the particle spacing {}: a particle would have no neighbour within h; must be at least the spacing (twice it is usual)",
                short(p.smoothing_length), short(p.particle_spacing))));
        }
        // k = rho0 c0^2 (linear) or rho0 c0^2 / 7 (Tait).
        let stiffness_per_c2 = p.rest_density / if p.equation_of_state == EquationOfState::Tait { 7.0 } else { 1.0 };
        match (p.solver, p.stiffness, p.speed_of_sound) {
            (PressureSolver::Wcsph, Some(k), None) => {
                positive("physics.stiffness", k)?;
                let c0 = (k / stiffness_per_c2).sqrt();
                let (lo, hi) = SPEED_OF_SOUND_RANGE;
                if !(lo..=hi).contains(&c0) {
                    return Err(err(origin, "physics.stiffness", format!(
                        "is {}, a speed of sound of {}; must be between {} and {} (a speed of sound between {} and {}: beyond these no liquid in any usual units, and the GPU's f32 arithmetic would overflow)",
                        short(k), short(c0), short(stiffness_per_c2 * lo * lo), short(stiffness_per_c2 * hi * hi), short(lo), short(hi))));
                }
            }
            (PressureSolver::Wcsph, None, Some(c)) => {
                positive("physics.speed_of_sound", c)?;
                in_range("physics.speed_of_sound", c, SPEED_OF_SOUND_RANGE, "m/s in SI")?;
            }
            (PressureSolver::Wcsph, ..) => {
                return Err(err(origin, "physics.stiffness", "give exactly one of stiffness and speed_of_sound"))
            }
            (PressureSolver::Dfsph, None, None) => {}
            (PressureSolver::Dfsph, k, _) => {
                let field = if k.is_some() { "physics.stiffness" } else { "physics.speed_of_sound" };
                return Err(err(origin, field, "is not used with solver = \"dfsph\", whose pressure comes from its incompressibility solve; remove it"));
            }
        }
        self.validate_dfsph(origin)?;
        if !(p.viscosity.is_finite() && p.viscosity >= 0.0) {
            return Err(err(origin, "physics.viscosity", format!("is {}; must be finite and >= 0", short(p.viscosity))));
        }
        in_range("physics.viscosity", p.viscosity, (0.0, MAX_VISCOSITY), "m^2/s in SI")?;
        let mut last = 0.0;
        for (i, c) in p.viscosity_schedule.iter().enumerate() {
            let f = format!("physics.viscosity_schedule[{i}]");
            // Two changes at one time would leave one of them unused.
            if !(c.time.is_finite() && c.time >= last) || (i > 0 && c.time == last) {
                return Err(err(origin, format!("{f}.time"), format!("is {}; times must be finite, >= 0 and increasing", short(c.time))));
            }
            if !(c.viscosity.is_finite() && c.viscosity >= 0.0) {
                return Err(err(origin, format!("{f}.viscosity"), format!("is {}; must be finite and >= 0", short(c.viscosity))));
            }
            in_range(&format!("{f}.viscosity"), c.viscosity, (0.0, MAX_VISCOSITY), "m^2/s in SI")?;
            last = c.time;
        }
        if !(p.boundary_friction.is_finite() && (0.0..=MAX_BOUNDARY_FRICTION).contains(&p.boundary_friction)) {
            return Err(err(origin, "physics.boundary_friction", format!(
                "is {}; must be from 0 to {} (1 no-slip, 0 free slip)", short(p.boundary_friction), short(MAX_BOUNDARY_FRICTION))));
        }
        self.validate_pressure_options(origin)?;
        finite3("physics.gravity", p.gravity)?;
        // |g|, scaled so that huge components do not overflow.
        let largest = p.gravity.iter().fold(0.0f64, |m, c| m.max(c.abs()));
        let g = if largest > 0.0 { largest * p.gravity.iter().map(|c| (c / largest).powi(2)).sum::<f64>().sqrt() } else { 0.0 };
        if g > MAX_GRAVITY {
            return Err(err(origin, "physics.gravity", format!(
                "is {}, of magnitude {}; must be at most {} (m/s^2 in SI: beyond it no real scene in any usual units, and the GPU's f32 arithmetic would overflow)",
                short3(p.gravity), short(g), short(MAX_GRAVITY))));
        }
        self.limits.validate(origin)?;
        if let Some(c) = &self.camera {
            for (field, v) in [("camera.eye", c.eye), ("camera.target", c.target)] {
                if let Some(v) = v {
                    finite3(field, v)?;
                }
            }
            finite3("camera.up", c.up)?;
            let un = (c.up[0] * c.up[0] + c.up[1] * c.up[1] + c.up[2] * c.up[2]).sqrt();
            if un == 0.0 {
                return Err(err(origin, "camera.up", format!("is {}; must be non-zero", short3(c.up))));
            }
            // The direction is known here only when both points are given (otherwise the
            // automatic one, which is never vertical, is used).
            if let (Some(eye), Some(target)) = (c.eye, c.target) {
                let d = [target[0] - eye[0], target[1] - eye[1], target[2] - eye[2]];
                let dn = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                if dn == 0.0 {
                    return Err(err(origin, "camera.target", format!("is {}, the same point as camera.eye; they must differ", short3(target))));
                }
                let cross = [d[1] * c.up[2] - d[2] * c.up[1], d[2] * c.up[0] - d[0] * c.up[2], d[0] * c.up[1] - d[1] * c.up[0]];
                let cn = (cross[0] * cross[0] + cross[1] * cross[1] + cross[2] * cross[2]).sqrt();
                if cn <= 1e-6 * dn * un {
                    return Err(err(origin, "camera.up", format!("is {}; must be non-zero and not parallel to the viewing direction", short3(c.up))));
                }
            }
            if !(c.fov_degrees.is_finite() && c.fov_degrees > 1.0 && c.fov_degrees < 170.0) {
                return Err(err(origin, "camera.fov_degrees", format!("is {}; must be between 1 and 170", short(c.fov_degrees))));
            }
        }
        positive("time.dt", self.time.dt)?;
        if self.time.dt < MIN_DT {
            return Err(err(origin, "time.dt", format!(
                "is {}; must be at least {} (the GPU steps time in f32, which holds no smaller step)", short(self.time.dt), short(MIN_DT))));
        }
        if self.time.dt > MAX_DT {
            return Err(err(origin, "time.dt", format!(
                "is {}; must be at most {} s (the GPU's f32 products of dt with speeds and accelerations would overflow)", short(self.time.dt), short(MAX_DT))));
        }
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
                    "block {}..{} is not inside the domain {}..{}", short3(b.min), short3(b.max), short3(self.domain.min), short3(self.domain.max))));
            }
            if !(b.jitter.is_finite() && (0.0..0.5).contains(&b.jitter)) {
                return Err(err(origin, format!("{f}.jitter"), format!("is {}; must be in [0, 0.5)", short(b.jitter))));
            }
            finite3(&format!("{f}.velocity"), b.velocity)?;
            let (_, fastest) = SPEED_OF_SOUND_RANGE;
            if b.velocity.iter().any(|c| c.abs() > fastest) {
                return Err(err(origin, format!("{f}.velocity"), format!(
                    "is {}; each component must be at most {} in size (the fastest speed of sound allowed)", short3(b.velocity), short(fastest))));
            }
        }
        for (i, b) in self.boundary.iter().enumerate() {
            let f = format!("boundary[{i}]");
            if let Boundary::Mesh(m) = b {
                finite3(&format!("{f}.scale"), m.scale)?;
                if m.scale.contains(&0.0) {
                    return Err(err(origin, format!("{f}.scale"), format!("is {}; every factor must be non-zero", short3(m.scale))));
                }
                finite3(&format!("{f}.translate"), m.translate)?;
                finite3(&format!("{f}.rotation_axis"), m.rotation_axis)?;
                // A turn of thousands of revolutions is a typo, and past some 1e15 degrees the
                // angle keeps no precision.
                if !(m.rotation_degrees.is_finite() && m.rotation_degrees.abs() <= MAX_ROTATION_DEGREES) {
                    return Err(err(origin, format!("{f}.rotation_degrees"), format!("is {}; must be a finite angle of at most {} degrees in size", short(m.rotation_degrees), short(MAX_ROTATION_DEGREES))));
                }
                if m.rotation_degrees != 0.0 && m.rotation_axis == [0.0; 3] {
                    return Err(err(origin, format!("{f}.rotation_axis"), "is zero; a rotation needs a non-zero axis"));
                }
                if let Some(crc) = &m.crc32 {
                    if !(crc.len() == 8 && crc.chars().all(|c| c.is_ascii_hexdigit())) {
                        return Err(err(origin, format!("{f}.crc32"), format!("is '{crc}'; must be the file's CRC-32 as 8 hexadecimal digits (or left out)")));
                    }
                }
                if m.surface.triangles().is_none() {
                    return Err(err(origin, format!("{f}.file"), format!("'{}' has not been read (a scene built in code reads its meshes with Scene::read_meshes)", m.file)));
                }
            }
            match b {
                Boundary::Container { .. } | Boundary::Box { .. } | Boundary::Mesh(_) => {
                    let walls = b.walls().expect("a particle boundary");
                    if let Boundary::Container { min, max, .. } | Boundary::Box { min, max, .. } = b {
                        ordered(&f, *min, *max)?;
                    }
                    let s = walls.spacing.unwrap_or(p.particle_spacing);
                    positive(&format!("{f}.spacing"), s)?;
                    if let Some(rd) = walls.rest_density {
                        positive(&format!("{f}.rest_density"), rd)?;
                        in_range(&format!("{f}.rest_density"), rd, REST_DENSITY_RANGE, "kg/m^3 in SI")?;
                        if p.boundary_volume == BoundaryVolume::Akinci {
                            return Err(err(origin, format!("{f}.rest_density"), format!(
                                "is {rd}; with physics.boundary_volume = \"akinci\" a wall particle's mass is rho0 / sum W over its wall neighbours, so a wall rest density is not used: remove it")));
                        }
                    }
                    if let Some(layers) = walls.layers.filter(|l| !(1..=MAX_WALL_LAYERS).contains(l)) {
                        return Err(err(origin, format!("{f}.layers"), format!(
                            "is {layers}; must be from 1 to {MAX_WALL_LAYERS} (the walls need only reach the kernel's support, h / spacing layers)")));
                    }
                    // The default, h / spacing layers, has a bound too.
                    let spacing = walls.spacing.unwrap_or(p.particle_spacing);
                    // (A wall spacing far below the fluid's is told by the particle count instead.)
                    let over = |s: f64| p.smoothing_length / s > MAX_DEFAULT_WALL_LAYERS as f64 + 1e-9;
                    if walls.layers.is_none() && over(spacing) && over(p.particle_spacing) {
                        return Err(err(origin, "physics.smoothing_length", format!(
                            "is {}, {} wall spacings ({}) of {f}: its walls would get as many layers, and at most {MAX_DEFAULT_WALL_LAYERS} are made; \
                             a smoothing length of 2 to 4 spacings is usual (give {f}.layers, from 1 to {MAX_WALL_LAYERS}, or a smaller h)",
                            short(p.smoothing_length), short(p.smoothing_length / spacing), short(spacing))));
                    }
                    let (lo, hi) = self.wall_span(b).expect("a particle boundary");
                    if !inside(lo) || !inside(hi) {
                        return Err(err(origin, &f, format!(
                            "its wall particles span {}..{}, outside the domain {}..{}; enlarge the domain",
                            short3(lo), short3(hi), short3(self.domain.min), short3(self.domain.max))));
                    }
                    // A solid thinner than the wall lattice would hold no wall particle, and the
                    // fluid would pass through it unseen.
                    if let Boundary::Mesh(m) = b {
                        if !self.mesh_index(m).has_band_point(self.domain.min, s, self.wall_thickness(walls), !m.fluid_inside) {
                            return Err(err(origin, &f, format!(
                                "no lattice point of the wall spacing {} lies on the walls' side of the mesh's surface (a solid thinner than that spacing would hold no wall particle); make it thicker, or give it a smaller spacing",
                                short(s))));
                        }
                    }
                }
                Boundary::Plane { point, normal, restitution } => {
                    finite3(&format!("{f}.point"), *point)?;
                    finite3(&format!("{f}.normal"), *normal)?;
                    // Normalised on load (`params`): its length must be a finite number away
                    // from 0, or the unit normal would be 0 or NaN.
                    // (Scaled by the largest component, so that a tiny one does not square to 0.)
                    let largest = normal.iter().fold(0.0f64, |m, c| m.max(c.abs()));
                    let length = if largest > 0.0 { largest * normal.iter().map(|c| (c / largest).powi(2)).sum::<f64>().sqrt() } else { 0.0 };
                    if !(1e-6..=1e150).contains(&length) {
                        return Err(err(origin, format!("{f}.normal"), format!(
                            "is {}, of length {}; must be a direction of length from 1e-6 to 1e150 (it is normalised)", short3(*normal), short(length))));
                    }
                    if !(restitution.is_finite() && (0.0..=1.0).contains(restitution)) {
                        return Err(err(origin, format!("{f}.restitution"), format!("is {}; must be in [0, 1]", short(*restitution))));
                    }
                }
            }
        }
        if self.boundary.iter().filter(|b| matches!(b, Boundary::Plane { .. })).count() > MAX_PLANES {
            return Err(err(origin, "boundary", format!("has more than {MAX_PLANES} planes")));
        }
        let boxes = self.boundary.iter().filter(|b| matches!(b, Boundary::Box { .. })).count();
        if boxes > MAX_SOLID_BOXES {
            return Err(err(origin, "boundary", format!("has {boxes} boxes; at most {MAX_SOLID_BOXES} are allowed (each is backed by its faces in the GPU's parameter block)")));
        }
        // A boundary given twice puts two walls in one place: its wall particles would count
        // twice in every density beside it (the fluid would start near 1.5 rho0 and be blown
        // apart, as if the speed of sound were too low).
        for (k, b) in self.boundary.iter().enumerate() {
            if let Some(j) = self.boundary[..k].iter().position(|a| a == b) {
                return Err(err(origin, format!("boundary[{k}]"), format!("repeats boundary[{j}]: the same wall twice would count its particles twice in every density beside it; remove one")));
            }
        }
        self.validate_overlaps(origin)?;
        self.validate_probes(origin)?;
        let grid = self.grid();
        let cells = lattice_size(grid.dims.iter().map(|&d| d as u64));
        if cells > MAX_CELLS {
            return Err(err(origin, "domain", format!(
                "needs {cells} grid cells of size h = {}; at most {MAX_CELLS} are allowed (shrink the domain or grow h)",
                p.smoothing_length)));
        }
        let count = self.estimated_particle_count();
        if count > MAX_PARTICLES {
            // The fluid's count, or else the walls' (their spacing, layers or size).
            let field = if self.fluid_particle_count() > MAX_PARTICLES { "fluid" } else { "boundary" };
            let count = if count == u64::MAX { "more than 1.8e19".to_string() } else { count.to_string() };
            return Err(err(origin, field, format!("would create {count} particles; at most {MAX_PARTICLES} are allowed")));
        }
        if let Some(message) = host_memory_shortfall(count, cells, SCENE_BYTES_PER_PARTICLE, "") {
            return Err(err(origin, "fluid", message));
        }
        Ok(())
    }

    /// The DFSPH settings: in range, and given only with `solver = "dfsph"`.
    fn validate_dfsph(&self, origin: &SceneOrigin) -> Result<(), SceneError> {
        let d = &self.physics.dfsph;
        if self.physics.solver == PressureSolver::Wcsph {
            if !d.is_default() {
                return Err(err(origin, "physics.dfsph", "applies only to physics.solver = \"dfsph\"; remove it or set the solver"));
            }
            return Ok(());
        }
        for (field, v) in [("physics.dfsph.density_error", d.density_error), ("physics.dfsph.divergence_error", d.divergence_error)] {
            if !(v.is_finite() && v > 0.0 && v < 1.0) {
                return Err(err(origin, field, format!("is {}; must be in (0, 1) (a fraction: 0.0001 is 0.01 %)", short(v))));
            }
        }
        for (what, min, max) in [("", d.min_iterations, d.max_iterations), ("divergence_", d.min_divergence_iterations, d.max_divergence_iterations)] {
            if !(1..=MAX_SOLVER_ITERATIONS).contains(&max) {
                return Err(err(origin, format!("physics.dfsph.max_{what}iterations"), format!("is {max}; must be from 1 to {MAX_SOLVER_ITERATIONS}")));
            }
            if min > max {
                return Err(err(origin, format!("physics.dfsph.min_{what}iterations"), format!("is {min}, above max_{what}iterations {max}; must be <= it")));
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
        for (field, v) in [("time.cfl_number", t.cfl_number_for(self.physics.solver)), ("time.force_number", t.force_number), ("time.viscous_number", t.viscous_number)] {
            if !(v.is_finite() && v > 0.0 && v <= 1.0) {
                return Err(err(origin, field, format!("is {}; must be in (0, 1]", short(v))));
            }
        }
        for (field, v) in [("time.dt_min", t.dt_min), ("time.dt_max", t.dt_max)] {
            if let Some(v) = v {
                if !(v.is_finite() && v > 0.0) {
                    return Err(err(origin, field, format!("is {}; must be a finite number > 0", short(v))));
                }
                if v > MAX_DT {
                    return Err(err(origin, field, format!("is {}; must be at most {} s, as time.dt", short(v), short(MAX_DT))));
                }
            }
        }
        if !t.adaptive && (t.dt_min.is_some() || t.dt_max.is_some()) {
            return Err(err(origin, "time.dt_min", "dt_min and dt_max need adaptive = true"));
        }
        if t.adaptive {
            let (lo, hi) = (t.dt_min.unwrap_or(t.dt * 1e-3), t.dt_max.unwrap_or(t.dt));
            if lo > hi {
                return Err(err(origin, "time.dt_min", format!("is {}, above dt_max {}; must be <= dt_max", short(lo), short(hi))));
            }
            // The GPU chooses the step in f32: a bound below its normal numbers is a step of 0,
            // and the run would never reach its end.
            if lo < MIN_DT {
                let field = if t.dt_min.is_some() { "time.dt_min" } else { "time.dt" };
                return Err(err(origin, field, format!(
                    "gives a smallest adaptive step of {}; must be at least {} (the GPU computes the step in f32, which holds no smaller step; dt_min defaults to dt / 1000)",
                    short(lo), short(MIN_DT))));
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

    /// Continuity density, density diffusion, artificial viscosity and the hydrostatic start:
    /// each value in its range, and each only where it means something.
    fn validate_pressure_options(&self, origin: &SceneOrigin) -> Result<(), SceneError> {
        let p = &self.physics;
        let continuity = p.density == DensityMethod::Continuity;
        if p.solver == PressureSolver::Dfsph {
            if continuity {
                return Err(err(origin, "physics.density", "is \"continuity\"; DFSPH keeps its density by its own solve: use density = \"summation\" with solver = \"dfsph\""));
            }
            if p.boundary_pressure == BoundaryPressure::Adami {
                return Err(err(origin, "physics.boundary_pressure", "is \"adami\", which extrapolates the wall particles' pressure from an equation of state's; DFSPH has its own wall terms: use boundary_pressure = \"mirror\" with solver = \"dfsph\", or solver = \"wcsph\""));
            }
            if p.artificial_viscosity != 0.0 {
                return Err(err(origin, "physics.artificial_viscosity", format!(
                    "is {}; Monaghan's artificial viscosity scales with the speed of sound, which DFSPH has none of: use viscosity, or solver = \"wcsph\"",
                    short(p.artificial_viscosity))));
            }
        }
        let (lo, hi) = DENSITY_DIFFUSION_RANGE;
        if !(p.density_diffusion.is_finite() && (lo..=hi).contains(&p.density_diffusion)) {
            return Err(err(origin, "physics.density_diffusion", format!(
                "is {}; must be between {} (off) and {} (delta of delta-SPH; 0.1 is usual)", short(p.density_diffusion), short(lo), short(hi))));
        }
        if p.density_diffusion > 0.0 && !continuity {
            return Err(err(origin, "physics.density_diffusion", format!(
                "is {}; density diffusion acts on the density that the continuity equation carries: add physics.density = \"continuity\", or set density_diffusion = 0",
                short(p.density_diffusion))));
        }
        let (lo, hi) = ARTIFICIAL_VISCOSITY_RANGE;
        if !(p.artificial_viscosity.is_finite() && (lo..=hi).contains(&p.artificial_viscosity)) {
            return Err(err(origin, "physics.artificial_viscosity", format!(
                "is {}; must be between {} (off) and {} (alpha of Monaghan's artificial viscosity; 0.01 to 0.1 is usual)",
                short(p.artificial_viscosity), short(lo), short(hi))));
        }
        let (lo, hi) = SURFACE_TENSION_RANGE;
        for (field, value, what) in [("surface_tension", p.surface_tension, "gamma of Akinci et al.'s surface tension; SPlisHSPlasH's default is 0.05"), ("wall_adhesion", p.wall_adhesion, "beta of Akinci et al.'s adhesion; SPlisHSPlasH's default is 0.01")] {
            if !(value.is_finite() && (lo..=hi).contains(&value)) {
                return Err(err(origin, format!("physics.{field}"), format!("is {}; must be between {} (off) and {} ({what})", short(value), short(lo), short(hi))));
            }
        }
        if p.wall_adhesion > 0.0 && !self.boundary.iter().any(|b| b.walls().is_some()) {
            return Err(err(origin, "physics.wall_adhesion", format!(
                "is {}; adhesion pulls the fluid towards wall particles and the scene has none (analytic planes have no particles): add a container, box or mesh boundary, or set wall_adhesion = 0",
                short(p.wall_adhesion))));
        }
        if p.initial_pressure == InitialPressure::Hydrostatic && !continuity {
            return Err(err(origin, "physics.initial_pressure", "is \"hydrostatic\", which sets each particle's density, and only the continuity equation keeps a density that was set: add physics.density = \"continuity\", or use initial_pressure = \"zero\""));
        }
        Ok(())
    }

    /// Fluid that could not start where it is: inside a solid (a box, a container's walls),
    /// behind a plane, or on top of another fluid block. Faces may touch.
    fn validate_overlaps(&self, origin: &SceneOrigin) -> Result<(), SceneError> {
        let tolerance = 1e-6 * self.physics.particle_spacing;
        let solids = self.named_solids();
        for (i, b) in self.fluid.iter().enumerate() {
            if let Some(a) = (0..3).find(|&a| self.fluid_lattice(i)[a].count == 0) {
                return Err(err(origin, format!("fluid[{i}]"), format!(
                    "is {} thick along {}, too thin for one layer of the particle spacing {}; make it thicker or the spacing smaller",
                    short(b.max[a] - b.min[a]), ["x", "y", "z"][a], short(self.physics.particle_spacing))));
            }
            let count = self.fluid_block_count(i);
            if count == 0 && self.boundary.iter().any(|b| matches!(b, Boundary::Mesh(_))) {
                return Err(err(origin, format!("fluid[{i}]"), format!(
                    "the block {}..{} has no lattice point on the fluid's side of the mesh boundaries at least half a spacing from their surfaces; move it into the fluid's space",
                    short3(b.min), short3(b.max))));
            }
            if count == 0 {
                return Err(err(origin, format!("fluid[{i}].shape"), format!(
                    "is \"{}\", and no lattice point of the box {}..{} lies inside it at the particle spacing {}; make the box larger or the spacing smaller",
                    b.shape.name(), short3(b.min), short3(b.max), short(self.physics.particle_spacing))));
            }
            // A shape is checked by its box: it starts clear of solids and other blocks.
            let block = (b.min, b.max);
            for (name, region, _) in &solids {
                if boxes_overlap(block, (region.min, region.max), tolerance) {
                    return Err(err(origin, format!("fluid[{i}]"), format!(
                        "the block {}..{} overlaps {name}, which fills {}..{}: fluid must start outside solids (a particle inside a wall is thrown out of it at the first step); move or shrink the block",
                        short3(b.min), short3(b.max), short3(region.min), short3(region.max))));
                }
            }
            for (k, other) in self.fluid.iter().enumerate().take(i) {
                if boxes_overlap(block, (other.min, other.max), tolerance) {
                    return Err(err(origin, format!("fluid[{i}]"), format!(
                        "the block {}..{} overlaps fluid[{k}] ({}..{}): their particles would sit on top of each other at twice the rest density; make the blocks meet at a face",
                        short3(b.min), short3(b.max), short3(other.min), short3(other.max))));
                }
            }
            for (k, boundary) in self.boundary.iter().enumerate() {
                let Boundary::Plane { point, normal, .. } = boundary else { continue };
                let len = normal.iter().map(|c| c * c).sum::<f64>().sqrt();
                let offset = (0..3).map(|a| normal[a] * point[a]).sum::<f64>() / len;
                // The corner deepest behind the plane.
                let deepest = (0..3).map(|a| normal[a] / len * if normal[a] < 0.0 { b.max[a] } else { b.min[a] }).sum::<f64>() - offset;
                if deepest < -tolerance {
                    return Err(err(origin, format!("fluid[{i}]"), format!(
                        "the block {}..{} reaches {} behind boundary[{k}] (the plane through {} with normal {}): fluid must start on the side the normal points to",
                        short3(b.min), short3(b.max), short(-deepest), short3(*point), short3(*normal))));
                }
            }
        }
        Ok(())
    }
}

/// Where the platform tells the host's available memory and `particles` particles at
/// `per_particle` bytes and a grid of `cells` cells (a start index each, and its count) need
/// more: the refusal's message (`user`, e.g. " on the cpu backend", says whose figure it is).
pub fn host_memory_shortfall(particles: u64, cells: u64, per_particle: u64, user: &str) -> Option<String> {
    host_memory_shortfall_with(particles, cells, per_particle, 0, user)
}

/// [`host_memory_shortfall`] with `extra` bytes besides (the CPU path's neighbour lists).
pub fn host_memory_shortfall_with(particles: u64, cells: u64, per_particle: u64, extra: u64, user: &str) -> Option<String> {
    let available = available_memory_bytes()?;
    let need = particles.saturating_mul(per_particle).saturating_add(cells.saturating_mul(8)).saturating_add(extra);
    (need > available).then(|| {
        format!("{particles} particles (fluid and walls) and {cells} cells need about {} MiB of host memory{user}; {} MiB are available", need >> 20, available >> 20)
    })
}

/// Bytes the CPU path's neighbour lists hold per fluid particle beyond [`CPU_BYTES_PER_PARTICLE`]
/// (which covers a support of two spacings): an index of 4 bytes per neighbour at rest, 4/3 pi
/// (h / s)^3 of them. Measured peak resident memory of 2-step runs fell 12-25 % below this model
/// from h / s = 8 to 16 (1,000 to 64,000 fluid particles among 28,000 to 690,000 wall particles);
/// at h / s = 16 the lists take about 65 KB per fluid particle.
pub fn cpu_list_bytes_per_fluid_particle(h: f64, spacing: f64) -> u64 {
    (4.0 * 4.0 / 3.0 * std::f64::consts::PI * (h / spacing).powi(3)).ceil() as u64
}

/// Host memory available to this process, where the platform tells.
pub fn available_memory_bytes() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// Whether the particle lattice starts at its rest density with the scene's kernel.
impl Scene {
    /// The density the kernel sum gives a fluid particle deep inside a block at rest, over rho0:
    /// sum over the simple cubic lattice of spacing s of m W(|x|, h) / rho0, with the scene's
    /// kernel, h and particle mass. About 1 where h suits the kernel (with m = rho0 s^3: the
    /// cubic spline from 2 spacings, Mueller's within 1 % from 2, Wendland's within 0.5 % from 3).
    pub fn lattice_rest_density_ratio(&self) -> f64 {
        let p = &self.physics;
        let mass = p.fluid_mass();
        super::kernels::lattice_kernel_sum(p.kernel, p.smoothing_length / p.particle_spacing) * mass / (p.rest_density * p.particle_spacing.powi(3))
    }

    /// Whether a fluid particle inside a block starts more than 2 % off its rest density: its
    /// ratio to rho0 (see [`Scene::lattice_rest_density_ratio`]) where it does.
    pub fn start_off_rest_density(&self) -> Option<f64> {
        let ratio = self.lattice_rest_density_ratio();
        ((ratio - 1.0).abs() > 0.02).then_some(ratio)
    }

    /// What starts the fluid at rest with the scene's kernel: the smoothing length (in
    /// spacings) whose lattice sum is within 0.5 % of 1, where one up to 5 spacings is, and the
    /// particle mass that makes today's sum 1.
    pub fn rest_density_fix(&self) -> String {
        let p = &self.physics;
        let ratio = self.lattice_rest_density_ratio();
        let suits = (4..=10).map(|k| k as f64 * 0.5).find(|&r| (super::kernels::lattice_kernel_sum(p.kernel, r) - 1.0).abs() <= 0.005);
        format!(
            "{}or set physics.particle_mass = {} to start at rho0",
            suits.map(|r| format!("with this kernel a smoothing length of {} spacings ({} rho0) starts at rest, ", short(r), short(super::kernels::lattice_kernel_sum(p.kernel, r)))).unwrap_or_default(),
            short(p.fluid_mass() / ratio)
        )
    }

    /// The depth of the deepest fluid block along gravity (its largest extent without gravity).
    pub fn fluid_depth(&self) -> f64 {
        let g = self.physics.gravity;
        let g_norm = g.iter().map(|v| v * v).sum::<f64>().sqrt();
        let extent = |b: &super::scene::FluidBlock| -> f64 {
            let size: [f64; 3] = std::array::from_fn(|a| b.max[a] - b.min[a]);
            match g_norm > 0.0 {
                true => (0..3).map(|a| size[a] * g[a].abs() / g_norm).sum(),
                false => size.iter().cloned().fold(0.0, f64::max),
            }
        };
        self.fluid.iter().map(extent).fold(0.0, f64::max)
    }

    /// A warning when a fluid particle inside a block starts more than 2 % off its rest density
    /// (see [`Scene::lattice_rest_density_ratio`]): the equation of state (or DFSPH's solve)
    /// then pushes the fluid apart, or pulls it together, from the first step.
    pub fn rest_density_warning(&self) -> Option<String> {
        let ratio = self.start_off_rest_density()?;
        let p = &self.physics;
        let over = p.smoothing_length / p.particle_spacing;
        let kernel = serde_json::to_string(&p.kernel).unwrap_or_default();
        // DFSPH's constant-density solve takes the whole excess out in its first steps, however
        // small dt is: the deeper the fluid in smoothing lengths, the more violently.
        let dfsph = match p.solver == PressureSolver::Dfsph {
            true => format!(
                " (DFSPH's constant-density solve does it within its first steps: a column {} deep has to change its height by {}, {} smoothing lengths, at once)",
                short(self.fluid_depth()),
                short((ratio - 1.0).abs() * self.fluid_depth()),
                short((ratio - 1.0).abs() * self.fluid_depth() / p.smoothing_length)
            ),
            false => String::new(),
        };
        Some(format!(
            "physics.kernel = {kernel} with physics.smoothing_length = {} ({} particle spacings): a fluid particle inside a block starts at {} rho0 (the kernel's sum over the lattice), not at its rest density, so the fluid is pushed {} from the first step{dfsph}; {}",
            short(p.smoothing_length),
            short(over),
            short(ratio),
            if ratio > 1.0 { "apart" } else { "together" },
            self.rest_density_fix()
        ))
    }

    /// A warning for each setting given a value other than its default that the scene's other
    /// settings leave unused (a weakly compressible setting under DFSPH, an adaptive step's
    /// number with a fixed dt, a wall particle setting without wall particles, a divergence
    /// solve setting with that solve off): the run goes on, and says it does not use them.
    pub fn unused_settings(&self) -> Vec<String> {
        let p = &self.physics;
        let d = Physics::new(p.smoothing_length, p.particle_spacing);
        let mut unused = Vec::new();
        let mut not_used = |given: bool, field: &str, value: String, because: &str| {
            if given {
                unused.push(format!("{field} = {value} is not used: {because}; it changes nothing in this run"));
            }
        };
        // An enum's value as a scene file writes it ("tait").
        fn json<T: serde::Serialize>(v: &T) -> String {
            serde_json::to_string(v).unwrap_or_default()
        }
        if p.solver == PressureSolver::Dfsph {
            let why = "solver = \"dfsph\" has no equation of state (its pressure comes from its incompressibility solve, which keeps it >= 0)";
            not_used(p.equation_of_state != d.equation_of_state, "physics.equation_of_state", json(&p.equation_of_state), why);
            not_used(p.clamp_negative_pressure != d.clamp_negative_pressure, "physics.clamp_negative_pressure", p.clamp_negative_pressure.to_string(), why);
            not_used(p.boundary_pressure != d.boundary_pressure, "physics.boundary_pressure", json(&p.boundary_pressure), "DFSPH's solve takes the walls' pressure as the fluid particle's own");
            let l = Limits::default();
            let mach = "solver = \"dfsph\" has no speed of sound to measure a Mach number against";
            not_used(self.limits.max_mach != l.max_mach, "limits.max_mach", short(self.limits.max_mach), mach);
            not_used(self.limits.warn_mach != l.warn_mach, "limits.warn_mach", short(self.limits.warn_mach), mach);
            let (s, ds) = (&p.dfsph, DfsphSettings::default());
            if !s.divergence_solve {
                let off = "physics.dfsph.divergence_solve = false";
                not_used(s.divergence_error != ds.divergence_error, "physics.dfsph.divergence_error", short(s.divergence_error), off);
                not_used(s.min_divergence_iterations != ds.min_divergence_iterations, "physics.dfsph.min_divergence_iterations", s.min_divergence_iterations.to_string(), off);
                not_used(s.max_divergence_iterations != ds.max_divergence_iterations, "physics.dfsph.max_divergence_iterations", s.max_divergence_iterations.to_string(), off);
            }
        }
        if !self.time.adaptive {
            let t = Time::fixed(self.time.dt, self.time.end_time);
            let fixed = "time.adaptive = false runs at the fixed time.dt";
            not_used(self.time.cfl_number.is_some(), "time.cfl_number", short(self.time.cfl_number.unwrap_or_default()), fixed);
            not_used(self.time.force_number != t.force_number, "time.force_number", short(self.time.force_number), fixed);
            not_used(self.time.viscous_number != t.viscous_number, "time.viscous_number", short(self.time.viscous_number), fixed);
        }
        if self.boundary.iter().all(|b| matches!(b, Boundary::Plane { .. })) {
            let planes = "the scene has no wall particles (its boundaries are planes)";
            not_used(p.boundary_pressure != d.boundary_pressure && p.solver != PressureSolver::Dfsph, "physics.boundary_pressure", json(&p.boundary_pressure), planes);
            not_used(p.boundary_volume != d.boundary_volume, "physics.boundary_volume", json(&p.boundary_volume), planes);
            not_used(p.boundary_friction != d.boundary_friction, "physics.boundary_friction", short(p.boundary_friction), planes);
        }
        unused
    }
}
