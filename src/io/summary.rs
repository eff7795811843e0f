//! `DIR/summary.json`: what a run did and how it ended.

use crate::io::atomic::write_atomic;
use serde::Serialize;
use std::path::Path;

/// The summary's file in a run directory.
pub const SUMMARY_FILE: &str = "summary.json";

/// How a run ended.
#[derive(Clone, Copy, Debug, Default, Serialize, serde::Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum RunStatus {
    /// It reached its end.
    #[default]
    Completed,
    /// The state went bad (NaN, escaped particles); `failure` says why.
    Failed,
    /// It could not go on (an output could not be written, the device was lost); `failure`
    /// names the step and the file.
    Error,
    /// SIGINT (Ctrl-C) or SIGTERM stopped it; `failure` names the signal and the step.
    Interrupted,
}

/// `DIR/summary.json`.
#[derive(Clone, Debug, Serialize, serde::Deserialize, PartialEq)]
pub struct Summary {
    pub scene: String,
    pub backend: String,
    pub adapter: String,
    /// The GPU driver and its version (empty on the CPU path).
    #[serde(default)]
    pub driver: String,
    pub fluid_particles: usize,
    pub wall_particles: usize,
    pub steps: u64,
    pub sim_time: f64,
    pub dt: f64,
    /// Smallest, largest and mean step taken (all equal to `dt` without adaptive dt; 0 when the
    /// run took no step).
    #[serde(default)]
    pub dt_min: f64,
    #[serde(default)]
    pub dt_max: f64,
    #[serde(default)]
    pub dt_mean: f64,
    pub wall_seconds: f64,
    pub particle_steps_per_second: f64,
    pub max_density_ratio: f64,
    pub nan_count: u64,
    pub escaped: u64,
    /// Why the run stopped early, if it did.
    pub failure: Option<String>,
    pub last_snapshot: Option<String>,
    /// Pictures written (`--frames`).
    #[serde(default)]
    pub frames: u64,
    #[serde(default)]
    pub status: RunStatus,
    /// The checkpoint to continue from with `--resume`, when checkpoints are on.
    #[serde(default)]
    pub last_checkpoint: Option<String>,
    /// Snapshots written by this run (each in every format).
    #[serde(default)]
    pub snapshots: u64,
    /// Surface meshes written by this run (`surface/step_NNNNNN.obj` or `.ply`).
    #[serde(default)]
    pub surface_meshes: u64,
    /// DFSPH's iterations per step (absent for WCSPH).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dfsph: Option<DfsphSummary>,
    /// The largest speed of any step over the speed of sound (absent without a speed of
    /// sound: DFSPH).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_mach: Option<f64>,
    /// Where the run left the weakly compressible regime without stopping (`limits.warn_*`).
    #[serde(default)]
    pub warnings: Vec<String>,
    /// The names of the scene's probes, whose time series are in `probes/NAME.csv`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub probes: Vec<String>,
    /// A run across ranks: each rank's share (absent for a run in one process).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ranks: Option<RanksSummary>,
}

/// A run across ranks, for summary.json.
#[derive(Clone, Debug, Serialize, serde::Deserialize, PartialEq)]
pub struct RanksSummary {
    pub count: usize,
    /// The transport (the MPI library) in words.
    pub transport: String,
    /// The axis the slabs cut ("x", "y" or "z") and the slab bounds in cell layers at the end.
    pub slab_axis: String,
    pub slab_bounds: Vec<u32>,
    /// The largest rank's particle count over the mean, at the last balance check and the
    /// largest seen; how often the bounds moved.
    pub imbalance_last: f64,
    pub imbalance_max: f64,
    pub rebalances: u64,
    pub per_rank: Vec<RankSummary>,
}

