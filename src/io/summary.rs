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
    pub fluid_particles: usize,
    pub wall_particles: usize,
    pub steps: u64,
    pub sim_time: f64,
    pub dt: f64,
    /// Smallest, largest and mean step taken (all equal to `dt` without adaptive dt).
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
}

pub fn write_summary(path: &Path, s: &Summary) -> anyhow::Result<()> {
    let json = serde_json::to_string_pretty(s)?;
    write_atomic(path, |w| writeln!(w, "{json}"))
}
