//! Why a run went bad: the message a failed run prints and writes into its summary, from what
//! was measured at its first bad step (its counts, largest density and speed, dt and time) and
//! where the fluid was when the failure was found. Each stability condition is checked against
//! those figures, and only a condition that they break is named as the cause; when none is
//! broken the message says the cause is unknown, with the figures.

use super::numbers::{short, short3, short_time};
use super::initial::SolidRegion;
use super::kernels::KernelCoefficients;
use super::params::Params;
use super::scene::{Boundary, Scene};
use super::state::{BadStep, Health, SnapshotExtremes};

/// The CFL number dt (c0 + |v|max) / h above which explicit weakly compressible SPH goes
/// unstable (h the support radius; Monaghan 1992 gives 0.25 on h/2 ... h, the built-in scenes
/// run at 0.225-0.25 on the support radius).
pub const CFL_LIMIT: f64 = 0.4;
/// The CFL number dt |v|max / h (h the support radius) DFSPH should stay below: with no sound
/// to outrun, its condition is on the flow speed alone.
pub const DFSPH_CFL_LIMIT: f64 = 0.25;
/// A DFSPH run that goes bad within this many steps of its start, from fluid that starts off
/// its rest density, is named as thrown apart by its start.
pub const START_STEPS: u64 = 20;
/// The viscous condition dt <= 0.125 h^2 / nu (Morris et al. 1997, Eq. 27).
pub const VISCOUS_NUMBER: f64 = 0.125;
/// The force condition dt <= 0.25 sqrt(h / |a|) (Monaghan 1992).
pub const FORCE_NUMBER: f64 = 0.25;
/// The largest surface tension gamma and wall adhesion beta that the diagnosis takes for usual:
/// gamma 0.05 (SPlisHSPlasH's default) to 1 holds a drop together, beta 0.01 to 5 wets a wall
/// (tests/physics/surface_tension.rs spreads a drop with 5). Where a blow-up follows larger
/// values, it names them.
pub const SURFACE_TENSION_USUAL: f64 = 1.0;
pub const WALL_ADHESION_USUAL: f64 = 5.0;

/// The diffusion number delta c0 dt / h of delta-SPH's density diffusion (coefficient
/// delta h c0, h the support radius) above which the explicit step amplifies density noise
/// instead of damping it, like an explicit heat equation past dt D / h^2 of order 0.1-0.5.
/// Measured with delta = 1 on a block falling in a tank (docs/pressure.md): at h = 2 spacings
/// it held at 0.165 and went bad at 0.18 with 0.01 m spacings, at 0.21 with 0.02 m.
pub const DIFFUSION_NUMBER: f64 = 0.16;

/// The cause of a run stopped because a snapshot showed a density of zero or below, which no
/// step's check sees: a continuity density (the only kind that can fall so) driven below zero.
pub fn diagnose_non_positive_density(scene: &Scene, step: u64, time: f64, e: &SnapshotExtremes) -> String {
    let params = scene.params();
    let mut msg = format!(
        "step {step} (t = {}): the density of {} particles fell to zero or below (down to {} kg/m^3, rest density {}), which no fluid can hold.",
        short_time(time),
        e.non_positive_density,
        short(e.min_density),
        short(params.rest_density)
    );
    let diffusion = diffusion_number(&params, params.dt);
    if diffusion > DIFFUSION_NUMBER {
        msg += &format!(" Cause: {}.", diffusion_cause(&params, params.dt, diffusion));
    } else {
        msg += &format!(
            " Cause: the continuity equation (physics.density = \"continuity\") integrates each density from the flow's divergence, and a step too long for how fast \
             that changes drove it below zero: lower time.dt (now {}){}.",
            short(params.dt),
            if params.density_diffusion > 0.0 { format!(", or physics.density_diffusion (delta = {})", short(params.density_diffusion)) } else { String::new() }
        );
    }
    msg
}

