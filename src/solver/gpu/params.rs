//! What the host and the shaders share: the uniform parameter block (`struct Params` in
//! wgsl/shared/common.wgsl) and the status words (`STATUS_*` in the same file). Each is written
//! once here with its WGSL spelling; a test reads common.wgsl and checks that both sides agree
//! field by field and word by word.

use crate::model::kernels::KernelCoefficients;
use crate::solver::cpu::dfsph_shared::{error_threshold, factor_epsilon, WARM_START_SHARE};
use crate::model::params::{Params, MAX_PLANES, MAX_SOLID_BOXES};
use encase::{ShaderType, UniformBuffer};

/// A WGSL `vec4<T>` for encase (which has no glam support of its own).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Vec4<T>(pub [T; 4]);
impl<T> AsRef<[T; 4]> for Vec4<T> {
    fn as_ref(&self) -> &[T; 4] {
        &self.0
    }
}
impl<T> AsMut<[T; 4]> for Vec4<T> {
    fn as_mut(&mut self) -> &mut [T; 4] {
        &mut self.0
    }
}
impl<T> From<[T; 4]> for Vec4<T> {
    fn from(v: [T; 4]) -> Self {
        Vec4(v)
    }
}
encase::impl_vector!(4, Vec4<T>; (T); using AsRef AsMut From);
pub type Vec4f = Vec4<f32>;
pub type Vec4u = Vec4<u32>;

/// A WGSL `vec2<T>` for encase.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Vec2<T>(pub [T; 2]);
impl<T> AsRef<[T; 2]> for Vec2<T> {
    fn as_ref(&self) -> &[T; 2] {
        &self.0
    }
}
impl<T> AsMut<[T; 2]> for Vec2<T> {
    fn as_mut(&mut self) -> &mut [T; 2] {
        &mut self.0
    }
}
impl<T> From<[T; 2]> for Vec2<T> {
    fn from(v: [T; 2]) -> Self {
        Vec2(v)
    }
}
encase::impl_vector!(2, Vec2<T>; (T); using AsRef AsMut From);
pub type Vec2u = Vec2<u32>;

/// A u64 as the two u32 words of a WGSL `vec2<u32>` (low word first).
fn words(v: u64) -> Vec2u {
    Vec2([v as u32, (v >> 32) as u32])
}

