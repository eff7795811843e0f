//! DFSPH on the CPU (Bender & Koschier 2015, 2017): the order of a step. Each stage is the twin
//! of the WGSL file of the same name (`dfsph_factors`, `dfsph_divergence`, `dfsph_predict`,
//! `dfsph_pressure`, `dfsph_convergence`, `dfsph_integrate`); what they share is in
//! `dfsph_shared` (the twin of wgsl/shared/dfsph.wgsl).

use super::dfsph_convergence::{begin_solve, check_convergence, SolveLimits};
use super::dfsph_divergence::{divergence_apply, divergence_rate, divergence_warm_start};
use super::dfsph_factors::{density_and_factor, FactorsInput, FactorsOutput};
use super::dfsph_integrate::{integrate, keep_warm_start, step_accelerations};
use super::dfsph_predict::{choose_dt, non_pressure_accelerations, predict_from_accelerations, predict_velocities, PredictInput};
use super::dfsph_pressure::{predict_density, pressure_apply, pressure_warm_start};
use super::dfsph_shared::{error_threshold, factor_epsilon, Pairs, SolveInput, WarmStart, WARM_START_SHARE};
use super::exchange::GhostLink;
use super::forces::SurfaceTension;
use super::integrate::{Backstops, StepHealth};
use crate::model::kernels::{KernelCoefficients, Neighbours};
use crate::model::params::{Grid, Params};
use crate::model::real::{Real, V3};
use crate::model::scene::DfsphSettings;
use crate::model::state::IterationStats;

/// DFSPH's arrays on the CPU, in the solver's cell order except the warm-start stiffnesses,
/// which are kept by particle id (the binning reorders the particles every step).
#[derive(Clone)]
pub struct DfsphCpu<R: Real> {
    pub settings: DfsphSettings,
    pub factors: Vec<R>,
    pub wall_gradients: Vec<V3<R>>,
    /// K of the current solve's last Jacobi step.
    pub stiffness: Vec<R>,
    /// The sums of K over this step's constant-density and divergence solves.
    pub pressure_sum: Vec<R>,
    pub divergence_sum: Vec<R>,
    /// Last step's sums, by particle id: where the next step's solves start.
    pub warm_pressure: Vec<R>,
    pub warm_divergence: Vec<R>,
    pub pairs: Pairs<R>,
    pub stats: IterationStats,
    /// The last step's dt (0 before the first).
    pub last_dt: f64,
    /// The dt the prediction chose for the step under way.
    pub dt: f64,
}

/// The parts of the CPU solver a DFSPH step reads and writes.
pub struct StepParts<'a, R: Real> {
    pub params: &'a Params,
    pub kernel: &'a KernelCoefficients<R>,
    pub grid: &'a Grid<R>,
    pub backstops: &'a Backstops<R>,
    pub positions: &'a mut [V3<R>],
    pub velocities: &'a mut Vec<V3<R>>,
    pub starts: &'a [u32],
    /// Receives the predicted velocities; afterwards it holds the velocities after the
    /// divergence solve.
    pub scratch: &'a mut Vec<V3<R>>,
    /// Each slot's entry in DFSPH's warm-start arrays: its id alone, across ranks its place in
    /// the rank's last exchange.
    pub warm_index: &'a [u32],
    pub densities: &'a mut [R],
    pub pressures: &'a mut [R],
    /// The non-pressure accelerations (adaptive dt), then the step's accelerations
    /// ([`step_accelerations`]).
    pub accelerations: &'a mut [V3<R>],
    pub wall_positions: &'a [V3<R>],
    pub wall_starts: &'a [u32],
    pub wall_masses: &'a [R],
    /// With surface tension, each fluid particle's normal from the factors' densities
    /// (surface_normals.rs, which the solver runs before the prediction); empty otherwise.
    pub normals: &'a [V3<R>],
    /// The step about to run (for the viscosity schedule).
    pub step: u64,
    /// Whether the factors pass runs eight particles at a time ([`super::CpuSolver::use_lanes`]).
    pub lanes: bool,
    /// The fluid particles of the whole simulation (the solves' average error is over them).
    pub particles: usize,
    /// Across ranks: the ghosts' part in the solves (`None` alone).
    pub link: Option<&'a mut GhostLink>,
}