/// How to bring the step `dt` down below `limit` (`to_limit` says it: "below 1e-4"): time.dt,
/// or with adaptive dt its CFL number, unless the adaptive step was held at time.dt_min, which
/// is then what has to go lower.
fn lower_dt(params: &Params, dt: f64, to_limit: &str, limit: f64) -> String {
    let to_limit = if to_limit.is_empty() { String::new() } else { format!(" {to_limit}") };
    match &params.adaptive {
        Some(a) if dt <= a.dt_min * (1.0 + 1e-6) => {
            format!("time.dt_min = {} held the adaptive step there, above what the flow allows: lower time.dt_min below {}", short(a.dt_min), short(limit))
        }
        Some(_) => format!("lower time.dt{to_limit} or time.cfl_number"),
        None => format!("lower time.dt{to_limit}, or set time.adaptive = true"),
    }
}

/// delta c0 dt / h of a scene's density diffusion at step `dt` (0 without diffusion).
fn diffusion_number(params: &Params, dt: f64) -> f64 {
    params.density_diffusion * params.speed_of_sound() * dt / params.h
}

/// The density diffusion named as the cause, at diffusion number `number` > [`DIFFUSION_NUMBER`].
fn diffusion_cause(params: &Params, dt: f64, number: f64) -> String {
    format!(
        "the density diffusion: delta c0 dt / h = {} is over {DIFFUSION_NUMBER} (delta = physics.density_diffusion = {}, c0 = {}, dt = {}, h = {}), \
         where the diffusive term amplifies density noise instead of damping it: lower physics.density_diffusion below {} or time.dt below {} (raising c0 makes it worse)",
        short(number),
        short(params.density_diffusion),
        short(params.speed_of_sound()),
        short(dt),
        short(params.h),
        short(DIFFUSION_NUMBER * params.h / (params.speed_of_sound() * dt)),
        short(DIFFUSION_NUMBER * params.h / (params.density_diffusion * params.speed_of_sound()))
    )
}

/// Fluid particles found inside each solid of a scene (past the first layer of its wall
/// particles), counted from positions handed over one at a time.
#[derive(Clone, Debug)]
pub struct SolidIntrusions {
    /// (the solid's name, its region, how deep a particle must be to count, particles found).
    pub solids: Vec<(String, SolidRegion, f64, u64)>,
}

impl SolidIntrusions {
    pub fn new(scene: &Scene) -> Self {
        SolidIntrusions { solids: scene.named_solids().into_iter().map(|(name, region, spacing)| (name, region, 0.5 * spacing, 0)).collect() }
    }
    /// Counts a fluid particle at `x` where it is inside a solid.
    pub fn add(&mut self, x: [f64; 3]) {
        for (_, r, depth, count) in &mut self.solids {
            if (0..3).all(|a| x[a] > r.min[a] + *depth && x[a] < r.max[a] - *depth) {
                *count += 1;
            }
        }
    }
    /// The solids with particles inside, with their counts.
    pub fn found(&self) -> Vec<(&str, u64)> {
        self.solids.iter().filter(|s| s.3 > 0).map(|s| (s.0.as_str(), s.3)).collect()
    }
}

/// Below this fraction of the rest density, a fluid particle held at negative pressure counts as
/// torn (the fluid is stretched there, not just thinned at a free surface).
pub const TORN_DENSITY_RATIO: f64 = 0.5;

/// With summation density, a particle counts as torn only above this many times its own
/// kernel's share m W(0): a lone particle, or a droplet of two or three, is thin because it has
/// next to no neighbours, not because tension stretched it.
pub const TORN_ABOVE_OWN_SHARE: f64 = 2.0;

/// Fluid stretched under tension: the fluid particles below [`TORN_DENSITY_RATIO`] rho0 whose
/// pressure is negative (or undefined), which only a scene that keeps negative pressure has.
#[derive(Clone, Debug)]
pub struct TornFluid {
    rest_density: f64,
    /// Densities at or below this are a lone particle's or a droplet's (summation density).
    floor: f64,
    /// How many such particles.
    pub count: u64,
    /// The smallest density among them, and its pressure.
    pub smallest: Option<(f64, f64)>,
}

