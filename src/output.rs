//! Output files, always written atomically: to a temporary file beside the target, then renamed,
//! so a reader never sees a half-written file and an interrupted run leaves the old one intact.

use crate::sim::Snapshot;
use anyhow::Context;
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Writes `path` atomically with the bytes `write` produces.
pub fn write_atomic(path: &Path, write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>) -> anyhow::Result<()> {
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create directory {}", dir.display()))?;
    let mut tmp = tempfile::NamedTempFile::new_in(dir).with_context(|| format!("cannot create a file in {}", dir.display()))?;
    {
        let mut buf = std::io::BufWriter::new(tmp.as_file_mut());
        write(&mut buf).with_context(|| format!("cannot write {}", path.display()))?;
        buf.flush().with_context(|| format!("cannot write {}", path.display()))?;
    }
    tmp.as_file().sync_all().ok();
    tmp.persist(path).with_context(|| format!("cannot move the finished file to {}", path.display()))?;
    Ok(())
}

/// The snapshot file of a step: `DIR/snapshots/step_000123.csv`.
pub fn snapshot_path(out: &Path, step: u64) -> PathBuf {
    out.join("snapshots").join(format!("step_{step:06}.csv"))
}

pub const SNAPSHOT_HEADER: &str = "x,y,z,vx,vy,vz,density,pressure";

/// Writes the fluid particles as CSV. Refuses a snapshot holding NaN or infinity, so a blown-up
/// state never reaches a file silently.
pub fn write_snapshot_csv(path: &Path, s: &Snapshot) -> anyhow::Result<()> {
    let bad = s.non_finite_count();
    if bad > 0 {
        anyhow::bail!("refusing to write {}: {bad} particles hold NaN or infinity at step {}", path.display(), s.step);
    }
    write_atomic(path, |w| {
        writeln!(w, "{SNAPSHOT_HEADER}")?;
        for i in 0..s.len() {
            let p = s.positions[i];
            let v = s.velocities[i];
            write_snapshot_row(w, &[p[0], p[1], p[2], v[0], v[1], v[2], s.densities[i], s.pressures[i]])?;
        }
        Ok(())
    })
}

/// One particle's line of a snapshot CSV: the values of `SNAPSHOT_HEADER` (also what the
/// streamed GPU writer uses, so both write the same bytes).
pub fn write_snapshot_row(w: &mut dyn Write, v: &[f64; 8]) -> std::io::Result<()> {
    writeln!(w, "{},{},{},{},{},{},{},{}", v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7])
}

/// Reads a snapshot CSV written by `write_snapshot_csv`.
pub fn read_snapshot_csv(path: &Path) -> anyhow::Result<Snapshot> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut lines = text.lines();
    anyhow::ensure!(lines.next() == Some(SNAPSHOT_HEADER), "{}: the header is not {SNAPSHOT_HEADER}", path.display());
    let mut s = Snapshot::default();
    for (n, line) in lines.enumerate() {
        let v: Vec<f64> = line
            .split(',')
            .map(|f| f.parse::<f64>())
            .collect::<Result<_, _>>()
            .with_context(|| format!("{}: line {}", path.display(), n + 2))?;
        anyhow::ensure!(v.len() == 8, "{}: line {} has {} fields, expected 8", path.display(), n + 2, v.len());
        s.positions.push([v[0], v[1], v[2]]);
        s.velocities.push([v[3], v[4], v[5]]);
        s.densities.push(v[6]);
        s.pressures.push(v[7]);
    }
    Ok(s)
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
}

pub fn write_summary(path: &Path, s: &Summary) -> anyhow::Result<()> {
    let json = serde_json::to_string_pretty(s)?;
    write_atomic(path, |w| writeln!(w, "{json}"))
}
