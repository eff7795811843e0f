//! Probes: quantities sampled during a run at fixed places (`[[probe]]` tables of a scene), as
//! time series. What each type measures and how is documented in docs/probes.md; the sampling
//! itself is a stage of the solvers (wgsl/sim/probes.wgsl and its CPU twin).
//!
//! - `point`: pressure, density and velocity at a point, kernel-weighted over the fluid
//!   particles within h and normalised by their kernel sum (Shepard); wall particles take no
//!   part, so a point on a wall reads the fluid beside it.
//! - `gauge`: the water's surface on a vertical line: the highest point where the kernel-summed
//!   fluid fraction sum_j (m_j / rho_j) W reaches 0.5.
//! - `force`: the force and moment the fluid exerts on a solid's wall particles: the reaction
//!   of the pressure and viscous terms the walls exert on the fluid.
//! - `front`: the farthest fluid along a direction among the particles near the floor.

use super::numbers::{short, short3};
use super::scene::{err, Boundary, ProbeType, Scene, SceneError, SceneOrigin};
// The `[[probe]]` table is part of the scene schema (scene.rs); named here too, with the probes.
pub use super::scene::ProbeSpec;

/// Most force probes and most front probes a scene may have (each reduces over every fluid
/// particle; the GPU keeps their sums in registers).
pub const MAX_FORCE_PROBES: usize = 4;
pub const MAX_FRONT_PROBES: usize = 4;
/// Most probes of all types.
pub const MAX_PROBES: usize = 64;
/// How far from the domain a force probe's `moment_about` may lie, in domain sizes.
pub const MOMENT_ARM_DOMAINS: f64 = 1000.0;
/// Fluid fraction at which a gauge finds the surface.
pub const GAUGE_FRACTION: f64 = 0.5;
/// A gauge's levels are this fraction of the particle spacing apart.
pub const GAUGE_LEVELS_PER_SPACING: f64 = 4.0;

/// How often a probe samples: every K steps, or at the first step reaching each multiple of an
/// interval of simulated time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ProbeInterval {
    Steps(u64),
    Seconds(f64),
}

/// A probe resolved for the solvers: defaults filled, the wall particles a force probe reads
/// chosen by [`Probe::takes_wall`].
#[derive(Clone, Debug, PartialEq)]
pub struct Probe {
    pub name: String,
    pub interval: ProbeInterval,
    pub geometry: ProbeGeometry,
}

#[derive(Clone, Debug, PartialEq)]
pub enum ProbeGeometry {
    Point { position: [f64; 3] },
    /// Levels from `top` down to `bottom`, `step` apart.
    Gauge { x: f64, z: f64, bottom: f64, top: f64, step: f64 },
    /// The wall particles of `boundary` inside [min, max]; the moment about `centre`.
    Force { boundary: usize, min: [f64; 3], max: [f64; 3], centre: [f64; 3] },
    Front { direction: [f64; 3], floor: f64, height: f64 },
}

impl ProbeGeometry {
    /// The type's name in a scene.
    pub fn type_name(&self) -> &'static str {
        match self {
            ProbeGeometry::Point { .. } => "point",
            ProbeGeometry::Gauge { .. } => "gauge",
            ProbeGeometry::Force { .. } => "force",
            ProbeGeometry::Front { .. } => "front",
        }
    }

    /// The columns of the type's time series after `time_s,step`, in SI units.
    pub fn columns(&self) -> &'static [&'static str] {
        match self {
            ProbeGeometry::Point { .. } => &["pressure_Pa", "density_kg_m3", "vx_m_s", "vy_m_s", "vz_m_s", "fluid_fraction"],
            ProbeGeometry::Gauge { .. } => &["surface_y_m", "height_m"],
            ProbeGeometry::Force { .. } => &["fx_N", "fy_N", "fz_N", "mx_Nm", "my_Nm", "mz_Nm"],
            ProbeGeometry::Front { .. } => &["front_m", "particles"],
        }
    }
}

impl Probe {
    /// Whether this probe samples the state reached after `step` steps, at `time`, whose
    /// previous step ended at `previous_time`.
    pub fn due(&self, step: u64, time: f64, previous_time: f64) -> bool {
        match self.interval {
            ProbeInterval::Steps(k) => step % k.max(1) == 0,
            // The first state at or past each multiple of the interval (a relative 1e-9 keeps a
            // time that lands on a multiple up to rounding on the multiple's side).
            ProbeInterval::Seconds(every) => step == 0 || (time / every + 1e-9).floor() > (previous_time / every + 1e-9).floor(),
        }
    }