impl TornFluid {
    pub fn new(params: &Params) -> Self {
        let own_share = params.fluid_mass * KernelCoefficients::<f64>::new(params.kernel, params.h).w(0.0);
        let floor = if params.continuity_density { f64::NEG_INFINITY } else { TORN_ABOVE_OWN_SHARE * own_share };
        TornFluid { rest_density: params.rest_density, floor, count: 0, smallest: None }
    }
    /// Counts a fluid particle of `density` and `pressure` if it is torn.
    pub fn add(&mut self, density: f64, pressure: f64) {
        // A NaN pressure counts: a density at or below zero gives the equation of state none.
        if density.is_finite() && density < TORN_DENSITY_RATIO * self.rest_density && density > self.floor && !(pressure >= 0.0) {
            self.count += 1;
            if self.smallest.is_none_or(|(d, _)| density < d) {
                self.smallest = Some((density, pressure));
            }
        }
    }
}

/// The faces of the domain, in the order of [`EscapedFluid::through`]: -x, +x, -y, +y, -z, +z.
const FACES: [&str; 6] = ["-x", "+x", "-y", "+y", "-z", "+z"];

/// Fluid particles outside the domain, by the face of the domain each is farthest beyond.
#[derive(Clone, Debug)]
pub struct EscapedFluid {
    min: [f64; 3],
    max: [f64; 3],
    /// Particles beyond each face, in the order of [`FACES`] (axis 2a: below min, 2a + 1: above max).
    pub through: [u64; 6],
}

impl EscapedFluid {
    pub fn new(scene: &Scene) -> Self {
        EscapedFluid { min: scene.domain.min, max: scene.domain.max, through: [0; 6] }
    }
    /// Counts a fluid particle at `x` where it is outside the domain (a non-finite one is not
    /// anywhere).
    pub fn add(&mut self, x: [f64; 3]) {
        let mut farthest: Option<(usize, f64)> = None;
        for a in 0..3 {
            for (face, beyond) in [(2 * a, self.min[a] - x[a]), (2 * a + 1, x[a] - self.max[a])] {
                if beyond > 0.0 && farthest.is_none_or(|(_, d)| beyond > d) {
                    farthest = Some((face, beyond));
                }
            }
        }
        if let (true, Some((face, _))) = (x.iter().all(|v| v.is_finite()), farthest) {
            self.through[face] += 1;
        }
    }
}

/// What the state at a failure shows: fluid inside solids, fluid torn under tension, and fluid
/// outside the domain.
#[derive(Clone, Debug)]
pub struct FailureScan {
    pub intrusions: SolidIntrusions,
    pub torn: TornFluid,
    pub escaped: EscapedFluid,
}

impl FailureScan {
    pub fn new(scene: &Scene) -> Self {
        FailureScan { intrusions: SolidIntrusions::new(scene), torn: TornFluid::new(&scene.params()), escaped: EscapedFluid::new(scene) }
    }
    /// Adds a fluid particle at `x` with its density and pressure.
    pub fn add(&mut self, x: [f64; 3], density: f64, pressure: f64) {
        self.intrusions.add(x);
        self.torn.add(density, pressure);
        self.escaped.add(x);
    }
}

/// What holds the fluid in on the side of `face` (an index into [`FACES`]): the container walls
/// on that side and the planes facing back into the domain from it, by name.
fn closed_by(scene: &Scene, face: usize) -> Vec<String> {
    let (axis, sign) = (face / 2, if face % 2 == 0 { -1.0 } else { 1.0 });
    let mut out = Vec::new();
    for (i, b) in scene.boundary.iter().enumerate() {
        match b {
            Boundary::Container { open_top, .. } if !(face == 3 && *open_top) => {
                out.push(format!("boundary[{i}] (the container's {} wall)", FACES[face]));
            }
            Boundary::Plane { point, normal, .. } => {
                let length = normal.iter().map(|v| v * v).sum::<f64>().sqrt();
                if length > 0.0 && normal[axis] * sign / length < -0.99 {
                    out.push(format!("boundary[{i}] (the plane through {})", short3(*point)));
                }
            }
            _ => {}
        }
    }
    out
}

