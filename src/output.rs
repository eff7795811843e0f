//! Output files, always written atomically: to a temporary file beside the target, then renamed,
//! so a reader never sees a half-written file and an interrupted run leaves the old one intact.

use crate::sim::Snapshot;
use anyhow::Context;
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Writes `path` atomically with the bytes `write` produces.
pub fn write_atomic(path: &Path, write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>) -> anyhow::Result<()> {
    let mut file = AtomicFile::create(path)?;
    write(&mut file).with_context(|| format!("cannot write {}", path.display()))?;
    file.commit()
}

/// A file written atomically: the bytes go (buffered) to a temporary file beside `path`, which
/// [`AtomicFile::commit`] renames over it; dropped without a commit, the temporary file is
/// removed and `path` is left as it was. Unlike [`write_atomic`] it can seek (files whose
/// sections are written out of order) and several can be open at once.
pub struct AtomicFile {
    path: PathBuf,
    out: std::io::BufWriter<tempfile::NamedTempFile>,
}

impl AtomicFile {
    pub fn create(path: &Path) -> anyhow::Result<Self> {
        let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create directory {}", dir.display()))?;
        let mut builder = tempfile::Builder::new();
        // Temporary files are private (0600) by default; an output file gets the permissions any
        // new file would (0666 less the umask).
        #[cfg(unix)]
        builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
        let tmp = builder.tempfile_in(dir).with_context(|| format!("cannot create a file in {}", dir.display()))?;
        Ok(AtomicFile { path: path.to_path_buf(), out: std::io::BufWriter::new(tmp) })
    }

    /// The file this one replaces once committed.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Flushes the bytes and renames the temporary file over the target.
    pub fn commit(self) -> anyhow::Result<()> {
        let path = self.path;
        let tmp = self.out.into_inner().map_err(|e| e.into_error()).with_context(|| format!("cannot write {}", path.display()))?;
        tmp.as_file().sync_all().ok();
        tmp.persist(&path).with_context(|| format!("cannot move the finished file to {}", path.display()))?;
        Ok(())
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.out.write(buf)
    }
    fn write_all(&mut self, buf: &[u8]) -> std::io::Result<()> {
        self.out.write_all(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }
}

impl std::io::Seek for AtomicFile {
    fn seek(&mut self, pos: std::io::SeekFrom) -> std::io::Result<u64> {
        self.out.seek(pos)
    }
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