/// Declares the uniform block once: the Rust struct (laid out by encase) and the WGSL type of
/// every field, in order, for the mirror test.
macro_rules! uniform_block {
    ($(#[$meta:meta])* pub struct $name:ident { $($(#[doc = $doc:literal])* $field:ident: $ty:ty => $wgsl:literal,)* }) => {
        $(#[$meta])*
        pub struct $name {
            $($(#[doc = $doc])* pub $field: $ty,)*
        }
        impl $name {
            /// Every field's name and WGSL type, in order (`struct Params` of common.wgsl).
            pub const WGSL_FIELDS: &'static [(&'static str, &'static str)] = &[$((stringify!($field), $wgsl)),*];
        }
    };
}

uniform_block! {
    /// The uniform parameter block: `struct Params` in wgsl/shared/common.wgsl.
    #[derive(ShaderType, Clone, Debug, Default)]
    pub struct GpuParams {
        domain_min: Vec4f => "vec4<f32>",
        domain_max: Vec4f => "vec4<f32>",
        gravity: Vec4f => "vec4<f32>",
        grid_origin: Vec4f => "vec4<f32>",
        /// xyz: cells per axis.
        grid_dims: Vec4u => "vec4<u32>",
        h: f32 => "f32",
        h2: f32 => "f32",
        inv_cell: f32 => "f32",
        dt: f32 => "f32",
        fluid_mass: f32 => "f32",
        rest_density: f32 => "f32",
        stiffness: f32 => "f32",
        viscosity: f32 => "f32",
        boundary_friction: f32 => "f32",
        /// poly6 or cubic normalisation, gradient factor, Laplacian factor (model::kernels).
        w_coef: f32 => "f32",
        grad_coef: f32 => "f32",
        lap_coef: f32 => "f32",
        fluid_count: u32 => "u32",
        wall_count: u32 => "u32",
        plane_count: u32 => "u32",
        /// gamma of surface tension.
        surface_tension: f32 => "f32",
        /// xyz: unit normal, w: offset (plane n.x = w).
        planes: [Vec4f; MAX_PLANES] => "array<vec4<f32>, 8>",
        /// x: restitution.
        plane_restitution: [Vec4f; MAX_PLANES] => "array<vec4<f32>, 8>",
        speed_of_sound: f32 => "f32",
        cfl_number: f32 => "f32",
        force_number: f32 => "f32",
        viscous_number: f32 => "f32",
        dt_min: f32 => "f32",
        dt_max: f32 => "f32",
        /// The run stops at a step whose largest density or speed passes these (infinite: off).
        stop_density: f32 => "f32",
        stop_speed: f32 => "f32",
        /// DFSPH: the fluid particle's volume m / rho0, the smallest denominator of alpha.
        fluid_volume: f32 => "f32",
        factor_epsilon: f32 => "f32",
        /// DFSPH: the share of the last step's stiffness a solve starts from.
        warm_start_share: f32 => "f32",
        /// DFSPH: the iteration limits of the constant-density and the divergence solve.
        min_iterations: u32 => "u32",
        max_iterations: u32 => "u32",
        min_divergence_iterations: u32 => "u32",
        max_divergence_iterations: u32 => "u32",
        /// DFSPH: the largest error sums (fixed-point, x: low word, y: high word) that meet the
        /// tolerances of the constant-density and the divergence solve.
        density_threshold: Vec2u => "vec2<u32>",
        divergence_threshold: Vec2u => "vec2<u32>",
        /// delta h c0 of density diffusion, alpha h_s c0 of artificial viscosity.
        diffusion_factor: f32 => "f32",
        artificial_viscosity_factor: f32 => "f32",
        /// The solid boxes backed by their faces, and their corners (xyz).
        solid_box_count: u32 => "u32",
        /// gamma m 32 / (pi h^3) of cohesion, beta 0.007 / h^3 of adhesion.
        cohesion_factor: f32 => "f32",
        adhesion_factor: f32 => "f32",
        solid_box_min: [Vec4f; MAX_SOLID_BOXES] => "array<vec4<f32>, 8>",
        solid_box_max: [Vec4f; MAX_SOLID_BOXES] => "array<vec4<f32>, 8>",
    }
}

fn v4(v: [f64; 3]) -> Vec4f {
    Vec4([v[0] as f32, v[1] as f32, v[2] as f32, 0.0])
}

impl GpuParams {
    /// The f32 constants, converted exactly as the f32 CPU path converts them.
    pub fn new(p: &Params, fluid_count: u32, wall_count: u32, viscosity: f64) -> Self {
        let d = p.dfsph.clone().unwrap_or_default();
        let n = fluid_count as usize;
        let k = KernelCoefficients::<f32>::new(p.kernel, p.h);
        let g = p.grid.cast::<f32>();
        let mut planes = [Vec4f::default(); MAX_PLANES];
        let mut restitution = [Vec4f::default(); MAX_PLANES];
        let (mut box_min, mut box_max) = ([Vec4f::default(); MAX_SOLID_BOXES], [Vec4f::default(); MAX_SOLID_BOXES]);
        for (i, b) in p.solid_boxes.iter().enumerate() {
            box_min[i] = v4(b.min);
            box_max[i] = v4(b.max);
        }
        for (i, pl) in p.planes.iter().enumerate() {
            planes[i] = Vec4([pl.normal[0] as f32, pl.normal[1] as f32, pl.normal[2] as f32, pl.offset as f32]);
            restitution[i] = Vec4([pl.restitution as f32, 0.0, 0.0, 0.0]);
        }
        GpuParams {
            domain_min: v4(p.domain_min),
            domain_max: v4(p.domain_max),
            gravity: v4(p.gravity),
            grid_origin: Vec4([g.origin.0[0], g.origin.0[1], g.origin.0[2], 0.0]),
            grid_dims: Vec4([g.dims[0], g.dims[1], g.dims[2], 0]),
            h: k.h,
            h2: k.h2,
            inv_cell: g.inv_cell,
            dt: p.dt as f32,
            fluid_mass: p.fluid_mass as f32,
            rest_density: p.rest_density as f32,
            stiffness: p.stiffness as f32,
            viscosity: viscosity as f32,
            boundary_friction: p.boundary_friction as f32,
            w_coef: k.w,
            grad_coef: k.grad,
            lap_coef: k.lap,
            fluid_count,
            wall_count,
            plane_count: p.planes.len() as u32,
            surface_tension: p.surface_tension as f32,
            planes,
            plane_restitution: restitution,
            speed_of_sound: p.speed_of_sound() as f32,
            cfl_number: p.adaptive.map_or(0.0, |a| a.cfl_number as f32),
            force_number: p.adaptive.map_or(0.0, |a| a.force_number as f32),
            viscous_number: p.adaptive.map_or(0.0, |a| a.viscous_number as f32),
            dt_min: p.adaptive.map_or(p.dt, |a| a.dt_min) as f32,
            dt_max: p.adaptive.map_or(p.dt, |a| a.dt_max) as f32,
            stop_density: p.stop_levels().density as f32,
            stop_speed: p.stop_levels().speed as f32,
            fluid_volume: (p.fluid_mass / p.rest_density) as f32,
            factor_epsilon: factor_epsilon(p.h) as f32,
            warm_start_share: WARM_START_SHARE as f32,
            min_iterations: d.min_iterations,
            max_iterations: d.max_iterations,
            min_divergence_iterations: d.min_divergence_iterations,
            max_divergence_iterations: d.max_divergence_iterations,
            density_threshold: words(error_threshold(d.density_error, n)),
            divergence_threshold: words(error_threshold(d.divergence_error, n)),
            diffusion_factor: p.diffusion_factor() as f32,
            artificial_viscosity_factor: p.artificial_viscosity_factor() as f32,
            solid_box_count: p.solid_boxes.len() as u32,
            cohesion_factor: p.cohesion_factor() as f32,
            adhesion_factor: p.adhesion_factor() as f32,
            solid_box_min: box_min,
            solid_box_max: box_max,
        }
    }

    pub fn bytes(&self) -> Vec<u8> {
        let mut buf = UniformBuffer::new(Vec::new());
        buf.write(self).expect("the parameter block serialises");
        buf.into_inner()
    }
}

/// Declares the status words once: a Rust constant per word and its WGSL name, for the mirror
/// test.
macro_rules! status_words {
    ($($(#[doc = $doc:literal])* $name:ident = $index:literal => $wgsl:literal,)*) => {
        $($(#[doc = $doc])* pub const $name: usize = $index;)*
        /// Every word's WGSL constant name and index.
        pub const WGSL_NAMES: &[(&str, usize)] = &[$(($wgsl, $index)),*];
    };
}

/// The status buffer: the health counters of a run, and the adaptive step's maxima, dt and
/// time, read and written by the shaders (wgsl/sim/density.wgsl, integrate.wgsl) and read back
/// by the host a few bytes at a time. Floats are stored as their bits.
pub mod status {
    use crate::model::params::TimeSum;

    status_words! {
        /// Steps done.
        STEPS = 0 => "STATUS_STEPS",
        /// Particles that became non-finite this step (cleared before each step).
        NON_FINITE = 1 => "STATUS_NON_FINITE",
        /// Particles outside the domain this step (cleared before each step).
        ESCAPED = 2 => "STATUS_ESCAPED",
        /// The first step that went wrong ([`NO_BAD_STEP`]: none).
        FIRST_BAD_STEP = 3 => "STATUS_FIRST_BAD_STEP",
        /// The largest density so far (positive floats order like their bits).
        MAX_DENSITY = 4 => "STATUS_MAX_DENSITY",
        /// Adaptive dt: the largest |v| of this step.
        MAX_SPEED = 5 => "STATUS_MAX_SPEED",
        /// Adaptive dt: the largest |a| of this step.
        MAX_ACCELERATION = 6 => "STATUS_MAX_ACCELERATION",
        /// Adaptive dt: this step's dt.
        DT = 7 => "STATUS_DT",
        /// Adaptive dt: the simulated time, summed exactly: (TIME_HI 2^32 + TIME_LO) 2^TIME_EXPONENT
        /// ([`TimeSum`](crate::model::params::TimeSum)).
        TIME_LO = 8 => "STATUS_TIME_LO",
        TIME_HI = 9 => "STATUS_TIME_HI",
        /// Adaptive dt: the smallest dt so far.
        DT_MIN = 10 => "STATUS_DT_MIN",
        /// Adaptive dt: the largest dt so far.
        DT_MAX = 11 => "STATUS_DT_MAX",
        /// The largest density of this step (reset by `finish_step`).
        STEP_MAX_DENSITY = 12 => "STATUS_STEP_MAX_DENSITY",
        /// The largest speed after this step's integration (reset by `finish_step`).
        STEP_MAX_SPEED = 13 => "STATUS_STEP_MAX_SPEED",
        /// The largest speed so far.
        TOP_SPEED = 14 => "STATUS_TOP_SPEED",
        /// The first bad step's measures, written by `finish_step` with the marker
        /// FIRST_BAD_STEP: which checks it failed (`CAUSE_*` bits) ...
        BAD_CAUSES = 15 => "STATUS_BAD_CAUSES",
        /// ... its counts of non-finite and escaped particles ...
        BAD_NON_FINITE = 16 => "STATUS_BAD_NON_FINITE",
        BAD_ESCAPED = 17 => "STATUS_BAD_ESCAPED",
        /// ... its largest density and speed ...
        BAD_MAX_DENSITY = 18 => "STATUS_BAD_MAX_DENSITY",
        BAD_MAX_SPEED = 19 => "STATUS_BAD_MAX_SPEED",
        /// ... its dt, and with adaptive dt the time at its end.
        BAD_DT = 20 => "STATUS_BAD_DT",
        BAD_TIME = 21 => "STATUS_BAD_TIME",
        /// DFSPH: the error sum of the solve under way, fixed-point (low and high word).
        DFSPH_ERROR_LO = 22 => "STATUS_DFSPH_ERROR_LO",
        DFSPH_ERROR_HI = 23 => "STATUS_DFSPH_ERROR_HI",
        /// DFSPH: the iterations of the solve under way, and whether it goes on (1) or ended (0).
        DFSPH_ITERATION = 24 => "STATUS_DFSPH_ITERATION",
        DFSPH_SOLVING = 25 => "STATUS_DFSPH_SOLVING",
        /// DFSPH's constant-density solve over the run: iterations, most in a step, the last
        /// step's, the last step's average error (f32) and the steps that ended unconverged.
        PRESSURE_ITERATIONS = 26 => "STATUS_PRESSURE_ITERATIONS",
        PRESSURE_ITERATIONS_MAX = 27 => "STATUS_PRESSURE_ITERATIONS_MAX",
        PRESSURE_ITERATIONS_LAST = 28 => "STATUS_PRESSURE_ITERATIONS_LAST",
        PRESSURE_ERROR = 29 => "STATUS_PRESSURE_ERROR",
        PRESSURE_UNCONVERGED = 30 => "STATUS_PRESSURE_UNCONVERGED",
        /// The same for DFSPH's divergence solve.
        DIVERGENCE_ITERATIONS = 31 => "STATUS_DIVERGENCE_ITERATIONS",
        DIVERGENCE_ITERATIONS_MAX = 32 => "STATUS_DIVERGENCE_ITERATIONS_MAX",
        DIVERGENCE_ITERATIONS_LAST = 33 => "STATUS_DIVERGENCE_ITERATIONS_LAST",
        DIVERGENCE_ERROR = 34 => "STATUS_DIVERGENCE_ERROR",
        DIVERGENCE_UNCONVERGED = 35 => "STATUS_DIVERGENCE_UNCONVERGED",
        /// Adaptive dt: the simulated time's power of two (an i32; with TIME_LO, TIME_HI).
        TIME_EXPONENT = 36 => "STATUS_TIME_EXPONENT",
    }
    /// Words of the status buffer.
    pub const WORDS: usize = 37;
    /// Bytes of the status buffer.
    pub const BYTES: u64 = WORDS as u64 * 4;
    /// FIRST_BAD_STEP while no step went wrong (`STATUS_NO_BAD_STEP` in WGSL).
    pub const NO_BAD_STEP: u32 = u32::MAX;
    /// The bits of BAD_CAUSES (`CAUSE_*` in WGSL).
    pub const CAUSE_NON_FINITE: u32 = 1;
    pub const CAUSE_ESCAPED: u32 = 2;
    pub const CAUSE_TOO_DENSE: u32 = 4;
    pub const CAUSE_TOO_FAST: u32 = 8;
    /// Every cause bit's WGSL name and value.
    pub const WGSL_CAUSES: &[(&str, u32)] =
        &[("CAUSE_NON_FINITE", CAUSE_NON_FINITE), ("CAUSE_ESCAPED", CAUSE_ESCAPED), ("CAUSE_TOO_DENSE", CAUSE_TOO_DENSE), ("CAUSE_TOO_FAST", CAUSE_TOO_FAST)];

    /// The status words of a new run.
    pub fn initial() -> [u32; WORDS] {
        let mut s = [0u32; WORDS];
        s[FIRST_BAD_STEP] = NO_BAD_STEP;
        s[DT_MIN] = f32::INFINITY.to_bits();
        set_time(&mut s, TimeSum::ZERO);
        s
    }

    /// The simulated time the words hold (adaptive dt).
    pub fn time(s: &[u32]) -> TimeSum {
        TimeSum::from_words([s[TIME_LO], s[TIME_HI], s[TIME_EXPONENT]])
    }

    /// Sets the simulated time words.
    pub fn set_time(s: &mut [u32], t: TimeSum) {
        [s[TIME_LO], s[TIME_HI], s[TIME_EXPONENT]] = t.words();
    }

    /// The status words of a state saved without them (by GPU ranks, whose hosts keep the
    /// health, time, dt range and iterations): what one GPU reads of them made from the state's
    /// header; the per-step words start from zero as at any step's start.
    pub fn from_header(state: &crate::model::state::BackendState) -> [u32; WORDS] {
        let mut s = initial();
        let f = |v: f64| (v as f32).to_bits();
        s[STEPS] = state.step as u32;
        s[MAX_DENSITY] = f(state.max_density);
        s[TOP_SPEED] = f(state.max_speed);
        set_time(&mut s, TimeSum::from_seconds(state.time));
        let [min, max, last] = state.dt_min_max_last;
        if state.step > 0 {
            (s[DT_MIN], s[DT_MAX], s[DT]) = (f(min), f(max), f(last));
        }
        if let Some(bad) = &state.bad_step {
            let m = &bad.measured;
            s[FIRST_BAD_STEP] = bad.step as u32;
            s[BAD_CAUSES] = if m.non_finite > 0 { CAUSE_NON_FINITE } else { 0 }
                | if m.escaped > 0 { CAUSE_ESCAPED } else { 0 }
                | if bad.too_dense { CAUSE_TOO_DENSE } else { 0 }
                | if bad.too_fast { CAUSE_TOO_FAST } else { 0 };
            (s[BAD_NON_FINITE], s[BAD_ESCAPED]) = (m.non_finite as u32, m.escaped as u32);
            (s[BAD_MAX_DENSITY], s[BAD_MAX_SPEED], s[BAD_DT], s[BAD_TIME]) = (f(m.max_density), f(m.max_speed), f(m.dt), f(m.time));
        }
        let it = &state.iterations;
        for (solve, first) in [(&it.pressure, PRESSURE_ITERATIONS), (&it.divergence, DIVERGENCE_ITERATIONS)] {
            s[first] = solve.total as u32;
            s[first + 1] = solve.max;
            s[first + 2] = solve.last;
            s[first + 3] = f(solve.last_error);
            s[first + 4] = solve.unconverged as u32;
        }
        s
    }

    /// DFSPH's iterations in the status words.
    pub fn iterations(s: &[u32]) -> crate::model::state::IterationStats {
        use crate::model::state::{IterationStats, SolveStats};
        let solve = |total: usize, max: usize, last: usize, error: usize, unconverged: usize| SolveStats {
            total: s[total] as u64,
            max: s[max],
            last: s[last],
            last_error: float(s, error),
            unconverged: s[unconverged] as u64,
        };
        IterationStats {
            pressure: solve(PRESSURE_ITERATIONS, PRESSURE_ITERATIONS_MAX, PRESSURE_ITERATIONS_LAST, PRESSURE_ERROR, PRESSURE_UNCONVERGED),
            divergence: solve(DIVERGENCE_ITERATIONS, DIVERGENCE_ITERATIONS_MAX, DIVERGENCE_ITERATIONS_LAST, DIVERGENCE_ERROR, DIVERGENCE_UNCONVERGED),
        }
    }

    /// The health of the run in the status words. `fixed_dt`: the step of a run without
    /// adaptive dt, whose time the host knows (with adaptive dt the GPU sums it).
    pub fn health(s: &[u32], fixed_dt: Option<f64>) -> crate::model::state::Health {
        use crate::model::state::{BadStep, StepMeasures};
        let bad_step = (s[FIRST_BAD_STEP] != NO_BAD_STEP).then(|| {
            let step = s[FIRST_BAD_STEP] as u64;
            let causes = s[BAD_CAUSES];
            BadStep {
                step,
                measured: StepMeasures {
                    non_finite: s[BAD_NON_FINITE] as u64,
                    escaped: s[BAD_ESCAPED] as u64,
                    max_density: float(s, BAD_MAX_DENSITY),
                    max_speed: float(s, BAD_MAX_SPEED),
                    dt: float(s, BAD_DT),
                    time: fixed_dt.map_or_else(|| float(s, BAD_TIME), |dt| step as f64 * dt),
                },
                too_dense: causes & CAUSE_TOO_DENSE != 0,
                too_fast: causes & CAUSE_TOO_FAST != 0,
            }
        });
        crate::model::state::Health {
            non_finite: s[NON_FINITE] as u64,
            escaped: s[ESCAPED] as u64,
            first_bad_step: bad_step.map(|b| b.step),
            max_density: float(s, MAX_DENSITY),
            max_speed: float(s, TOP_SPEED),
            bad_step,
            iterations: None,
        }
    }

    /// A float word.
    pub fn float(s: &[u32], word: usize) -> f64 {
        f32::from_bits(s[word]) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::{status, GpuParams};

    /// wgsl/shared/common.wgsl, where the shaders declare the block and the words.
    fn common_wgsl() -> &'static str {
        super::super::shaders::source("shared/common.wgsl").expect("the shared shader file")
    }

    /// The fields of `struct Params` in common.wgsl: (name, type) in order.
    fn wgsl_fields() -> Vec<(String, String)> {
        let text = common_wgsl();
        let body = &text[text.find("struct Params {").expect("struct Params") + "struct Params {".len()..];
        let body = &body[..body.find("\n}").expect("the end of struct Params")];
        body.lines()
            .map(|l| l.split("//").next().unwrap().trim())
            .filter(|l| !l.is_empty())
            .map(|l| {
                let (name, ty) = l.trim_end_matches(',').split_once(':').expect("name: type");
                (name.trim().to_string(), ty.trim().to_string())
            })
            .collect()
    }

    /// A state saved by GPU ranks (no status words) gives one GPU the words whose health,
    /// time, dt range and iterations are the state's.
    #[test]
    fn status_words_made_from_a_header_read_back_as_the_header() {
        use crate::model::state::{BackendState, BadStep, IterationStats, SolveStats, StepMeasures};
        let bad = BadStep { step: 7, measured: StepMeasures { non_finite: 2, escaped: 0, max_density: 1500.0, max_speed: 3.5, dt: 0.0009765625, time: 0.25 }, too_dense: true, too_fast: false };
        let solve = |k: u64| SolveStats { total: 40 * k, max: 5 * k as u32, last: 3, last_error: 0.5, unconverged: k };
        let state = BackendState {
            kind: "gpu".into(),
            step: 40,
            max_density: 1020.0,
            max_speed: 2.0,
            first_bad_step: Some(7),
            bad_step: Some(bad),
            time: 0.1 + 0.2,
            dt_min_max_last: [0.001, 0.004, 0.0025],
            iterations: IterationStats { pressure: solve(1), divergence: solve(2) },
            ..BackendState::default()
        };
        let words = status::from_header(&state);
        assert_eq!(words[status::STEPS], 40);
        let h = status::health(&words, None);
        assert_eq!((h.max_density, h.max_speed, h.first_bad_step), (1020.0, 2.0, Some(7)));
        assert_eq!(h.bad_step, Some(bad));
        assert_eq!(status::iterations(&words), state.iterations);
        let f = |i: usize| status::float(&words, i);
        // The time to the last bit of the f64 (ranks resume to the same time as one GPU).
        assert_eq!(status::time(&words).seconds(), 0.1 + 0.2);
        assert_eq!((f(status::DT_MIN), f(status::DT_MAX), f(status::DT)), (0.001f32 as f64, 0.004f32 as f64, 0.0025f32 as f64));
        // Before the first step the dt range is empty, as one GPU starts it.
        let start = status::from_header(&BackendState { step: 0, ..state });
        assert_eq!((start[status::DT_MIN], start[status::DT]), (f32::INFINITY.to_bits(), 0));
    }

    #[test]
    fn the_uniform_block_is_the_same_on_both_sides() {
        let wgsl = wgsl_fields();
        let rust: Vec<(String, String)> = GpuParams::WGSL_FIELDS.iter().map(|(n, t)| (n.to_string(), t.to_string())).collect();
        assert_eq!(wgsl, rust, "struct Params in wgsl/shared/common.wgsl and GpuParams differ");
        // encase lays the Rust struct out as WGSL's uniform rules do; 16-byte multiples.
        assert_eq!(GpuParams::default().bytes().len() % 16, 0);
    }

    #[test]
    fn the_status_words_are_the_same_on_both_sides() {
        let text = common_wgsl();
        let mut seen = 0;
        for line in text.lines().filter(|l| l.trim_start().starts_with("const STATUS_")) {
            let (name, value) = line.trim_start().trim_start_matches("const ").split_once(':').expect("const NAME: u32 = V");
            let value = value.split('=').nth(1).expect("a value").split(';').next().unwrap().trim();
            if name == "STATUS_NO_BAD_STEP" {
                assert_eq!(value, format!("{:#x}u", status::NO_BAD_STEP));
                continue;
            }
            let index: usize = value.trim_end_matches('u').parse().expect("an index");
            let rust = status::WGSL_NAMES.iter().find(|(n, _)| *n == name).unwrap_or_else(|| panic!("{name} has no Rust constant"));
            assert_eq!(rust.1, index, "{name}");
            seen += 1;
        }
        assert_eq!(seen, status::WGSL_NAMES.len(), "every Rust status word is declared in WGSL");
        assert_eq!(status::WGSL_NAMES.len(), status::WORDS);
        for (name, bit) in status::WGSL_CAUSES {
            let line = text.lines().find(|l| l.trim_start().starts_with(&format!("const {name}:"))).unwrap_or_else(|| panic!("{name} is not declared in WGSL"));
            assert!(line.contains(&format!("= {bit}u;")), "{name}: {line}");
        }
        let mut indices: Vec<usize> = status::WGSL_NAMES.iter().map(|w| w.1).collect();
        indices.sort();
        assert_eq!(indices, (0..status::WORDS).collect::<Vec<_>>(), "the words are 0..WORDS, each once");
    }
}