impl<R: Real> StepParts<'_, R> {
    /// Which slots hold ghosts (empty alone).
    fn ghosts(&self) -> &[bool] {
        self.link.as_ref().map_or(&[], |l| &l.ghosts[..])
    }

    /// After a change of the velocities: across ranks the ghosts take their owners'.
    fn sync_velocities(&mut self) {
        if let Some(link) = self.link.as_deref_mut() {
            link.sync(&mut self.velocities[..]);
        }
    }

    /// This rank's error sum, across ranks the ranks' together.
    fn total_error(&mut self, units: u64) -> u64 {
        match self.link.as_deref_mut() {
            Some(link) => link.sum_units(units),
            None => units,
        }
    }
}

impl<R: Real> DfsphCpu<R> {
    pub fn new(settings: &DfsphSettings, n: usize) -> Self {
        DfsphCpu {
            settings: settings.clone(),
            factors: vec![R::zero(); n],
            wall_gradients: vec![V3::zero(); n],
            stiffness: vec![R::zero(); n],
            pressure_sum: vec![R::zero(); n],
            divergence_sum: vec![R::zero(); n],
            warm_pressure: vec![R::zero(); n],
            warm_divergence: vec![R::zero(); n],
            pairs: Pairs::default(),
            stats: IterationStats::default(),
            last_dt: 0.0,
            dt: 0.0,
        }
    }

    /// The arrays kept by slot for `n` held particles (across ranks the count changes from step
    /// to step; the warm starts are kept by id for every particle of the simulation).
    pub fn resize(&mut self, n: usize) {
        self.factors.resize(n, R::zero());
        self.wall_gradients.resize(n, V3::zero());
        self.stiffness.resize(n, R::zero());
        self.pressure_sum.resize(n, R::zero());
        self.divergence_sum.resize(n, R::zero());
    }

    /// Bytes of the arrays (the neighbour lists at their current capacity).
    pub fn memory_bytes(&self) -> u64 {
        let r = std::mem::size_of::<R>() as u64;
        self.factors.len() as u64 * (9 * r) + self.pairs.bytes()
    }

    /// The dt the divergence solve judges its error with: the step's own with a fixed dt; with
    /// adaptive dt the last step's (the new one is chosen after the solve), dt_max before any.
    pub fn divergence_dt(&self, params: &Params) -> f64 {
        match params.adaptive {
            Some(_) if self.last_dt > 0.0 => self.last_dt,
            Some(a) => a.dt_max,
            None => params.dt,
        }
    }

    /// 1 / (rho0 dt^2) of the last step, which scales the output pressure (0 before any step
    /// with adaptive dt).
    fn pressure_scale(&self, params: &Params) -> R {
        let dt = if params.adaptive.is_some() { self.last_dt } else { params.dt };
        if dt > 0.0 {
            let dt = R::of(dt);
            R::one() / (R::of(params.rest_density) * dt * dt)
        } else {
            R::zero()
        }
    }

    fn solve_input<'a>(&'a self, volume: R, ghosts: &'a [bool]) -> SolveInput<'a, R> {
        SolveInput { pairs: &self.pairs, volume, factors: &self.factors, wall_gradients: &self.wall_gradients, ghosts }
    }

    /// The factors stage on the current state: density, output pressure, alpha, wall gradients,
    /// the neighbour lists and the divergence warm start.
    pub fn factors_stage(&mut self, s: &mut StepParts<'_, R>) {
        let p = s.params;
        let input = FactorsInput {
            kernel: s.kernel,
            grid: s.grid,
            fluid_mass: R::of(p.fluid_mass),
            rest_density: R::of(p.rest_density),
            volume: R::of(p.fluid_mass / p.rest_density),
            fluid: Neighbours { positions: s.positions, starts: s.starts },
            walls: Neighbours { positions: s.wall_positions, starts: s.wall_starts },
            wall_masses: s.wall_masses,
            ids: s.warm_index,
            warm_pressure: &self.warm_pressure,
            pressure_scale: self.pressure_scale(p),
            factor_epsilon: R::of(factor_epsilon(p.h)),
            lanes: s.lanes,
        };
        let out = FactorsOutput {
            densities: s.densities,
            pressures: s.pressures,
            factors: &mut self.factors,
            wall_gradients: &mut self.wall_gradients,
            divergence_sum: &mut self.divergence_sum,
        };
        density_and_factor(&input, out, &mut self.pairs);
    }