/// The cause that fluid outside the domain shows: the face it left through, and either that
/// nothing closes the domain on that side or that what closes it let the fluid through.
fn escape_cause(scene: &Scene, escaped: &EscapedFluid, max_speed: f64) -> Option<String> {
    // The face most left through (the first in FACES' order on a tie).
    let face = (0..6).rev().max_by_key(|&f| escaped.through[f]).filter(|&f| escaped.through[f] > 0)?;
    let (axis, above) = (face / 2, face % 2 == 1);
    let count = escaped.through[face];
    let others: u64 = escaped.through.iter().sum::<u64>() - count;
    let bound = if above { escaped.max[axis] } else { escaped.min[axis] };
    let coordinate = ["x", "y", "z"][axis];
    let field = format!("domain.{}[{axis}]", if above { "max" } else { "min" });
    let mut text = format!(
        "{count} fluid particles are beyond the domain's {} face ({coordinate} {} {}){}",
        FACES[face],
        if above { ">" } else { "<" },
        short(bound),
        if others > 0 { format!(" ({others} more beyond its other faces)") } else { String::new() }
    );
    let closers = closed_by(scene, face);
    if closers.is_empty() {
        // A splash up against gravity rises |v|^2 / 2|g| at most above where it was thrown.
        let g = scene.physics.gravity;
        let outward = if above { 1.0 } else { -1.0 };
        let g_along = g[axis] * outward;
        let rise = if g_along < 0.0 && max_speed.is_finite() { format!(" (fluid thrown up at |v|max = {} rises |v|^2 / 2|g| = {} above where it was thrown)", short(max_speed), short(max_speed * max_speed / (-2.0 * g_along))) } else { String::new() };
        let open_top = scene.boundary.iter().enumerate().find_map(|(i, b)| match b {
            Boundary::Container { open_top: true, .. } if face == 3 => Some(format!(", and boundary[{i}], the container, is open at the top")),
            _ => None,
        });
        text += &format!(
            ", where nothing holds the fluid in (no wall or plane closes that side{}): fluid thrown that way leaves the domain; move {field} out{rise}, \
             or close that side ({})",
            open_top.unwrap_or_default(),
            if face == 3 { "a container with open_top = false, or a plane" } else { "a container, or a plane" }
        );
    } else if closers.iter().all(|c| c.contains("container")) {
        text += &format!(
            ": they went through {}, whose wall particles did not hold fluid moving at up to |v|max = {}: back the wall with a plane on its inner face \
             (as the built-in dam break does), or lower time.dt",
            closers.join(" and "),
            short(max_speed)
        );
    } else {
        text += &format!(
            ": they got past {}; a plane holds the fluid on the side its normal points to from inside the domain, so check that it lies within the domain \
             ({field} = {})",
            closers.join(" and "),
            short(bound)
        );
    }
    Some(text)
}

