//! The project's own snapshot format: `x,y,z,vx,vy,vz,density,pressure`, one line per
//! particle in original order.

use crate::io::atomic::write_atomic;
use crate::model::state::Snapshot;
use anyhow::Context;
use std::io::Write;
use std::path::Path;

pub const SNAPSHOT_HEADER: &str = "x,y,z,vx,vy,vz,density,pressure";

/// Writes the fluid particles as CSV. Refuses a snapshot holding NaN or infinity, so a blown-up
/// state never reaches a file silently.
pub fn write_snapshot_csv(path: &Path, s: &Snapshot) -> anyhow::Result<()> {
    refuse_non_finite(path, s)?;
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

/// Refuses a snapshot holding NaN or infinity, so that a blown-up state never reaches a file
/// silently (the rule of every snapshot writer).
pub fn refuse_non_finite(path: &Path, s: &Snapshot) -> anyhow::Result<()> {
    let bad = s.non_finite_count();
    if bad > 0 {
        anyhow::bail!("refusing to write {}: {bad} particles hold NaN or infinity at step {}", path.display(), s.step);
    }
    Ok(())
}
