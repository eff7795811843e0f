//! The state of a run as the layers above the solvers see it: a snapshot of the particles,
//! the fields of the last step, the health of the run, the time steps taken, and the complete
//! state a checkpoint saves.

use super::params::StopLevels;

/// Fluid particles in their original order, widened to f64.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Snapshot {
    pub step: u64,
    pub time: f64,
    pub positions: Vec<[f64; 3]>,
    pub velocities: Vec<[f64; 3]>,
    pub densities: Vec<f64>,
    pub pressures: Vec<f64>,
}

impl Snapshot {
    pub fn with_len(n: usize, step: u64, time: f64) -> Self {
        Snapshot {
            step,
            time,
            positions: vec![[0.0; 3]; n],
            velocities: vec![[0.0; 3]; n],
            densities: vec![0.0; n],
            pressures: vec![0.0; n],
        }
    }
    pub fn len(&self) -> usize {
        self.positions.len()
    }
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }
    /// Number of particles with a non-finite value in any field.
    pub fn non_finite_count(&self) -> usize {
        (0..self.len())
            .filter(|&i| {
                !(self.positions[i].iter().chain(&self.velocities[i]).all(|v| v.is_finite())
                    && self.densities[i].is_finite()
                    && self.pressures[i].is_finite())
            })
            .count()
    }
    pub fn max_speed(&self) -> f64 {
        self.velocities.iter().map(|v| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()).fold(0.0, f64::max)
    }
    /// The largest speed and the density range over the particles whose values are finite.
    pub fn extremes(&self) -> SnapshotExtremes {
        let mut e = SnapshotExtremes::NONE;
        for (v, &rho) in self.velocities.iter().zip(&self.densities) {
            if v.iter().all(|x| x.is_finite()) && rho.is_finite() {
                e.add(*v, rho);
            }
        }
        e
    }
    pub fn kinetic_energy(&self, mass: f64) -> f64 {
        self.velocities.iter().map(|v| 0.5 * mass * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2])).sum()
    }
}

/// What a snapshot shows of the state's health, over its finite particles: whether it is a
/// good state to name as the last one (a step's density check reads the state it starts from,
/// so a snapshot can show a density the next step stops at), and its speed for a later
/// diagnosis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SnapshotExtremes {
    pub max_speed: f64,
    pub min_density: f64,
    pub max_density: f64,
    /// The particles whose density is zero or below (a continuity density driven negative).
    pub non_positive_density: u64,
}

impl SnapshotExtremes {
    /// Of no particle.
    pub const NONE: SnapshotExtremes = SnapshotExtremes { max_speed: 0.0, min_density: f64::INFINITY, max_density: f64::NEG_INFINITY, non_positive_density: 0 };

    /// Adds a particle of velocity `v` and density `rho` (finite).
    pub fn add(&mut self, v: [f64; 3], rho: f64) {
        self.max_speed = self.max_speed.max((v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt());
        self.min_density = self.min_density.min(rho);
        self.max_density = self.max_density.max(rho);
        self.non_positive_density += (rho <= 0.0) as u64;
    }

    /// Of the particles of both.
    pub fn merge(self, o: SnapshotExtremes) -> SnapshotExtremes {
        SnapshotExtremes {
            max_speed: self.max_speed.max(o.max_speed),
            min_density: self.min_density.min(o.min_density),
            max_density: self.max_density.max(o.max_density),
            non_positive_density: self.non_positive_density + o.non_positive_density,
        }
    }

    /// Why the state is not a good one, against the run's stop levels; None where it is.
    pub fn why_bad(&self, stop: StopLevels, rest_density: f64) -> Option<String> {
        if self.non_positive_density > 0 {
            return Some(format!("the density of {} particles is zero or below (down to {} kg/m^3)", self.non_positive_density, crate::model::numbers::short(self.min_density)));
        }
        if self.max_density > stop.density {
            return Some(format!("its density reaches {} rho0, over the stop level", crate::model::numbers::short(self.max_density / rest_density)));
        }
        if self.max_speed > stop.speed {
            return Some(format!("its speed reaches {}, over the stop level", crate::model::numbers::short(self.max_speed)));
        }
        None
    }
}

/// The fields one step computed, in original particle order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StepFields {
    pub densities: Vec<f64>,
    pub pressures: Vec<f64>,
    pub accelerations: Vec<[f64; 3]>,
}