/// Why a run went bad: the first bad step and what went wrong there, then the cause that the
/// figures of that step show (`scan`: the fluid inside solids and the fluid torn under tension
/// when the failure was found, where the caller looked), or "cause unknown".
pub fn diagnose(scene: &Scene, health: &Health, scan: Option<&FailureScan>) -> String {
    let params = scene.params();
    let Some(bad) = health.bad_step else {
        return "no step went bad".into();
    };
    let BadStep { step, measured: m, too_dense, too_fast } = bad;
    let (h, rho0) = (params.h, params.rest_density);
    let c0 = params.speed_of_sound();
    let ratio = m.max_density / rho0;
    let mach = m.max_speed / c0;
    let limits = &params.limits;

    let mut what = Vec::new();
    if m.non_finite > 0 {
        what.push(format!("{} particles became NaN or infinite", m.non_finite));
    }
    if m.escaped > 0 {
        what.push(format!("{} particles left the domain", m.escaped));
    }
    if too_dense {
        what.push(format!("the density reached {} rho0, over limits.max_density_ratio = {}", short(ratio), short(limits.max_density_ratio)));
    }
    if too_fast {
        what.push(format!(
            "the speed reached {} (Mach {} against c0 = {}), over limits.max_mach = {}",
            short(m.max_speed),
            short(mach),
            short(c0),
            short(limits.max_mach)
        ));
    }
    let mut msg = format!("step {step} (t = {}): {}.", short_time(m.time), what.join(", and "));

    // The conditions, each from the failing step's own figures.
    let dt = m.dt;
    let cfl = dt * (c0 + m.max_speed) / h;
    let acoustic_cfl = dt * c0 / h;
    let nu = params.viscosity_at_step(step.saturating_sub(1));
    let viscous_limit = if nu > 0.0 { VISCOUS_NUMBER * h * h / nu } else { f64::INFINITY };
    let g = params.gravity.iter().map(|v| v * v).sum::<f64>().sqrt();
    let force = dt * (g / h).sqrt();
    // First the conditions the scene's own constants break at this dt (the speed of sound,
    // the viscosity, gravity): where one is broken, the fast, dense or misplaced fluid found at
    // the failure is what it led to, not a cause of its own.
    let mut causes = Vec::new();
    let dfsph = params.dfsph.is_some();
    if acoustic_cfl > CFL_LIMIT {
        causes.push(format!(
            "the CFL condition: dt c0 / h = {} is over {CFL_LIMIT} before the flow adds its speed (dt = {} is too large for the speed of sound c0 = {}; h = {}): {}",
            short(acoustic_cfl),
            short(dt),
            short(c0),
            short(h),
            lower_dt(&params, dt, &format!("to 0.25 h / c0 = {} or less", short(0.25 * h / c0)), 0.25 * h / c0)
        ));
    }
    if dt > viscous_limit {
        // The viscosity in force: the scene's, or a later one of its schedule.
        let source = match scene.physics.viscosity_schedule.iter().enumerate().rev().find(|(_, c)| c.time <= m.time && c.viscosity == nu) {
            Some((i, _)) => format!("physics.viscosity_schedule[{i}].viscosity"),
            None => "physics.viscosity".to_string(),
        };
        causes.push(format!(
            "the viscous condition: dt = {} is over {VISCOUS_NUMBER} h^2 / nu = {} (nu = {}, h = {}): {}",
            short(dt),
            short(viscous_limit),
            short(nu),
            short(h),
            match lower_dt(&params, dt, "", viscous_limit) {
                held if held.starts_with("time.dt_min") => format!("{held}, or lower {source}"),
                _ => format!("lower time.dt or {source}"),
            }
        ));
    }
    let diffusion = diffusion_number(&params, dt);
    if diffusion > DIFFUSION_NUMBER {
        causes.push(diffusion_cause(&params, dt, diffusion));
    }
    if force > FORCE_NUMBER {
        causes.push(format!(
            "the force condition: dt sqrt(|g| / h) = {} is over {FORCE_NUMBER} (|g| = {}): lower time.dt below {} or physics.gravity",
            short(force),
            short(g),
            short(FORCE_NUMBER * (h / g).sqrt())
        ));
    }
    // Then what the failing step measured.
    if causes.is_empty() {
        // A DFSPH fluid that starts off its rest density (the kernel's sum over the lattice) is
        // taken to it within the first steps, whatever dt: what the early step measured follows.
        if let Some(start) = scene.start_off_rest_density().filter(|_| dfsph && step <= START_STEPS) {
            let depth = scene.fluid_depth();
            causes.push(format!(
                "the fluid started at {} rho0, not at rest (physics.kernel's sum over the particle lattice at physics.smoothing_length = {} spacings; \
                 the warning at load), and DFSPH's constant-density solve takes it to rest density within its first steps, whatever dt: \
                 a column {} deep has to change its height by {} ({} smoothing lengths) at once, which throws the fluid about; {}",
                short(start),
                short(params.h / scene.physics.particle_spacing),
                short(depth),
                short((start - 1.0).abs() * depth),
                short((start - 1.0).abs() * depth / h),
                scene.rest_density_fix()
            ));
        }
        // A weakly compressible fluid that starts denser than rest by the kernel's sum is
        // pushed apart by its own equation of state from the first step: where that start is
        // what the early step's density shows, no speed of sound mends it.
        let dense_start = scene.start_off_rest_density().filter(|&r| !dfsph && too_dense && step <= START_STEPS && r > 1.0);
        if let Some(start) = dense_start {
            causes.push(format!(
                "the fluid started at {} rho0, not at rest (physics.kernel's sum over the particle lattice at physics.smoothing_length = {} spacings; \
                 the warning at load), and its equation of state pushes it apart from the first step; {}",
                short(start),
                short(params.h / scene.physics.particle_spacing),
                scene.rest_density_fix()
            ));
        }
        if dfsph && cfl > DFSPH_CFL_LIMIT {
            causes.push(format!(
                "the CFL condition: the flow's speed |v|max = {} made dt |v|max / h = {} go over {DFSPH_CFL_LIMIT}, which DFSPH needs (dt = {}, h = {}): {}",
                short(m.max_speed),
                short(cfl),
                short(dt),
                short(h),
                lower_dt(&params, dt, &format!("below {}", short(DFSPH_CFL_LIMIT * h / m.max_speed)), DFSPH_CFL_LIMIT * h / m.max_speed)
            ));
        }
        if let Some(it) = health.iterations.filter(|it| it.pressure.unconverged + it.divergence.unconverged > 0) {
            causes.push(format!(
                "DFSPH's solves stopped at their iteration limit with the error above its tolerance ({} pressure and {} divergence solves; the summary's dfsph section): \
                 raise physics.dfsph.max_iterations or lower time.dt",
                it.pressure.unconverged, it.divergence.unconverged
            ));
        }
        if !dfsph && cfl > CFL_LIMIT {
            causes.push(format!(
                "the CFL condition: the flow's speed |v|max = {} made dt (c0 + |v|max) / h = {} go over {CFL_LIMIT} (dt = {}, c0 = {}, h = {}): {}",
                short(m.max_speed),
                short(cfl),
                short(dt),
                short(c0),
                short(h),
                lower_dt(&params, dt, &format!("below {}", short(CFL_LIMIT * h / (c0 + m.max_speed))), CFL_LIMIT * h / (c0 + m.max_speed))
            ));
        }
        if let Some(torn) = scan.map(|s| &s.torn).filter(|t| t.count > 0 && !dfsph && !params.clamp_negative_pressure) {
            let (density, pressure) = torn.smallest.unwrap_or_default();
            causes.push(format!(
                "the fluid was torn under tension: {} fluid particles are below {TORN_DENSITY_RATIO} rho0 at negative (or no) pressure (the least dense at {} rho0, \
                 pressure {} Pa), which the scene keeps (physics.clamp_negative_pressure = false); this is SPH's tensile instability, which clumps particles \
                 and flings others out fast, and can take a density to zero, where the equation of state has no pressure: set \
                 physics.clamp_negative_pressure = true",
                torn.count,
                short(density / rho0),
                short(pressure)
            ));
        }
        // Akinci et al.'s cohesion pulls every fluid pair within h together, a tension the
        // pressure has to hold: a gamma beyond what holds a drop together compresses the fluid,
        // and its collapse throws particles out (a higher speed of sound holds the compression
        // but not the throw: measured on a weightless block, docs/output.md).
        if (too_dense || too_fast || m.escaped > 0) && params.surface_tension > SURFACE_TENSION_USUAL {
            causes.push(format!(
                "the surface tension: physics.surface_tension = {} is above the 0.05 to {SURFACE_TENSION_USUAL} that holds a drop together at any resolution, \
                 and Akinci et al.'s cohesion pulls every pair within h together, a tension the pressure has to hold, whose collapse throws particles out: lower it",
                short(params.surface_tension)
            ));
        }
        if too_dense && dfsph {
            causes.push(format!(
                "the fluid was compressed to {} rho0, which DFSPH's constant-density solve should have prevented: lower time.dt, or check what presses the fluid",
                short(ratio)
            ));
        } else if too_dense && dense_start.is_none() {
            causes.push(format!(
                "the fluid was compressed to {} rho0: weakly compressible SPH holds while density varies by a few per cent, which needs a speed of sound \
                 about 10 times the largest flow speed (rho/rho0 - 1 is about the square of the Mach number); {}, or check what presses the fluid",
                short(ratio),
                raise_sound(scene, c0, None)
            ));
        }
        if too_fast && mach <= 0.3 {
            // The scene's own limit, below where weak compressibility fails, stopped the run.
            causes.push(format!(
                "the scene's limits.max_mach = {} is below the Mach 0.3 up to which the fluid stays nearly incompressible, and the flow reached Mach {}                  (a largest speed of {}): the limit stopped the run, not the flow; raise limits.max_mach if this speed is expected",
                short(params.limits.max_mach),
                short(mach),
                short(m.max_speed)
            ));
        } else if too_fast {
            causes.push(format!(
                "the flow reached Mach {} (a largest speed of {}): beyond about 0.3 the fluid is no longer nearly incompressible; {}",
                short(mach),
                short(m.max_speed),
                raise_sound(scene, c0, Some(10.0 * m.max_speed))
            ));
        }
        // Akinci et al.'s adhesion pulls fluid within h of a wall particle towards it: a beta
        // beyond what wets a wall overcomes the walls' pressure and draws the fluid into them
        // (a higher speed of sound does not stop it: measured on a drop, docs/output.md).
        let intruded = scan.is_some_and(|s| !s.intrusions.found().is_empty());
        if (intruded || m.escaped > 0 || too_dense) && params.wall_adhesion > WALL_ADHESION_USUAL {
            causes.push(format!(
                "the wall adhesion: physics.wall_adhesion = {} is above the 0.01 to {WALL_ADHESION_USUAL} that wets a wall, and Akinci et al.'s adhesion \
                 pulls the fluid within h of the walls into them, against the walls' pressure: lower it",
                short(params.wall_adhesion)
            ));
        }
        for (name, count) in scan.map(|s| s.intrusions.found()).unwrap_or_default() {
            causes.push(format!("{count} fluid particles are inside {name}, past its first layer of wall particles: the fluid leaked into the solid or started in it"));
        }
        if let Some(escape) = scan.filter(|_| m.escaped > 0).and_then(|s| escape_cause(scene, &s.escaped, m.max_speed)) {
            causes.push(escape);
        }
    }
    let figures = format!(
        "measured at step {step}: |v|max = {}, max rho/rho0 = {}, dt = {}, CFL number dt ({}|v|max) / h = {}",
        short(m.max_speed),
        short(ratio),
        short(dt),
        if dfsph { "" } else { "c0 + " },
        short(cfl)
    );
    if causes.is_empty() {
        msg += &format!(
            " Cause unknown: the CFL number {} is below {}, the viscous condition (dt <= {}) and the force condition (dt sqrt(|g| / h) = {} <= {FORCE_NUMBER}) hold, \
             the density ({} rho0){} stayed within the limits, and {}; {figures}. Check the scene's boundaries and the domain.",
            short(cfl),
            if dfsph { DFSPH_CFL_LIMIT } else { CFL_LIMIT },
            short(viscous_limit),
            short(force),
            short(ratio),
            if dfsph { String::new() } else { format!(" and the speed (Mach {})", short(mach)) },
            if scan.is_some() { "no fluid particle is inside a solid or torn under tension" } else { "the particles were not checked against the solids" }
        );
    } else {
        msg += &format!(" Cause: {}. ({figures}.)", causes.join("; and "));
    }
    msg
}

