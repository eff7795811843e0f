//! The [`Backend`] trait every layer above the solvers drives, and what it hands out.

use super::decomposition::RankReport;
use super::gpu::buffers::ParticleBuffers;
use crate::model::diagnosis::{diagnose, FailureScan};
use crate::model::params::Params;
use crate::model::probes::ProbeSample;
use crate::model::scene::Scene;
use crate::model::state::{BackendState, DtStats, Health, Snapshot, StepFields};

/// One particle of a snapshot as a backend hands it over in pieces: x, y, z, vx, vy, vz,
/// density, pressure, in f32 (what the GPU holds).
pub type SnapshotRow = [f32; 8];

/// Across ranks, one rank's part of a snapshot that every rank writes into the same files
/// (`io::snapshot::pieces`): the particles of a block of consecutive original ids
/// ([`id_block`]), in original order, and the ranks that write together. No rank holds every
/// particle.
pub struct SnapshotPiece {
    pub step: u64,
    pub time: f64,
    /// Fluid particles of the whole simulation.
    pub total: u64,
    /// The original id of the first row.
    pub first: u64,
    /// `x y z vx vy vz density pressure` of particles `first..first + rows.len()`.
    pub rows: Vec<[f64; 8]>,
    pub comm: std::sync::Arc<dyn super::communicator::Communicator>,
}

/// The original ids whose snapshot rows rank `rank` of `ranks` writes: `total` cut into
/// blocks of consecutive ids whose sizes differ by at most one.
pub fn id_block(total: u64, ranks: usize, rank: usize) -> std::ops::Range<u64> {
    let start = |r: usize| (total as u128 * r as u128 / ranks.max(1) as u128) as u64;
    start(rank)..start(rank + 1)
}

/// A saved state that one rank of several reads its part of, without holding every particle
/// (a checkpoint file, `io::checkpoint`, or a state held whole).
pub trait StateSource {
    /// Every particle's position, in the state's order.
    fn visit_positions(&mut self, visit: &mut dyn FnMut([f64; 3])) -> anyhow::Result<()>;
    /// The state with only the particles that `keep(index, position)` accepts, and their
    /// indices in the state, ascending; DFSPH's warm starts (by id in the state) are those of
    /// the kept particles, in their order.
    fn read_kept(&mut self, keep: &mut dyn FnMut(usize, [f64; 3]) -> bool) -> anyhow::Result<(BackendState, Vec<u64>)>;
}

/// A state held whole as a [`StateSource`].
pub struct WholeState<'a>(pub &'a BackendState);

impl StateSource for WholeState<'_> {
    fn visit_positions(&mut self, visit: &mut dyn FnMut([f64; 3])) -> anyhow::Result<()> {
        self.0.positions.iter().for_each(|&p| visit(p));
        Ok(())
    }
    fn read_kept(&mut self, keep: &mut dyn FnMut(usize, [f64; 3]) -> bool) -> anyhow::Result<(BackendState, Vec<u64>)> {
        let state = self.0;
        let kept: Vec<u64> = (0..state.positions.len()).filter(|&i| keep(i, state.positions[i])).map(|i| i as u64).collect();
        let pick = |v: &Vec<[f64; 3]>| kept.iter().map(|&i| v[i as usize]).collect::<Vec<_>>();
        let part = BackendState {
            positions: pick(&state.positions),
            velocities: pick(&state.velocities),
            ids: kept.iter().map(|&i| state.ids[i as usize]).collect(),
            densities: if state.densities.is_empty() { Vec::new() } else { kept.iter().map(|&i| state.densities[i as usize]).collect() },
            warm_start: if state.warm_start.is_empty() { Vec::new() } else { kept.iter().map(|&i| state.warm_start[state.ids[i as usize] as usize]).collect() },
            ..state.clone()
        };
        Ok((part, kept))
    }
}

/// One of the particle arrays of a saved state ([`BackendState`]), in the backend's internal
/// order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StateArray {
    Positions,
    Velocities,
    Ids,
    /// DFSPH's warm-start stiffnesses by particle id (empty for WCSPH).
    WarmStart,
    /// The densities the continuity equation carries (empty with summation density).
    Densities,
}