    /// The divergence solve on the current velocities.
    pub fn divergence_solve(&mut self, s: &mut StepParts<'_, R>) {
        let p = s.params;
        let volume = R::of(p.fluid_mass / p.rest_density);
        let dt = R::of(self.divergence_dt(p));
        let n = s.particles;
        let limits = SolveLimits {
            min_iterations: self.settings.min_divergence_iterations,
            max_iterations: self.settings.max_divergence_iterations,
            threshold: error_threshold(self.settings.divergence_error, n),
            particles: n,
        };
        let ghosts = s.ghosts().to_vec();
        let mut stats = self.stats.divergence;
        let mut stiffness = std::mem::take(&mut self.stiffness);
        let mut sums = std::mem::take(&mut self.divergence_sum);
        let warm = self.settings.warm_start;
        if warm {
            let last = WarmStart { ids: s.warm_index, last: &self.warm_divergence, share: R::of(WARM_START_SHARE) };
            divergence_warm_start(&self.solve_input(volume, &ghosts), s.velocities, &last, &mut stiffness);
            divergence_apply(&self.solve_input(volume, &ghosts), &stiffness, s.velocities, &mut sums);
            s.sync_velocities();
        }
        let mut solve = begin_solve(warm);
        let error = divergence_rate(&self.solve_input(volume, &ghosts), s.velocities, dt, &mut stiffness);
        check_convergence(&limits, &mut solve, s.total_error(error), &mut stats);
        while solve.solving {
            divergence_apply(&self.solve_input(volume, &ghosts), &stiffness, s.velocities, &mut sums);
            s.sync_velocities();
            let error = divergence_rate(&self.solve_input(volume, &ghosts), s.velocities, dt, &mut stiffness);
            check_convergence(&limits, &mut solve, s.total_error(error), &mut stats);
        }
        self.stiffness = stiffness;
        self.divergence_sum = sums;
        self.stats.divergence = stats;
    }

    /// Viscosity and gravity, the step's dt, the predicted velocities (into `scratch`, then
    /// swapped with the velocities) and the constant-density warm start. Returns dt.
    pub fn predict(&mut self, s: &mut StepParts<'_, R>) -> f64 {
        let p = s.params;
        let n = s.velocities.len();
        s.scratch.resize(n, V3::zero());
        let input = PredictInput {
            kernel: s.kernel,
            grid: s.grid,
            fluid_mass: R::of(p.fluid_mass),
            rest_density: R::of(p.rest_density),
            viscosity: R::of(p.viscosity_at_step(s.step)),
            boundary_friction: R::of(p.boundary_friction),
            gravity: V3::from64(p.gravity),
            fluid: Neighbours { positions: s.positions, starts: s.starts },
            velocities: s.velocities,
            densities: s.densities,
            walls: Neighbours { positions: s.wall_positions, starts: s.wall_starts },
            wall_masses: s.wall_masses,
            tension: SurfaceTension::of(p),
            adhesion_factor: R::of(p.adhesion_factor()),
            normals: s.normals,
        };
        let dt = match p.adaptive {
            None => {
                predict_velocities(&input, R::of(p.dt), s.scratch, &mut self.pressure_sum);
                p.dt
            }
            Some(adaptive) => {
                let mut maxima = non_pressure_accelerations(&input, s.accelerations);
                if let Some(link) = s.link.as_deref_mut() {
                    // The own particles' maxima (as non_pressure_accelerations takes them), then
                    // the ranks' largest.
                    let own = |values: &[V3<R>]| {
                        values.iter().zip(&link.ghosts).filter(|(_, &ghost)| !ghost).map(|(v, _)| v.length().to64()).filter(|v| v.is_finite()).fold(0.0, f64::max)
                    };
                    let all = link.max(&[own(input.velocities), own(s.accelerations)]);
                    maxima = (all[0], all[1]);
                }
                let dt = choose_dt(&adaptive, p.h, maxima, p.viscosity_at_step(s.step));
                predict_from_accelerations(s.velocities, s.accelerations, R::of(dt), s.scratch, &mut self.pressure_sum);
                dt
            }
        };
        std::mem::swap(s.velocities, s.scratch);
        s.sync_velocities();
        self.dt = dt;
        dt
    }

