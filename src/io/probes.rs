//! `DIR/probes/NAME.csv`: one time series per probe, a header line first, then one line per
//! sample: `time_s,step,` and the probe's columns in SI units. Each file is rewritten
//! atomically after every batch of steps that sampled it, like the snapshot index, so a reader
//! never sees half a line; a resumed run keeps the lines of the steps before its checkpoint and
//! computes the later ones again, so no line is lost or written twice.

use super::atomic::write_atomic;
use super::rundir::PROBES_DIR;
use crate::model::probes::{Probe, ProbeSample, Probes};
use anyhow::Context;
use std::path::{Path, PathBuf};

/// One probe's file and its lines.
struct ProbeFile {
    path: PathBuf,
    header: String,
    /// The step, time and values of each line, in step order.
    rows: Vec<(u64, f64, Vec<f64>)>,
    changed: bool,
}

/// The time series of every probe of a run.
pub struct ProbeWriter {
    probes: Vec<Probe>,
    offsets: Vec<usize>,
    files: Vec<ProbeFile>,
}

/// The path of a probe's time series in run directory `out`.
pub fn probe_csv(out: &Path, name: &str) -> PathBuf {
    out.join(PROBES_DIR).join(format!("{name}.csv"))
}

impl ProbeWriter {
    /// The writer of a new run into `out` (nothing is written before the first sample).
    pub fn new(out: &Path, probes: &Probes) -> Self {
        let files = probes
            .probes
            .iter()
            .map(|p| ProbeFile { path: probe_csv(out, &p.name), header: header(p), rows: Vec::new(), changed: true })
            .collect();
        ProbeWriter { probes: probes.probes.clone(), offsets: probes.offsets(), files }
    }

    /// The writer of a run resumed at step `first_step`: the lines an earlier run wrote for the
    /// steps before it are kept, later ones dropped (they are sampled again). A file with
    /// another header (another scene) is started afresh.
    pub fn resume(out: &Path, probes: &Probes, first_step: u64) -> anyhow::Result<Self> {
        let mut w = ProbeWriter::new(out, probes);
        for f in &mut w.files {
            let text = match std::fs::read_to_string(&f.path) {
                Ok(t) => t,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
                Err(e) => return Err(e).with_context(|| format!("cannot read {}", f.path.display())),
            };
            let mut lines = text.lines();
            if lines.next() != Some(f.header.as_str()) {
                continue;
            }
            for (n, line) in lines.enumerate() {
                let bad = || anyhow::anyhow!("{}: line {} is not a probe sample: '{line}'", f.path.display(), n + 2);
                let fields: Vec<&str> = line.split(',').collect();
                let time: f64 = fields.first().and_then(|s| s.parse().ok()).ok_or_else(bad)?;
                let step: u64 = fields.get(1).and_then(|s| s.parse().ok()).ok_or_else(bad)?;
                let values: Vec<f64> = fields[2..].iter().map(|s| s.parse().map_err(|_| bad())).collect::<anyhow::Result<_>>()?;
                if step < first_step {
                    f.rows.push((step, time, values));
                }
            }
        }
        Ok(w)
    }

    /// Adds the samples to the series of the probes due at each (a sample holds every probe;
    /// a probe keeps only those at its own interval).
    pub fn add(&mut self, samples: &[ProbeSample]) {
        for s in samples {
            for ((probe, &at), f) in self.probes.iter().zip(&self.offsets).zip(&mut self.files) {
                if !probe.due(s.step, s.time, s.previous_time) {
                    continue;
                }
                let n = probe.geometry.columns().len();
                // A step sampled again (after a restore) replaces its line.
                while f.rows.last().is_some_and(|r| r.0 >= s.step) {
                    f.rows.pop();
                }
                f.rows.push((s.step, s.time, s.values[at..at + n].to_vec()));
                f.changed = true;
            }
        }
    }

    /// Rewrites the files that changed since they were last written.
    pub fn write(&mut self) -> anyhow::Result<()> {
        for f in self.files.iter_mut().filter(|f| f.changed) {
            write_atomic(&f.path, |w| {
                writeln!(w, "{}", f.header)?;
                for (step, time, values) in &f.rows {
                    // `{}` writes the shortest text that reads back as the same number; a value
                    // that is not finite (a state gone bad) is written as such, never dropped.
                    write!(w, "{},{step}", number(*time))?;
                    for v in values {
                        write!(w, ",{}", number(*v))?;
                    }
                    writeln!(w)?;
                }
                Ok(())
            })?;
            f.changed = false;
        }
        Ok(())
    }

    /// Each probe, its file and its series (time, values) so far.
    pub fn series(&self) -> Vec<(&Probe, &Path, Vec<(f64, &[f64])>)> {
        self.probes
            .iter()
            .zip(&self.files)
            .map(|(p, f)| (p, f.path.as_path(), f.rows.iter().map(|r| (r.1, r.2.as_slice())).collect()))
            .collect()
    }
}

/// A number as the shortest text that reads back as the same f64: plain between 1e-4 and
/// 1e7, in scientific notation beyond (Rust's `{}` never uses an exponent).
/// A value the GPU computed (exactly an f32) is written as the shortest text of that f32.
fn number(v: f64) -> String {
    let plain = v == 0.0 || !v.is_finite() || (1e-4..1e7).contains(&v.abs());
    let single = v as f32;
    match (single as f64 == v, plain) {
        (true, true) => format!("{single}"),
        (true, false) => format!("{single:e}"),
        (false, true) => format!("{v}"),
        (false, false) => format!("{v:e}"),
    }
}

/// A probe's header line: `time_s,step` and its columns.
fn header(p: &Probe) -> String {
    let mut h = String::from("time_s,step");
    for c in p.geometry.columns() {
        h.push(',');
        h.push_str(c);
    }
    h
}
