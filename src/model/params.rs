//! The resolved constants of a scene (defaults filled in, stiffness derived), the one
//! neighbour grid, adaptive time stepping and the viscosity schedule.

use super::real::{Real, V3};
use super::scene::{Boundary, BoundaryPressure, BoundaryVolume, DensityMethod, DfsphSettings, EquationOfState, Kernel, Limits, PressureSolver, Scene};

/// Plane in the form normal . x = offset, with a unit normal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    pub normal: [f64; 3],
    pub offset: f64,
    pub restitution: f64,
}

/// A solid box obstacle's faces, [min, max]: the integration puts a fluid particle that entered
/// it back on its nearest face, as a plane does.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolidBox {
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
    /// The `[[boundary]] type = "box"` obstacles, each backed by its faces.
    pub solid_boxes: Vec<SolidBox>,
    pub grid: Grid,
    /// DFSPH's settings when the scene uses it (`None`: weakly compressible, pressure from
    /// the equation of state).
    pub dfsph: Option<DfsphSettings>,
    pub boundary_volume: BoundaryVolume,
    /// The weakly compressible regime the run must stay in.
    pub limits: Limits,
    /// The probes sampled during a run (none: no probe stage runs).
    pub probes: super::probes::Probes,
    /// Density carried by the continuity equation instead of kernel summation.
    pub continuity_density: bool,
    /// delta of the density diffusion (0: off; continuity density only).
    pub density_diffusion: f64,
    /// alpha of Monaghan's artificial viscosity (0: off).
    pub artificial_viscosity: f64,
    /// gamma of Akinci et al.'s surface tension and beta of their adhesion (0: off).
    pub surface_tension: f64,
    pub wall_adhesion: f64,
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
    /// The delta-SPH term D_i = delta h_s c0 sum_j psi_ij . grad W_ij V_j
    /// with psi_ij = 2 (rho_j - rho_i) (x_j - x_i) / |x_ij|^2 (Molteni & Colagrossi 2009; Antuono
    /// et al. 2010, Eq. 5), h_s = h / 2 the smoothing length of a kernel of support h, so that
    /// the factor 2 delta h_s c0 = delta h c0. 0 when diffusion is off.
    pub fn diffusion_factor(&self) -> f64 {
        self.density_diffusion * self.h * self.speed_of_sound()
    }
    /// alpha h_s c0 of Monaghan's artificial viscosity (Monaghan 1992, Eq. 4.1), h_s = h / 2.
    pub fn artificial_viscosity_factor(&self) -> f64 {
        self.artificial_viscosity * 0.5 * self.h * self.speed_of_sound()
    }
    /// gamma m 32 / (pi h^3), the cohesion's factor outside its spline (Akinci et al. 2013,
    /// with r = q h): 0 when surface tension is off.
    pub fn cohesion_factor(&self) -> f64 {
        self.surface_tension * self.fluid_mass * 32.0 / (std::f64::consts::PI * self.h.powi(3))
    }
    /// beta 0.007 / h^3, the adhesion's factor outside its spline (Akinci et al. 2013,
    /// with r = q h): 0 when adhesion is off.
    pub fn adhesion_factor(&self) -> f64 {
        self.wall_adhesion * 0.007 / self.h.powi(3)
    }
    pub fn uses_gravity(&self) -> bool {
        self.gravity.iter().any(|&g| g != 0.0)
    }
    /// The speed of sound implied by the equation of state: c0^2 = dp/drho at rho0; 0 for
    /// DFSPH, which has no equation of state (its CFL condition is on the flow speed alone).
    pub fn speed_of_sound(&self) -> f64 {
        if self.dfsph.is_some() {
            return 0.0;
        }
        match self.eos {
            EquationOfState::Linear => (self.stiffness / self.rest_density).sqrt(),
            EquationOfState::Tait => (7.0 * self.stiffness / self.rest_density).sqrt(),
        }
    }
    /// The density and the speed at which a run stops (`limits.max_density_ratio` rho0 and
    /// `limits.max_mach` c0; infinite where a check is off or, for the speed, where the scene
    /// has no speed of sound).
    pub fn stop_levels(&self) -> StopLevels {
        // Without a speed of sound (DFSPH) there is no Mach number to check.
        let c0 = self.speed_of_sound();
        StopLevels { density: self.limits.max_density_ratio * self.rest_density, speed: if c0 > 0.0 { self.limits.max_mach * c0 } else { f64::INFINITY } }
    }
}

/// The largest density and speed a step may reach before the run stops.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StopLevels {
    pub density: f64,
    pub speed: f64,
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