/// A stage of a DFSPH step, run alone by the stage tests (`CpuSolver::dfsph_stage`,
/// `GpuSolver::dfsph_stage`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DfsphStage {
    /// Density, output pressure, factors, wall gradients.
    Factors,
    /// The divergence solve's starting stiffness.
    DivergenceWarmStart,
    /// The divergence solve's stiffness and error from the current velocities.
    DivergenceRate,
    /// One Jacobi step of the divergence solve with the current stiffness.
    DivergenceApply,
    /// Viscosity, gravity, dt and the predicted velocities.
    Predict,
    /// The constant-density solve's starting stiffness.
    PressureWarmStart,
    /// The constant-density solve's stiffness and error from the predicted velocities.
    PredictDensity,
    /// One Jacobi step of the constant-density solve with the current stiffness.
    PressureApply,
}

/// A piece of a [`StateArray`]: vectors (positions, velocities) widened to f64, or ids.
pub enum StatePiece<'a> {
    Vectors(&'a [[f64; 3]]),
    Ids(&'a [u32]),
    Pairs(&'a [[f64; 2]]),
    Scalars(&'a [f64]),
}

/// A simulation the layers above can drive: the CPU reference or the GPU pipeline. It knows no
/// file format and no picture: it hands out snapshots, rows and state, and the io and viz layers
/// turn them into files and pictures.
pub trait Backend {
    /// "cpu" or "gpu".
    fn kind(&self) -> &'static str;
    /// The adapter name, or "cpu".
    fn adapter(&self) -> String;
    /// The GPU driver and its version where the adapter reports them; empty on the CPU path.
    fn driver(&self) -> String {
        String::new()
    }
    fn params(&self) -> &Params;
    fn fluid_count(&self) -> usize;
    fn wall_count(&self) -> usize;
    /// Advances up to `n` steps (a backend may stop early after a step that went wrong).
    fn step(&mut self, n: u64) -> anyhow::Result<()>;
    fn steps_done(&self) -> u64;
    /// Simulated time reached so far.
    fn time(&self) -> f64 {
        self.steps_done() as f64 * self.params().dt
    }
    /// The steps taken so far (with adaptive dt a few bytes read from the GPU).
    fn dt_stats(&mut self) -> anyhow::Result<DtStats> {
        Ok(if self.steps_done() == 0 { DtStats::default() } else { DtStats::fixed(self.params().dt) })
    }
    /// Bytes the backend allocated for the simulation, where it knows.
    fn memory_bytes(&self) -> Option<u64> {
        None
    }
    /// Reads the health counters (a few bytes on the GPU).
    fn health(&mut self) -> anyhow::Result<Health>;
    /// The particles in original order, with density and pressure evaluated for the current
    /// positions. Taking a snapshot never changes the trajectory. Across ranks every rank
    /// calls it (it is collective) and rank 0 receives every particle; the other ranks get the
    /// step and time with no particle. [`Backend::step_fields`] and [`Backend::save_state`]
    /// do the same.
    fn snapshot(&mut self) -> anyhow::Result<Snapshot>;
    /// Whether [`Backend::visit_snapshot_rows`] hands the snapshot over in pieces (the GPU,
    /// which then never needs one host copy of every array).
    fn streams_snapshots(&self) -> bool {
        false
    }
    /// The snapshot of [`Backend::snapshot`] in pieces: `visit(first, rows)` gets particles
    /// `first..first + rows.len()` of the original order, in order. Only where
    /// [`Backend::streams_snapshots`]; elsewhere an error.
    fn visit_snapshot_rows(&mut self, _visit: &mut dyn FnMut(u64, &[SnapshotRow]) -> anyhow::Result<()>) -> anyhow::Result<()> {
        anyhow::bail!("the {} backend hands out whole snapshots only", self.kind())
    }
    /// Across ranks: this rank's [`SnapshotPiece`] of the snapshot [`Backend::snapshot`]
    /// would give (collective: every rank calls it; the rows travel to the rank whose block of
    /// ids holds them, never all to one). `None` alone.
    fn snapshot_piece(&mut self) -> Option<anyhow::Result<SnapshotPiece>> {
        None
    }
    /// Density, pressure and acceleration computed by the last step, in original particle
    /// order (read before a snapshot, which re-evaluates density for the new positions).
    fn step_fields(&mut self) -> anyhow::Result<StepFields>;
    /// The device and the particle buffers of a backend that keeps its particles on a GPU, for
    /// drawing them where they are (in the backend's current order, after the last step).
    fn gpu_particles(&self) -> Option<ParticleBuffers> {
        None
    }
    /// Everything the next step reads, in the backend's internal (cell) order, for checkpoints.
    fn save_state(&mut self) -> anyhow::Result<BackendState>;
    /// [`Backend::save_state`] without its particle arrays (left empty), which
    /// [`Backend::visit_state_array`] hands over in pieces.
    fn save_state_header(&mut self) -> anyhow::Result<BackendState> {
        Ok(state_header(self.save_state()?))
    }
    /// Elements of one particle array of the saved state: every fluid particle's, but DFSPH's
    /// warm start, which only DFSPH has.
    fn state_array_len(&self, array: StateArray) -> usize {
        match array {
            StateArray::WarmStart if self.params().dfsph.is_none() => 0,
            StateArray::Densities if !self.params().continuity_density => 0,
            _ => self.fluid_count(),
        }
    }
    /// One particle array of the saved state, in pieces of at most `chunk` particles, in order.
    fn visit_state_array(&mut self, array: StateArray, chunk: u64, visit: &mut dyn FnMut(StatePiece) -> anyhow::Result<()>) -> anyhow::Result<()> {
        visit_state_pieces(&self.save_state()?, array, chunk, visit)
    }
    /// Continues from a saved state: the following steps are bitwise those the saving backend
    /// would have computed (on the same adapter or float type).
    fn restore_state(&mut self, state: &BackendState) -> anyhow::Result<()>;
    /// Across ranks: [`Backend::restore_state`] with each rank reading only its part of the
    /// state from `source` (collective). `None` alone.
    fn restore_state_part(&mut self, _source: &mut dyn StateSource) -> Option<anyhow::Result<()>> {
        None
    }
    /// The samples of the scene's probes taken since the last call, in step order: each holds
    /// every probe's values, for the steps at which some probe was due
    /// ([`crate::model::probes::Probes::samples_step`]). A few numbers per sample: no particle
    /// array is read back.
    fn take_probe_samples(&mut self) -> anyhow::Result<Vec<ProbeSample>> {
        Ok(Vec::new())
    }
    /// This rank's part when the simulation runs across ranks (`None` alone).
    fn rank_report(&self) -> Option<RankReport> {
        None
    }
    /// Every rank's part, gathered (collective across ranks; `None` alone).
    fn rank_reports(&mut self) -> anyhow::Result<Option<Vec<RankReport>>> {
        Ok(None)
    }
    /// Whether `flag` is set on any rank (collective across ranks; alone, `flag`): decisions
    /// every rank must take together, such as stopping at a signal one rank saw first.
    fn any_rank(&mut self, flag: bool) -> anyhow::Result<bool> {
        Ok(flag)
    }
}

/// `state` without its particle arrays (left empty).
pub fn state_header(mut state: BackendState) -> BackendState {
    (state.positions, state.velocities, state.ids, state.warm_start, state.densities) = Default::default();
    state
}

/// One particle array of `state` in pieces of at most `chunk` particles, in order.
pub fn visit_state_pieces(state: &BackendState, array: StateArray, chunk: u64, visit: &mut dyn FnMut(StatePiece) -> anyhow::Result<()>) -> anyhow::Result<()> {
    let chunk = chunk.max(1) as usize;
    match array {
        StateArray::Positions => state.positions.chunks(chunk).try_for_each(|c| visit(StatePiece::Vectors(c))),
        StateArray::Velocities => state.velocities.chunks(chunk).try_for_each(|c| visit(StatePiece::Vectors(c))),
        StateArray::Ids => state.ids.chunks(chunk).try_for_each(|c| visit(StatePiece::Ids(c))),
        StateArray::WarmStart => state.warm_start.chunks(chunk).try_for_each(|c| visit(StatePiece::Pairs(c))),
        StateArray::Densities => state.densities.chunks(chunk).try_for_each(|c| visit(StatePiece::Scalars(c))),
    }
}

/// Why the run of `backend` (a run of `scene`) went bad: the diagnosis of its first bad step
/// ([`crate::model::diagnosis::diagnose`]), with what the state now shows: fluid particles
/// inside the scene's solids, and fluid torn under tension (read in pieces where the backend
/// streams its snapshots).
pub fn diagnose_failure(backend: &mut dyn Backend, scene: &Scene) -> anyhow::Result<String> {
    let health = backend.health()?;
    let mut found = FailureScan::new(scene);
    if backend.streams_snapshots() {
        backend.visit_snapshot_rows(&mut |_, rows| {
            for r in rows {
                found.add([r[0] as f64, r[1] as f64, r[2] as f64], r[6] as f64, r[7] as f64);
            }
            Ok(())
        })?;
    } else {
        let s = backend.snapshot()?;
        for ((&x, &density), &pressure) in s.positions.iter().zip(&s.densities).zip(&s.pressures) {
            found.add(x, density, pressure);
        }
    }
    Ok(diagnose(scene, &health, Some(&found)))
}
