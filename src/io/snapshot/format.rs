//! The snapshot file formats and the file of a step's snapshot.

use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// A snapshot file format (`--format`).
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum SnapshotFormat {
    /// `x,y,z,vx,vy,vz,density,pressure`, one line per particle.
    Csv,
    /// Legacy binary VTK unstructured grid of vertex cells (ParaView, VisIt), with a
    /// `particles.vtk.series` index.
    Vtk,
    /// Binary little-endian PLY point cloud (Blender, splashsurf, MeshLab).
    Ply,
}

impl SnapshotFormat {
    pub fn extension(self) -> &'static str {
        match self {
            SnapshotFormat::Csv => "csv",
            SnapshotFormat::Vtk => "vtk",
            SnapshotFormat::Ply => "ply",
        }
    }
}

/// The subdirectory of a run directory that holds its snapshots, their index and VTK series.
pub const SNAPSHOTS_DIR: &str = "snapshots";

/// The file of a step's snapshot in a format: `DIR/snapshots/step_000123.vtk`.
pub fn snapshot_file(out: &Path, step: u64, format: SnapshotFormat) -> PathBuf {
    out.join(SNAPSHOTS_DIR).join(format!("step_{step:06}.{}", format.extension()))
}

/// The step of a snapshot file name `step_000123.ext`.
pub fn step_of_name(name: &str) -> Option<u64> {
    name.strip_prefix("step_")?.split('.').next()?.parse().ok()
}