/// The uniform neighbour grid over the domain, cell size h (report Sec. V), in the float type
/// `R` of whoever uses it: the scene's constants are `Grid<f64>`, the f32 paths use
/// [`Grid::cast`] of it (the same conversion on the CPU and for the GPU's parameter block).
/// Cell coordinates, keys and stencil runs are in [`super::kernels`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid<R = f64> {
    pub origin: V3<R>,
    pub cell_size: R,
    /// 1 / cell_size, computed in f64 and converted once.
    pub inv_cell: R,
    pub dims: [u32; 3],
}

impl<R: Real> Grid<R> {
    pub fn cell_count(&self) -> usize {
        self.dims.iter().map(|&d| d as usize).product()
    }
    /// The grid in another float type.
    pub fn cast<S: Real>(&self) -> Grid<S> {
        Grid { origin: V3::from64(self.origin.to64()), cell_size: S::of(self.cell_size.to64()), inv_cell: S::of(self.inv_cell.to64()), dims: self.dims }
    }
}

/// The simulated time of the GPU's adaptive step, summed exactly: significand 2^exponent, the
/// significand a 64-bit integer held at most 2^62. Each dt, an f32 m 2^e with a 24-bit m, adds
/// as m shifted by e - exponent (rounded to nearest only when e < exponent); the exponent grows
/// when the significand passes 2^62 or a dt would shift past it. So the sum is exact while each
/// dt's last bit lies above time / 2^62, on any device: integer arithmetic, unlike a Kahan sum's
/// compensation, cannot be reassociated away by a shader compiler. The twin of `add_to_time` in
/// wgsl/shared/adaptive_dt.wgsl, whose status words hold it (src/solver/gpu/params.rs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TimeSum {
    pub significand: u64,
    pub exponent: i32,
}

impl TimeSum {
    /// Zero, at the exponent of the smallest f32 (2^-149), where every f32 adds exactly.
    pub const ZERO: TimeSum = TimeSum { significand: 0, exponent: -149 };
    /// The largest significand held (2^62: a sum of two then fits in 64 bits).
    const SIGNIFICAND_LIMIT: u64 = 1 << 62;
    /// How far a 24-bit m may be shifted up and stay below 2^62.
    const SHIFT_ROOM: i32 = 38;

    /// The time, rounded to f64.
    pub fn seconds(&self) -> f64 {
        self.significand as f64 * 2f64.powi(self.exponent)
    }

    /// A time given in seconds (finite, >= 0): exact, as an f64's 53-bit significand fits.
    pub fn from_seconds(t: f64) -> TimeSum {
        if !(t.is_finite() && t > 0.0) {
            return TimeSum::ZERO;
        }
        let bits = t.to_bits();
        let biased = ((bits >> 52) & 0x7ff) as i32;
        let fraction = bits & ((1 << 52) - 1);
        let (significand, exponent) = if biased == 0 { (fraction, -1074) } else { (fraction | 1 << 52, biased - 1075) };
        TimeSum { significand, exponent }
    }

    /// Adds a step's dt (> 0, finite): the same operations as the shader's.
    pub fn add(&mut self, dt: f32) {
        let bits = dt.to_bits();
        let biased = ((bits >> 23) & 0xff) as i32;
        let m = (bits & 0x7f_ffff) as u64 | if biased == 0 { 0 } else { 0x80_0000 };
        let e = biased.max(1) - 150;
        if e - self.exponent > Self::SHIFT_ROOM {
            self.significand = shift_right_rounded(self.significand, (e - Self::SHIFT_ROOM - self.exponent) as u32);
            self.exponent = e - Self::SHIFT_ROOM;
        }
        self.significand += if e >= self.exponent { m << (e - self.exponent) } else { shift_right_rounded(m, (self.exponent - e) as u32) };
        if self.significand > Self::SIGNIFICAND_LIMIT {
            self.significand = shift_right_rounded(self.significand, 1);
            self.exponent += 1;
        }
    }

    /// The three status words: the significand's low and high word, the exponent's bits.
    pub fn words(&self) -> [u32; 3] {
        [self.significand as u32, (self.significand >> 32) as u32, self.exponent as u32]
    }

    pub fn from_words(w: [u32; 3]) -> TimeSum {
        TimeSum { significand: (w[1] as u64) << 32 | w[0] as u64, exponent: w[2] as i32 }
    }
}