/// Where a run left the regime its method holds without stopping: its largest density and
/// speed against `limits.warn_density_ratio` and `limits.warn_mach`, one line each (a DFSPH
/// run has no Mach number, and its density is its solve's).
pub fn regime_warnings(scene: &Scene, health: &Health) -> Vec<String> {
    let params = &scene.params();
    let start = scene.start_off_rest_density();
    let limits = &params.limits;
    let c0 = params.speed_of_sound();
    let ratio = health.max_density / params.rest_density;
    let mach = health.max_speed / c0;
    let mut out = Vec::new();
    if let (true, Some(dfsph)) = (ratio > limits.warn_density_ratio, &params.dfsph) {
        // No equation of state to stiffen: the solve holds the density where it converges.
        out.push(format!(
            "the density reached {} rho0, over limits.warn_density_ratio = {}: DFSPH's constant-density solve holds the average density error within \
             physics.dfsph.density_error = {} where it converges, so some step's solve stopped before it did or dt let the flow run past it; \
             lower time.dt (or time.cfl_number with adaptive dt) or raise physics.dfsph.max_iterations{}",
            short(ratio),
            short(limits.warn_density_ratio),
            short(dfsph.density_error),
            start.map(|r| format!(" (the fluid also started at {} rho0: the warning at load)", short(r))).unwrap_or_default()
        ));
    } else if ratio > limits.warn_density_ratio {
        out.push(format!(
            "the density reached {} rho0, over limits.warn_density_ratio = {}: weakly compressible SPH stands in for a liquid while density varies by a few per cent, \
             so the results are less accurate where it was compressed; a higher speed of sound keeps density closer to rho0: {}",
            short(ratio),
            short(limits.warn_density_ratio),
            raise_sound(scene, c0, None)
        ));
    }
    // Without a speed of sound (DFSPH) there is no Mach number.
    if c0 > 0.0 && mach > limits.warn_mach {
        out.push(format!(
            "the speed reached {} (Mach {} against c0 = {}), over limits.warn_mach = {}: beyond about 0.3 the fluid is no longer nearly incompressible \
             (rho/rho0 - 1 is about Mach^2); {}",
            short(health.max_speed),
            short(mach),
            short(c0),
            short(limits.warn_mach),
            raise_sound(scene, c0, Some(10.0 * health.max_speed))
        ));
    }
    out
}