/// The iterations of one of DFSPH's two solves over a run.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SolveStats {
    /// Iterations over all steps.
    pub total: u64,
    /// The most iterations one step took.
    pub max: u32,
    /// The last step's iterations.
    pub last: u32,
    /// The average error the last step's solve ended with (a fraction of rho0).
    pub last_error: f64,
    /// Steps whose solve stopped at its iteration limit with the error above the tolerance.
    pub unconverged: u64,
}

impl SolveStats {
    /// Iterations per step, on average over `steps` steps.
    pub fn mean(&self, steps: u64) -> f64 {
        if steps == 0 { 0.0 } else { self.total as f64 / steps as f64 }
    }
}

/// DFSPH's iterations: the constant-density (pressure) solve and the divergence solve.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct IterationStats {
    pub pressure: SolveStats,
    pub divergence: SolveStats,
}

/// DFSPH's arrays at some point of a step, in original particle order (for the stage tests).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DfsphFields {
    pub densities: Vec<f64>,
    pub pressures: Vec<f64>,
    pub factors: Vec<f64>,
    pub wall_gradients: Vec<[f64; 3]>,
    pub stiffness: Vec<f64>,
    pub pressure_sum: Vec<f64>,
    pub divergence_sum: Vec<f64>,
    /// The velocities the solves work on: the state's own up to the prediction, the predicted
    /// ones after it.
    pub velocities: Vec<[f64; 3]>,
}

/// What a run found wrong, and the largest density and speed seen.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Health {
    /// Particles with a non-finite position or velocity after the last step (those of the
    /// first bad step are in `bad_step`).
    pub non_finite: u64,
    /// Particles outside the domain after the last step.
    pub escaped: u64,
    /// The first step after which a particle was non-finite or outside the domain, or the
    /// largest density or speed passed its stop level.
    pub first_bad_step: Option<u64>,
    /// Largest density over all steps so far.
    pub max_density: f64,
    /// DFSPH's iterations so far (`None` for weakly compressible SPH).
    pub iterations: Option<IterationStats>,
    /// Largest speed over all steps so far.
    pub max_speed: f64,
    /// What was measured at the first bad step, recorded when it happened (so that a later
    /// read sees that step's figures, not those of a step after it).
    pub bad_step: Option<BadStep>,
}

/// What one step measured: the counts of bad particles, the largest density (of the state it
/// started from) and speed (after it), its dt and the time at its end.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StepMeasures {
    pub non_finite: u64,
    pub escaped: u64,
    pub max_density: f64,
    pub max_speed: f64,
    pub dt: f64,
    pub time: f64,
}

/// The first step that went wrong, what it measured and which checks it failed.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BadStep {
    pub step: u64,
    pub measured: StepMeasures,
    /// The largest density passed the stop level (`limits.max_density_ratio` rho0).
    pub too_dense: bool,
    /// The largest speed passed the stop level (`limits.max_mach` c0).
    pub too_fast: bool,
}

impl BadStep {
    /// The step's measures judged against the stop levels: `None` when it went well.
    pub fn judge(step: u64, measured: StepMeasures, stop: StopLevels) -> Option<BadStep> {
        let too_dense = measured.max_density > stop.density;
        let too_fast = measured.max_speed > stop.speed;
        (measured.non_finite > 0 || measured.escaped > 0 || too_dense || too_fast).then_some(BadStep { step, measured, too_dense, too_fast })
    }
}