/// v / 2^k rounded to nearest, ties up (v < 2^63, so adding 2^(k - 1) cannot overflow, and
/// v / 2^64 rounds to 0).
fn shift_right_rounded(v: u64, k: u32) -> u64 {
    match k {
        0 => v,
        1..=63 => (v + (1 << (k - 1))) >> k,
        _ => 0,
    }
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
    /// wgsl/sim/integrate.wgsl `choose_dt`.
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

    /// The dt a continuity density advances by at the start of a step: the last step's, the
    /// one that moved the particles to the positions the rate is taken at (the density and
    /// the positions then advance alternately by the same dt, as with a fixed dt); before any
    /// step, the CFL condition of a fluid at rest, which bounds every dt the first step can
    /// choose. The same in wgsl/sim/continuity.wgsl `continuity_dt`.
    pub fn continuity_dt(&self, h: f64, c0: f64, last_dt: f64) -> f64 {
        if last_dt > 0.0 { last_dt } else { (self.cfl_number * h / c0).clamp(self.dt_min, self.dt_max) }
    }
}

impl Grid {
    /// The same grid with cells `factor` times as wide, from the same origin over at least the
    /// same box (a neighbour skin's, src/solver/gpu/skin.rs).
    pub fn widened(&self, factor: f64) -> Grid {
        let cell_size = self.cell_size * factor;
        let dims = self.dims.map(|d| ((d as f64 * self.cell_size / cell_size).ceil().max(1.0)) as u32);
        Grid { origin: self.origin, cell_size, inv_cell: 1.0 / cell_size, dims }
    }
}

impl Scene {
    /// The cells of the domain's lattice (origin `domain.min`, size h) that a particle can
    /// reach: all of them, or in a closed container holding every fluid block only those over
    /// the container and its walls (and any other boundary's walls). A dam break's domain is
    /// sized for its coarsest walls, so at a million particles most of its cells would lie
    /// outside the tank (8 bytes of GPU memory each: about 9 bytes per fluid particle). A
    /// particle that leaks out of the grid is binned into the nearest border cell: clamping
    /// moves cells by at most as much as it moves the particle, so its neighbours within h are
    /// still in its stencil (Grid::cell_coords), and it escapes only where it leaves the domain.
    pub fn grid(&self) -> Grid {
        let h = self.physics.smoothing_length;
        let (lo, hi) = self.reachable_bounds();
        let mut origin = self.domain.min;
        let mut dims = [1u32; 3];
        for a in 0..3 {
            let skipped = ((lo[a] - self.domain.min[a]) / h).floor().max(0.0);
            origin[a] = self.domain.min[a] + skipped * h;
            let n = ((hi[a] - origin[a]) / h).ceil().max(1.0);
            dims[a] = n.min(u32::MAX as f64) as u32;
        }
        Grid { origin: V3(origin), cell_size: h, inv_cell: 1.0 / h, dims }
    }

    /// The box a particle can reach: the domain, or within it the walls of a closed container
    /// whose box holds every fluid block, together with every other boundary's walls.
    pub fn reachable_bounds(&self) -> ([f64; 3], [f64; 3]) {
        let holds_the_fluid = |min: &[f64; 3], max: &[f64; 3]| {
            !self.fluid.is_empty() && self.fluid.iter().all(|f| (0..3).all(|a| f.min[a] >= min[a] && f.max[a] <= max[a]))
        };
        // A mesh that holds the fluid is closed: the fluid outside it is cut away at the start.
        let closed = self.boundary.iter().any(|b| match b {
            Boundary::Container { min, max, open_top: false, .. } => holds_the_fluid(min, max),
            Boundary::Mesh(m) => m.fluid_inside,
            _ => false,
        });
        if !closed {
            return (self.domain.min, self.domain.max);
        }
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for (a, b) in self.boundary.iter().filter_map(|b| self.wall_span(b)) {
            for k in 0..3 {
                lo[k] = lo[k].min(a[k]).max(self.domain.min[k]);
                hi[k] = hi[k].max(b[k]).min(self.domain.max[k]);
            }
        }
        (lo, hi)
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
            // DFSPH: no equation of state.
            (None, None) => 0.0,
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
            fluid_mass: p.fluid_mass(),
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
                cfl_number: self.time.cfl_number_for(p.solver),
                force_number: self.time.force_number,
                viscous_number: self.time.viscous_number,
                dt_min: self.time.dt_min.unwrap_or(self.time.dt * 1e-3),
                dt_max: self.time.dt_max.unwrap_or(self.time.dt),
            }),
            rebuild_every: self.time.neighbour_rebuild_every,
            domain_min: self.domain.min,
            domain_max: self.domain.max,
            planes,
            solid_boxes: self
                .boundary
                .iter()
                .filter_map(|b| match b {
                    Boundary::Box { min, max, .. } => Some(SolidBox { min: *min, max: *max }),
                    _ => None,
                })
                .collect(),
            grid: self.grid(),
            dfsph: (p.solver == PressureSolver::Dfsph).then(|| p.dfsph.clone()),
            boundary_volume: p.boundary_volume,
            limits: self.limits,
            probes: self.probes(),
            continuity_density: p.density == DensityMethod::Continuity,
            density_diffusion: p.density_diffusion,
            artificial_viscosity: p.artificial_viscosity,
            surface_tension: p.surface_tension,
            wall_adhesion: p.wall_adhesion,
        }
    }
}