    /// Whether wall particle `x` of boundary `boundary` is one a force probe reads.
    pub fn takes_wall(&self, boundary: usize, x: [f64; 3]) -> bool {
        match &self.geometry {
            ProbeGeometry::Force { boundary: b, min, max, .. } => *b == boundary && (0..3).all(|a| x[a] >= min[a] && x[a] <= max[a]),
            _ => false,
        }
    }
}

/// The probes of a scene, resolved, in the order of the scene's tables.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Probes {
    pub probes: Vec<Probe>,
}

impl Probes {
    pub fn is_empty(&self) -> bool {
        self.probes.is_empty()
    }

    /// Values of one sample: every probe's columns, in order.
    pub fn value_count(&self) -> usize {
        self.probes.iter().map(|p| p.geometry.columns().len()).sum()
    }

    /// The first value of each probe in a sample.
    pub fn offsets(&self) -> Vec<usize> {
        let mut at = 0;
        self.probes
            .iter()
            .map(|p| {
                let o = at;
                at += p.geometry.columns().len();
                o
            })
            .collect()
    }

    /// Whether a solver samples the state after `step` steps: when some probe is due there.
    /// With a fixed dt the time of a step is `step dt`; with adaptive dt a probe timed in
    /// seconds needs every step sampled (the time of a step is known only on the device), and
    /// the writer keeps the due ones ([`Probe::due`] with each sample's times).
    pub fn samples_step(&self, step: u64, dt: f64, adaptive: bool) -> bool {
        let t = |n: u64| n as f64 * dt;
        self.probes.iter().any(|p| match p.interval {
            ProbeInterval::Seconds(_) if adaptive => true,
            _ => p.due(step, t(step), t(step.saturating_sub(1))),
        })
    }

    /// The force probes, in order (their index is their bit in the wall particles' masks).
    pub fn force_count(&self) -> usize {
        self.probes.iter().filter(|p| matches!(p.geometry, ProbeGeometry::Force { .. })).count()
    }
    pub fn front_count(&self) -> usize {
        self.probes.iter().filter(|p| matches!(p.geometry, ProbeGeometry::Front { .. })).count()
    }

    /// Each wall particle's mask of the force probes that read it (bit k: the k-th force
    /// probe), from the boundary each particle belongs to.
    pub fn wall_masks(&self, wall_positions: &[[f64; 3]], wall_boundaries: &[u32]) -> Vec<u32> {
        let forces: Vec<&Probe> = self.probes.iter().filter(|p| matches!(p.geometry, ProbeGeometry::Force { .. })).collect();
        wall_positions
            .iter()
            .zip(wall_boundaries)
            .map(|(&x, &b)| forces.iter().enumerate().filter(|(_, p)| p.takes_wall(b as usize, x)).fold(0u32, |m, (k, _)| m | 1 << k))
            .collect()
    }
}

/// One sample of every probe of a scene, as a solver takes it: the state after `step` steps,
/// at `time`, whose previous step ended at `previous_time`; `values` holds every probe's
/// columns in order ([`Probes::offsets`]).
#[derive(Clone, Debug, PartialEq)]
pub struct ProbeSample {
    pub step: u64,
    pub time: f64,
    pub previous_time: f64,
    pub values: Vec<f64>,
}

/// The longest probe name (a row's probes' names with their `_0`, `_1`, ... too).
const MAX_NAME: usize = 64;

/// Whether a name can be a file name on every platform: letters, digits, `_` and `-`.
fn file_safe(name: &str) -> bool {
    !name.is_empty() && name.len() <= MAX_NAME && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
}