impl Health {
    pub fn is_ok(&self) -> bool {
        self.first_bad_step.is_none()
    }
    /// Records a step: the running maxima, and the first step that went wrong with what it
    /// measured (later bad steps change nothing: the health describes the first).
    pub fn record(&mut self, step: u64, measured: StepMeasures, stop: StopLevels) {
        self.non_finite = measured.non_finite;
        self.escaped = measured.escaped;
        self.max_speed = self.max_speed.max(measured.max_speed);
        if self.bad_step.is_none() {
            if let Some(bad) = BadStep::judge(step, measured, stop) {
                self.bad_step = Some(bad);
                self.first_bad_step = Some(step);
            }
        }
    }
    /// The counts of non-finite and escaped particles of the event that stopped the run: the
    /// first bad step's, or after the last step where none went bad.
    pub fn bad_counts(&self) -> (u64, u64) {
        self.bad_step.map_or((self.non_finite, self.escaped), |b| (b.measured.non_finite, b.measured.escaped))
    }
    /// The health as it stood at the first bad step: the running maxima of `before` (read at a
    /// step before it) and of that step, not those of the steps a batch ran on past it, whose
    /// figures (a density of 300 rho0, a speed of 1e17) describe the wreck, not the event.
    /// Without a bad step, the health itself.
    pub fn until_first_bad_step(&self, before: &Health) -> Health {
        match self.bad_step {
            Some(bad) => Health {
                max_density: before.max_density.max(bad.measured.max_density),
                max_speed: before.max_speed.max(bad.measured.max_speed),
                ..self.clone()
            },
            None => self.clone(),
        }
    }
}

/// The time steps taken so far: smallest, largest, mean and the last one.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DtStats {
    pub min: f64,
    pub max: f64,
    pub mean: f64,
    pub last: f64,
}

impl DtStats {
    pub fn fixed(dt: f64) -> Self {
        DtStats { min: dt, max: dt, mean: dt, last: dt }
    }
}

/// The complete dynamic state of a backend: particles in the internal order the next step's
/// binning starts from (the order inside a cell depends on it), their original ids, the step
/// count and the health counters. Values are widened to f64, which is exact for f32.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BackendState {
    /// `gpu`, `cpu f32` or `cpu f64`: a state is restored only into the same kind.
    pub kind: String,
    pub step: u64,
    pub positions: Vec<[f64; 3]>,
    pub velocities: Vec<[f64; 3]>,
    pub ids: Vec<u32>,
    pub non_finite: u64,
    pub escaped: u64,
    pub first_bad_step: Option<u64>,
    pub max_density: f64,
    pub max_speed: f64,
    pub bad_step: Option<BadStep>,
    /// The CPU's simulated time and its smallest, largest and last dt (adaptive dt makes
    /// time differ from step x dt).
    pub time: f64,
    pub dt_min_max_last: [f64; 3],
    /// The GPU's whole status buffer (health counters, and the adaptive step's dt and exact
    /// time), restored word for word.
    pub gpu_status: Vec<u32>,
    /// DFSPH: each particle's stiffness sums of the last step (constant-density solve,
    /// divergence solve), by original id, where the next step's solves start; empty for WCSPH.
    pub warm_start: Vec<[f64; 2]>,
    /// DFSPH on the CPU: the iterations so far (the GPU keeps them in its status words).
    pub iterations: IterationStats,
    /// With continuity density: each particle's carried density, in the order of `positions`;
    /// empty otherwise.
    pub densities: Vec<f64>,
}

impl BackendState {
    /// Checks that the state fits a backend of `kind` with `fluid_count` particles.
    pub fn check_fits(&self, kind: &str, fluid_count: usize) -> anyhow::Result<()> {
        anyhow::ensure!(self.kind == kind, "the state was saved by the {} backend, not {kind}", self.kind);
        let n = fluid_count;
        anyhow::ensure!(
            self.positions.len() == n && self.velocities.len() == n && self.ids.len() == n && (self.densities.is_empty() || self.densities.len() == n),
            "the state holds {} positions, {} velocities, {} ids and {} carried densities; the scene has {n} particles",
            self.positions.len(),
            self.velocities.len(),
            self.ids.len(),
            self.densities.len()
        );
        let mut seen = vec![false; n];
        for &id in &self.ids {
            anyhow::ensure!((id as usize) < n && !seen[id as usize], "the state's particle ids are not a permutation");
            seen[id as usize] = true;
        }
        Ok(())
    }
    pub fn health(&self) -> Health {
        Health {
            non_finite: self.non_finite,
            escaped: self.escaped,
            first_bad_step: self.first_bad_step,
            max_density: self.max_density,
            max_speed: self.max_speed,
            bad_step: self.bad_step,
            iterations: None,
        }
    }
}