/// One rank of a run across ranks.
#[derive(Clone, Debug, Serialize, serde::Deserialize, PartialEq)]
pub struct RankSummary {
    pub rank: usize,
    /// Fluid particles it owns at the end (ghosts left out), and the ghosts it holds.
    pub particles: usize,
    pub ghosts: usize,
    /// Wall particles it holds (those near its slab).
    #[serde(default)]
    pub walls: usize,
    /// Particles it sent to a neighbour over the run.
    pub migrated: u64,
    /// Seconds in the exchange and the collectives, and their share of the run's wall time.
    pub exchange_seconds: f64,
    pub exchange_share: f64,
    /// Where it ran: its place among the ranks of its machine, how many ran there, and the
    /// CPU threads it computed with.
    pub node_rank: usize,
    pub node_ranks: usize,
    pub threads: usize,
    /// The device it computed on: the CPU path's threads, or the GPU adapter and why this
    /// rank took it (by its place on its machine).
    #[serde(default)]
    pub adapter: String,
    /// On a GPU: the steps whose particles stayed on the device (only the band next to the
    /// faces crossed the bus), and the bytes of particles that crossed it, both ways.
    #[serde(default)]
    pub resident_steps: u64,
    #[serde(default)]
    pub bus_bytes: u64,
    /// On a GPU: seconds in the device's calls (uploads, steps, read-backs and the waits for
    /// them), the solves' exchanges inside them left out, and their share of the wall time.
    #[serde(default)]
    pub device_seconds: f64,
    #[serde(default)]
    pub device_share: f64,
}

impl RanksSummary {
    /// The summary of every rank's report, over a run of `wall_seconds`.
    pub fn of(reports: &[crate::solver::decomposition::RankReport], wall_seconds: f64) -> Self {
        let first = &reports[0];
        RanksSummary {
            count: first.ranks,
            transport: first.transport.clone(),
            slab_axis: ["x", "y", "z"][first.axis].to_string(),
            slab_bounds: first.bounds.clone(),
            imbalance_last: first.stats.last_imbalance,
            imbalance_max: first.stats.max_imbalance,
            rebalances: first.stats.rebalances,
            per_rank: reports
                .iter()
                .map(|r| RankSummary {
                    rank: r.rank,
                    particles: r.own_particles,
                    ghosts: r.stats.ghosts,
                    walls: r.walls,
                    migrated: r.stats.migrated,
                    exchange_seconds: r.stats.exchange_seconds,
                    exchange_share: if wall_seconds > 0.0 { r.stats.exchange_seconds / wall_seconds } else { 0.0 },
                    node_rank: r.node_rank,
                    node_ranks: r.node_ranks,
                    threads: r.threads,
                    adapter: r.adapter.clone(),
                    resident_steps: r.stats.resident_steps,
                    bus_bytes: r.stats.bus_bytes,
                    device_seconds: r.stats.device_seconds,
                    device_share: if wall_seconds > 0.0 { r.stats.device_seconds / wall_seconds } else { 0.0 },
                })
                .collect(),
        }
    }
}

/// DFSPH's solves over a run: iterations per step and how the last step ended.
#[derive(Clone, Debug, Serialize, serde::Deserialize, PartialEq)]
pub struct DfsphSummary {
    /// Mean and largest iterations per step of the constant-density (pressure) solve.
    pub pressure_iterations_mean: f64,
    pub pressure_iterations_max: u32,
    /// The same for the divergence solve (0 when it is switched off).
    pub divergence_iterations_mean: f64,
    pub divergence_iterations_max: u32,
    /// Average density error (a fraction of rho0) and divergence error at the end of the last
    /// step's solves.
    pub last_density_error: f64,
    pub last_divergence_error: f64,
    /// Steps whose solve stopped at its iteration limit with the error above the tolerance.
    pub unconverged_pressure_steps: u64,
    pub unconverged_divergence_steps: u64,
}

impl DfsphSummary {
    /// The summary of `stats` over `steps` steps.
    pub fn of(stats: &crate::model::state::IterationStats, steps: u64) -> Self {
        DfsphSummary {
            pressure_iterations_mean: stats.pressure.mean(steps),
            pressure_iterations_max: stats.pressure.max,
            divergence_iterations_mean: stats.divergence.mean(steps),
            divergence_iterations_max: stats.divergence.max,
            last_density_error: stats.pressure.last_error,
            last_divergence_error: stats.divergence.last_error,
            unconverged_pressure_steps: stats.pressure.unconverged,
            unconverged_divergence_steps: stats.divergence.unconverged,
        }
    }
}

pub fn write_summary(path: &Path, s: &Summary) -> anyhow::Result<()> {
    let json = serde_json::to_string_pretty(s)?;
    write_atomic(path, |w| writeln!(w, "{json}"))
}