/// Most analytic planes a scene may have (they live in the GPU's parameter block).
pub const MAX_PLANES: usize = 8;
/// Most solid boxes a scene may have (their faces live in the GPU's parameter block too).
pub const MAX_SOLID_BOXES: usize = 8;


#[cfg(test)]
mod tests {
    use super::TimeSum;

    /// The sum in units of 2^-60 s, exact in a u128 for dts of at least 2^-20 s.
    fn exact_in_units(dts: &[f32]) -> u128 {
        dts.iter()
            .map(|&dt| {
                let bits = dt.to_bits();
                let m = ((bits & 0x7f_ffff) | 0x80_0000) as u128;
                let e = ((bits >> 23) & 0xff) as i32 - 150;
                assert!(e >= -60, "{dt} is below the reference's unit");
                m << (e + 60)
            })
            .sum()
    }

    fn in_units(t: TimeSum) -> u128 {
        assert!(t.exponent >= -60, "{t:?}");
        (t.significand as u128) << (t.exponent + 60)
    }

    #[test]
    fn a_time_sum_is_exact_where_a_float_sum_is_not() {
        let mut t = TimeSum::ZERO;
        let mut f32_sum = 0.0f32;
        for _ in 0..5000 {
            t.add(2e-4);
            f32_sum += 2e-4;
        }
        assert_eq!(t.seconds(), 2e-4f32 as f64 * 5000.0);
        assert_ne!(f32_sum as f64, t.seconds());
        // 200,000 dts from 1e-6 to 1e-3 s (up to 100 s): the sum is the exact one, bit for bit.
        let mut state = 12345u64;
        let dts: Vec<f32> = (0..200_000)
            .map(|_| {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                10f32.powf(-6.0 + 3.0 * (state >> 40) as f32 / (1u64 << 24) as f32)
            })
            .collect();
        let mut t = TimeSum::ZERO;
        for &dt in &dts {
            t.add(dt);
        }
        assert_eq!(in_units(t), exact_in_units(&dts));
        assert!(t.significand <= 1 << 62);
    }

    #[test]
    fn a_time_sum_makes_room_for_a_large_dt_and_rounds_a_negligible_one() {
        // A dt far above the sum so far: the sum's low bits are rounded away, the dt kept whole.
        let mut t = TimeSum::ZERO;
        t.add(1e-30);
        t.add(1.0);
        assert_eq!(t.seconds(), 1.0);
        t.add(3.0);
        assert_eq!(t.seconds(), 4.0);
        // A dt far below time / 2^62 rounds to nothing.
        let mut t = TimeSum::from_seconds(1.0);
        for _ in 0..20 {
            t.add(1.0);
        }
        assert_eq!(t.seconds(), 21.0);
        let before = t;
        t.add(2f32.powi(-80));
        assert_eq!(t, before, "far below the last bit");
        // Subnormal and huge dts are still sums of their values.
        let mut t = TimeSum::ZERO;
        t.add(f32::from_bits(1));
        t.add(f32::from_bits(1));
        assert_eq!(t.seconds(), 2.0 * f32::from_bits(1) as f64);
        t.add(f32::MAX);
        assert_eq!(t.seconds(), f32::MAX as f64);
    }

    #[test]
    fn a_time_in_seconds_converts_exactly_both_ways() {
        for s in [0.0, 5e-324, 1e-300, 0.1 + 0.2, 1.5, 12345.678, 1e10, f64::MAX] {
            assert_eq!(TimeSum::from_seconds(s).seconds(), s, "{s}");
            let t = TimeSum::from_seconds(s);
            assert_eq!(TimeSum::from_words(t.words()), t);
        }
        assert_eq!(TimeSum::from_seconds(f64::NAN), TimeSum::ZERO);
        assert_eq!(TimeSum::from_seconds(-1.0), TimeSum::ZERO);
    }
}