impl Scene {
    /// The scene's probes with their defaults filled (the scene is validated).
    pub fn probes(&self) -> Probes {
        let s = self.physics.particle_spacing;
        let h = self.physics.smoothing_length;
        let floor = self.fluid.iter().map(|b| b.min[1]).fold(f64::INFINITY, f64::min);
        let probes = self
            .probe
            .iter()
            .flat_map(|p| p.row().into_iter().map(move |(name, position)| (p, name, position)))
            .map(|(p, name, position)| {
                let geometry = match p.kind {
                    ProbeType::Point => ProbeGeometry::Point { position: position.unwrap_or_default() },
                    ProbeType::Gauge => {
                        let position = position.unwrap_or_default();
                        ProbeGeometry::Gauge {
                            x: position[0],
                            z: position[2],
                            bottom: position[1],
                            top: p.top.unwrap_or(self.domain.max[1]),
                            step: s / GAUGE_LEVELS_PER_SPACING,
                        }
                    }
                    ProbeType::Force => {
                        let boundary = p.boundary.unwrap_or_default();
                        let (lo, hi) = self.boundary_extent(boundary);
                        ProbeGeometry::Force {
                            boundary,
                            min: p.min.unwrap_or([f64::NEG_INFINITY; 3]),
                            max: p.max.unwrap_or([f64::INFINITY; 3]),
                            centre: p.moment_about.unwrap_or(std::array::from_fn(|a| 0.5 * (lo[a] + hi[a]))),
                        }
                    }
                    ProbeType::Front => {
                        let direction = p.direction.unwrap_or([1.0, 0.0, 0.0]);
                        let len = direction.iter().map(|c| c * c).sum::<f64>().sqrt();
                        ProbeGeometry::Front {
                            direction: direction.map(|c| c / len),
                            floor: p.floor.unwrap_or(if floor.is_finite() { floor } else { self.domain.min[1] }),
                            height: p.height.unwrap_or(h),
                        }
                    }
                };
                let interval = match (p.every_steps, p.every_seconds) {
                    (_, Some(t)) => ProbeInterval::Seconds(t),
                    (Some(k), None) => ProbeInterval::Steps(k),
                    (None, None) => ProbeInterval::Steps(1),
                };
                Probe { name, interval, geometry }
            })
            .collect();
        Probes { probes }
    }

    /// The box a box, container or mesh boundary spans (a container's cavity).
    fn boundary_extent(&self, index: usize) -> ([f64; 3], [f64; 3]) {
        match self.boundary.get(index) {
            Some(Boundary::Box { min, max, .. }) | Some(Boundary::Container { min, max, .. }) => (*min, *max),
            Some(Boundary::Mesh(m)) => m.bounds(),
            _ => ([0.0; 3], [0.0; 3]),
        }
    }