/// What raises the speed of sound c0 of `scene` (to `target` where given): the field the scene
/// sets it by. A scene that gives the stiffness k gets the k that `target` needs, since c0
/// grows as the square root of k (k = rho0 c0^2, or rho0 c0^2 / 7 for Tait).
fn raise_sound(scene: &Scene, c0: f64, target: Option<f64>) -> String {
    // A speed of sound beyond what a scene may have cannot be the remedy.
    let most = super::check::SPEED_OF_SOUND_RANGE.1;
    if let Some(t) = target.filter(|&t| t > most) {
        return format!(
            "a speed of sound 10 times the largest speed would be {}, beyond the {} a scene may have: this flow is too fast for weakly compressible SPH; check what drives it (an initial velocity, gravity, a force)",
            short(t),
            short(most)
        );
    }
    match (scene.physics.stiffness, target) {
        (Some(k), Some(t)) if c0 > 0.0 => format!(
            "raise physics.stiffness (k = {} gives c0 = {}; c0 = {}, 10 times the largest speed, needs k = {}), or give physics.speed_of_sound instead",
            short(k),
            short(c0),
            short(t),
            short(k * (t / c0).powi(2))
        ),
        (Some(k), _) => format!("raise physics.stiffness (k = {} gives c0 = {}; c0 grows as the square root of k)", short(k), short(c0)),
        (None, Some(t)) => format!("raise physics.speed_of_sound to at least 10 times the largest speed (c0 = {} now, {} needed)", short(c0), short(t)),
        (None, None) => format!("raise physics.speed_of_sound (c0 = {})", short(c0)),
    }
}