    /// The constant-density solve on the predicted velocities.
    pub fn pressure_solve(&mut self, s: &mut StepParts<'_, R>, dt: f64) {
        let p = s.params;
        let volume = R::of(p.fluid_mass / p.rest_density);
        let (dt, inv_dt) = (R::of(dt), R::one() / R::of(dt));
        let rest_density = R::of(p.rest_density);
        let n = s.particles;
        let limits = SolveLimits {
            min_iterations: self.settings.min_iterations,
            max_iterations: self.settings.max_iterations,
            threshold: error_threshold(self.settings.density_error, n),
            particles: n,
        };
        let ghosts = s.ghosts().to_vec();
        let mut stats = self.stats.pressure;
        let mut stiffness = std::mem::take(&mut self.stiffness);
        let mut sums = std::mem::take(&mut self.pressure_sum);
        let warm = self.settings.warm_start;
        if warm {
            let last = WarmStart { ids: s.warm_index, last: &self.warm_pressure, share: R::of(WARM_START_SHARE) };
            pressure_warm_start(&self.solve_input(volume, &ghosts), s.velocities, s.densities, rest_density, dt, &last, &mut stiffness);
            pressure_apply(&self.solve_input(volume, &ghosts), &stiffness, inv_dt, s.velocities, &mut sums);
            s.sync_velocities();
        }
        let mut solve = begin_solve(warm);
        let error = predict_density(&self.solve_input(volume, &ghosts), s.velocities, s.densities, rest_density, dt, &mut stiffness);
        check_convergence(&limits, &mut solve, s.total_error(error), &mut stats);
        while solve.solving {
            pressure_apply(&self.solve_input(volume, &ghosts), &stiffness, inv_dt, s.velocities, &mut sums);
            s.sync_velocities();
            let error = predict_density(&self.solve_input(volume, &ghosts), s.velocities, s.densities, rest_density, dt, &mut stiffness);
            check_convergence(&limits, &mut solve, s.total_error(error), &mut stats);
        }
        self.stiffness = stiffness;
        self.pressure_sum = sums;
        self.stats.pressure = stats;
    }

    // A step on a binned state is `factors_stage`, `solve`, `finish`, in that order
    // (`CpuSolver::step_once`, which samples the probes between them).

    /// The solves and the prediction between them; returns the step's dt. Afterwards
    /// `s.velocities` holds the new velocities and `s.scratch` those the prediction started
    /// from (after the divergence solve); the positions are still the step's first.
    pub fn solve(&mut self, s: &mut StepParts<'_, R>) -> f64 {
        if self.settings.divergence_solve {
            self.divergence_solve(s);
        }
        let dt = self.predict(s);
        self.pressure_solve(s, dt);
        dt
    }

    /// The end of a step after [`DfsphCpu::solve`]: the positions advanced, the warm start kept
    /// and the step's accelerations. Returns what went wrong and dt.
    pub fn finish(&mut self, s: &mut StepParts<'_, R>, dt: f64) -> (StepHealth, f64) {
        let p = s.params;
        let domain = (V3::from64(p.domain_min), V3::from64(p.domain_max));
        let ghosts: &[bool] = s.link.as_ref().map_or(&[], |l| &l.ghosts[..]);
        let found = integrate(s.positions, s.velocities, R::of(dt), s.backstops, domain, ghosts);
        keep_warm_start(s.warm_index, &self.pressure_sum, &self.divergence_sum, &mut self.warm_pressure, &mut self.warm_divergence);
        step_accelerations(s.scratch, s.velocities, R::of(dt), s.accelerations);
        self.last_dt = dt;
        (found, dt)
    }
}