    /// Every `[[probe]]` table checked: names unique and file-safe, geometry inside the domain
    /// and outside every solid, intervals and counts within bounds.
    pub(crate) fn validate_probes(&self, origin: &SceneOrigin) -> Result<(), SceneError> {
        // Every probe a table declares (a row declares several), by name.
        let mut names: Vec<(String, usize)> = Vec::new();
        for (i, p) in self.probe.iter().enumerate() {
            let refuse = |f: &str, why: &str| err(origin, format!("probe[{i}] ('{}').{f}", p.name), why.to_string());
            // (A type without rows is told below that the fields do not apply to it.)
            let rows = matches!(p.kind, ProbeType::Point | ProbeType::Gauge);
            match if rows { (p.to, p.count) } else { (None, None) } {
                (Some(_), None) => return Err(refuse("to", "is given without count; a row of probes needs both (count = N probes from position to to)")),
                (None, Some(_)) => return Err(refuse("count", "is given without to; a row of probes needs both (count = N probes from position to to)")),
                (_, Some(n)) if !(2..=MAX_PROBES as u32).contains(&n) => {
                    return Err(refuse("count", &format!("is {n}; a row holds 2 to {MAX_PROBES} probes")));
                }
                _ => {}
            }
            names.extend(p.row().into_iter().map(|(name, _)| (name, i)));
        }
        if names.len() > MAX_PROBES {
            return Err(err(origin, "probe", format!("declares {} probes (a row counting each of its own); at most {MAX_PROBES} are allowed", names.len())));
        }
        for (k, (name, i)) in names.iter().enumerate() {
            // A row's probes add _0, _1, ... to its name, which must still name a file.
            if name.len() > MAX_NAME {
                return Err(err(origin, format!("probe[{i}].name"), format!(
                    "gives the row's probe '{name}', {} characters; a probe's name is at most {MAX_NAME} (a row adds _0, _1, ...): shorten it", name.len())));
            }
            if let Some((_, j)) = names[..k].iter().find(|(other, j)| other == name && j != i) {
                return Err(err(origin, format!("probe[{i}].name"), format!(
                    "gives the probe '{name}', which probe[{j}] declares too; names must be unique (each has its own file, and a row's are NAME_0, NAME_1, ...)")));
            }
        }
        let (lo, hi) = (self.domain.min, self.domain.max);
        let solids = self.named_solids();
        let meshes: Vec<_> = self
            .boundary
            .iter()
            .enumerate()
            .filter_map(|(k, b)| match b {
                Boundary::Mesh(m) if !self.probe.is_empty() => Some((k, self.mesh_index(m), m.fluid_inside, self.wall_thickness(&m.walls))),
                _ => None,
            })
            .collect();
        let tolerance = 1e-9 * self.physics.particle_spacing;
        let mut forces = 0;
        let mut fronts = 0;
        for (i, p) in self.probe.iter().enumerate() {
            let field = |f: &str| format!("probe[{i}] ('{}').{f}", p.name);
            if !file_safe(&p.name) {
                return Err(err(origin, format!("probe[{i}].name"), format!(
                    "is '{}'; a probe's name names its file probes/NAME.csv: 1 to 64 letters, digits, '_' or '-'", p.name)));
            }
            match (p.every_steps, p.every_seconds) {
                (Some(_), Some(_)) => {
                    return Err(err(origin, field("every_steps"), "and every_seconds are both given; give one (every K steps, or every T seconds of simulated time)"));
                }
                (Some(0), None) => return Err(err(origin, field("every_steps"), "is 0; must be at least 1")),
                (None, Some(t)) if !(t.is_finite() && t > 0.0) => {
                    return Err(err(origin, field("every_seconds"), format!("is {}; must be a finite number > 0", short(t))));
                }
                _ => {}
            }
            // A point that must lie inside the domain and outside every solid (on a face is fine).
            // (`f` names the field.)
            let placed = |f: &str, x: [f64; 3]| -> Result<(), SceneError> {
                if !x.iter().all(|c| c.is_finite()) {
                    return Err(err(origin, f, format!("is {}; every component must be finite", short3(x))));
                }
                if (0..3).any(|a| x[a] < lo[a] || x[a] > hi[a]) {
                    return Err(err(origin, f, format!("{} lies outside the domain {}..{}; a probe must be inside it", short3(x), short3(lo), short3(hi))));
                }
                for (name, r, _) in &solids {
                    if (0..3).all(|a| x[a] > r.min[a] + tolerance && x[a] < r.max[a] - tolerance) {
                        return Err(err(origin, f, format!(
                            "{} lies inside {name}, which fills {}..{}; a probe must be in the fluid's space (on a solid's face is allowed)",
                            short3(x), short3(r.min), short3(r.max))));
                    }
                }
                for (k, index, fluid_inside, thickness) in &meshes {
                    // On the walls' side of the surface (not on it): inside a solid mesh, or
                    // within a tank mesh's walls.
                    let depth = index.distance_within_reach(x).unwrap_or(f64::INFINITY);
                    let in_walls = if *fluid_inside { !index.inside(x) && depth < *thickness } else { index.inside(x) };
                    if in_walls && depth > tolerance {
                        let what = if *fluid_inside { "the walls of" } else { "the solid of" };
                        return Err(err(origin, f, format!(
                            "{} lies in {what} boundary[{k}] (the mesh); a probe must be in the fluid's space (on the mesh's surface is allowed)",
                            short3(x))));
                    }
                }
                Ok(())
            };
            if let Some(f) = p.given().into_iter().find(|f| !p.kind.fields().contains(f)) {
                let kind = format!("{:?}", p.kind).to_lowercase();
                return Err(err(origin, field(f), format!(
                    "does not apply to a probe of type \"{kind}\"; its fields are {} (and name, type, every_steps or every_seconds)", p.kind.fields().join(", "))));
            }
            let finite3 = |f: &str, v: &Option<[f64; 3]>| -> Result<(), SceneError> {
                match v {
                    Some(v) if !v.iter().all(|c| c.is_finite()) => Err(err(origin, field(f), format!("is {}; every component must be finite", short3(*v)))),
                    _ => Ok(()),
                }
            };
            match p.kind {
                ProbeType::Point | ProbeType::Gauge => {
                    let Some(position) = p.position else {
                        return Err(err(origin, field("position"), "is missing; a point or gauge probe needs position = [x, y, z]"));
                    };
                    placed(&field("position"), position)?;
                    if let Some(to) = p.to {
                        placed(&field("to"), to)?;
                    }
                    // Each probe of a row, and each gauge's top (a table without a row is its
                    // one probe, placed above).
                    for (name, at) in p.row() {
                        let at = at.unwrap_or(position);
                        if p.count.is_some() {
                            placed(&format!("probe[{i}] ('{}'), the row's probe '{name}' at", p.name), at)?;
                        }
                        if let Some(t) = p.top {
                            if !(t.is_finite() && t > at[1] && t <= hi[1]) {
                                return Err(err(origin, field("top"), format!(
                                    "is {}; must be above the bottom y = {} of the gauge '{name}' and at most the domain's top {}", short(t), short(at[1]), short(hi[1]))));
                            }
                        }
                    }
                }
                ProbeType::Force => {
                    forces += 1;
                    let Some(boundary) = p.boundary else {
                        return Err(err(origin, field("boundary"), "is missing; a force probe needs boundary = INDEX, the index of a box, container or mesh in the [[boundary]] list (from 0)"));
                    };
                    match self.boundary.get(boundary) {
                        Some(Boundary::Box { .. }) | Some(Boundary::Container { .. }) | Some(Boundary::Mesh(_)) => {}
                        Some(Boundary::Plane { .. }) => {
                            return Err(err(origin, field("boundary"), format!(
                                "is {boundary}, an analytic plane, which has no wall particles to feel a force; must be the index of a box, container or mesh")));
                        }
                        None => {
                            return Err(err(origin, field("boundary"), format!(
                                "is {boundary}; the scene has {} [[boundary]] tables (indices from 0); must be the index of a box, container or mesh", self.boundary.len())));
                        }
                    }
                    finite3("min", &p.min)?;
                    finite3("max", &p.max)?;
                    finite3("moment_about", &p.moment_about)?;
                    // The moment's arm: a point a thousand domains away turns every force into
                    // a moment beyond the GPU's f32.
                    if let Some(c) = p.moment_about {
                        let size = (0..3).map(|k| self.domain.max[k] - self.domain.min[k]).fold(0.0f64, f64::max);
                        let reach = MOMENT_ARM_DOMAINS * size;
                        if (0..3).any(|k| c[k] < self.domain.min[k] - reach || c[k] > self.domain.max[k] + reach) {
                            return Err(err(origin, field("moment_about"), format!(
                                "is {}; must lie within {} domain sizes ({}) of the domain {}..{}",
                                short3(c), short(MOMENT_ARM_DOMAINS), short(reach), short3(self.domain.min), short3(self.domain.max))));
                        }
                    }
                    if let (Some(a), Some(b)) = (p.min, p.max) {
                        if (0..3).any(|k| b[k] < a[k]) {
                            return Err(err(origin, field("min"), format!("{} must not be above max {} on any axis", short3(a), short3(b))));
                        }
                    }
                }
                ProbeType::Front => {
                    fronts += 1;
                    if let Some(direction) = p.direction {
                        let len = direction.iter().map(|c| c * c).sum::<f64>().sqrt();
                        if !(len.is_finite() && len > 0.0) {
                            return Err(err(origin, field("direction"), format!("is {}; must be a finite, non-zero vector", short3(direction))));
                        }
                    }
                    if let Some(f) = p.floor {
                        if !(f.is_finite() && f >= lo[1] && f <= hi[1]) {
                            return Err(err(origin, field("floor"), format!("is {}; must lie within the domain's y range {}..{}", short(f), short(lo[1]), short(hi[1]))));
                        }
                    }
                    if let Some(h) = p.height {
                        if !(h.is_finite() && h > 0.0) {
                            return Err(err(origin, field("height"), format!("is {}; must be a finite number > 0", short(h))));
                        }
                    }
                }
            }
        }
        if forces > MAX_FORCE_PROBES {
            return Err(err(origin, "probe", format!("has {forces} force probes; at most {MAX_FORCE_PROBES} are allowed")));
        }
        if fronts > MAX_FRONT_PROBES {
            return Err(err(origin, "probe", format!("has {fronts} front probes; at most {MAX_FRONT_PROBES} are allowed")));
        }
        Ok(())
    }
}
