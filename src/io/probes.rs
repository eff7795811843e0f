//! `DIR/probes/NAME.csv`: one time series per probe, a header line first, then one line per
//! sample: `time_s,step,` and the probe's columns in SI units. A file is first written
//! atomically (header and lines), then the lines of every later batch of steps are appended with
//! one write: rewriting a series after every batch made a long run's writing grow with the
//! square of its samples (measured: 0.1-0.5 ms per probe and step on a GPU, more than the step).
//! An append that fails is cut back to the lines before it; a run killed during one can leave
//! part of a line at the end, which a resumed run drops; a resumed run keeps the lines of the steps before its checkpoint (rewriting the file
//! once) and computes the later ones again, so no line is lost or written twice.

use super::atomic::write_atomic;
use super::rundir::{RunDirError, PROBES_DIR};
use crate::model::probes::{Probe, ProbeSample, Probes};
use anyhow::Context;
use std::io::Write;
use std::path::{Path, PathBuf};

/// One probe's file and its lines.
struct ProbeFile {
    path: PathBuf,
    header: String,
    /// The step, time and values of each line, in step order.
    rows: Vec<(u64, f64, Vec<f64>)>,
    /// How many of `rows` the file on disk holds.
    written: usize,
    /// Whether the file must be written whole (new, resumed, or lines on disk replaced).
    rewrite: bool,
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
            .map(|p| ProbeFile { path: probe_csv(out, &p.name), header: header(p), rows: Vec::new(), written: 0, rewrite: true })
            .collect();
        ProbeWriter { probes: probes.probes.clone(), offsets: probes.offsets(), files }
    }

    /// The writer of a run resumed at step `first_step`: the lines an earlier run wrote for the
    /// steps before it are kept, later ones dropped (they are sampled again), and so is the part
    /// of a line that a run stopped while appending it left at the end. The second value names
    /// the series whose file is missing (or empty): they restart at `first_step`, and the run
    /// says so. A file that does not start with its probe's header, or holds a line that is not
    /// a sample, is not the run's series: it is refused (a [`RunDirError`]), never replaced.
    pub fn resume(out: &Path, probes: &Probes, first_step: u64) -> anyhow::Result<(Self, Vec<PathBuf>)> {
        let mut w = ProbeWriter::new(out, probes);
        let mut missing = Vec::new();
        let refuse = |path: &Path, why: String| -> anyhow::Error {
            RunDirError(format!(
                "--resume: {}: {why}; it is not this run's series, and resuming would replace it: move it away (the series then restarts at step {first_step})",
                path.display()
            ))
            .into()
        };
        for f in &mut w.files {
            let text = match std::fs::read_to_string(&f.path) {
                Ok(t) if t.is_empty() => {
                    missing.push(f.path.clone());
                    continue;
                }
                Ok(t) => t,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                    missing.push(f.path.clone());
                    continue;
                }
                Err(e) if e.kind() == std::io::ErrorKind::InvalidData => return Err(refuse(&f.path, "is not UTF-8 text".into())),
                Err(e) => return Err(refuse(&f.path, format!("cannot be read as the probe's series ({e})"))),
            };
            // Whole lines only: what follows the last newline was being appended when the run stopped.
            let whole = &text[..text.rfind('\n').map_or(0, |i| i + 1)];
            let mut lines = whole.lines();
            let first = lines.next().unwrap_or("");
            if first != f.header {
                return Err(refuse(&f.path, format!("its first line is '{}', where the probe's header is '{}'", clip(first), f.header)));
            }
            for (n, line) in lines.enumerate() {
                let bad = || refuse(&f.path, format!("line {} is not a sample of the probe: '{}'", n + 2, clip(line)));
                let fields: Vec<&str> = line.split(',').collect();
                // A run writes finite numbers only: a NaN or infinity is not its line.
                let number = |s: &&str| s.parse::<f64>().ok().filter(|v| v.is_finite());
                let time: f64 = fields.first().and_then(number).ok_or_else(bad)?;
                let step: u64 = fields.get(1).and_then(|s| s.parse().ok()).ok_or_else(bad)?;
                let values: Vec<f64> = fields[2..].iter().map(|s| number(s).ok_or_else(bad)).collect::<anyhow::Result<_>>()?;
                if values.len() != f.header.split(',').count() - 2 {
                    return Err(bad());
                }
                if step < first_step {
                    f.rows.push((step, time, values));
                }
            }
        }
        Ok((w, missing))
    }

    /// Each series' lines (samples) before `step`, named by the file's path in the run
    /// directory: what a run resumed at `step` keeps of them.
    pub fn lines_before(&self, step: u64) -> Vec<(String, u64)> {
        self.probes.iter().zip(&self.files).map(|(p, f)| (format!("{PROBES_DIR}/{}.csv", p.name), f.rows.iter().filter(|r| r.0 < step).count() as u64)).collect()
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
                // A step sampled again (after a restore) replaces its line; one already on disk
                // makes the file be written whole.
                while f.rows.last().is_some_and(|r| r.0 >= s.step) {
                    f.rows.pop();
                }
                if f.rows.len() < f.written {
                    f.written = f.rows.len();
                    f.rewrite = true;
                }
                f.rows.push((s.step, s.time, s.values[at..at + n].to_vec()));
            }
        }
    }

    /// Brings the files up to date: a file written for the first time (or after its lines on
    /// disk changed) is written whole and atomically; otherwise the new lines are appended.
    pub fn write(&mut self) -> anyhow::Result<()> {
        for f in &mut self.files {
            if !f.rewrite && f.written == f.rows.len() {
                continue;
            }
            if !f.rewrite {
                let mut text = Vec::new();
                for row in &f.rows[f.written..] {
                    write_line(&mut text, row)?;
                }
                match std::fs::OpenOptions::new().append(true).open(&f.path) {
                    // One write of whole lines; one that fails part way (a full disk) is cut back
                    // to the lines before it, so that the file never ends in part of a line.
                    Ok(mut file) => {
                        let before = file.metadata().with_context(|| format!("cannot write {}", f.path.display()))?.len();
                        if let Err(e) = file.write_all(&text) {
                            let _ = file.set_len(before);
                            return Err(e).with_context(|| format!("cannot write {}", f.path.display()));
                        }
                    }
                    // Removed while the run went on: written whole again below.
                    Err(e) if e.kind() == std::io::ErrorKind::NotFound => f.rewrite = true,
                    Err(e) => return Err(e).with_context(|| format!("cannot write {}", f.path.display())),
                }
            }
            if f.rewrite {
                write_atomic(&f.path, |w| {
                    writeln!(w, "{}", f.header)?;
                    f.rows.iter().try_for_each(|row| write_line(w, row))
                })?;
                f.rewrite = false;
            }
            f.written = f.rows.len();
        }
        Ok(())
    }

    /// Each probe, its file and its series (time, values) so far, each number as its file
    /// holds it: a resumed run reads the lines before its checkpoint back from that text, so a
    /// plot drawn from these values is the same picture whether the run was interrupted or not
    /// (a value computed in f32 is written as the shortest text of that f32, which reads back
    /// as a nearby f64, not the f32 itself).
    pub fn series(&self) -> Vec<(&Probe, &Path, Vec<(f64, Vec<f64>)>)> {
        self.probes
            .iter()
            .zip(&self.files)
            .map(|(p, f)| (p, f.path.as_path(), f.rows.iter().map(|r| (as_written(r.1), r.2.iter().map(|&v| as_written(v)).collect())).collect()))
            .collect()
    }
}

/// At most 80 characters of a line, for a message.
fn clip(line: &str) -> String {
    match line.char_indices().nth(80) {
        Some((i, _)) => format!("{}...", &line[..i]),
        None => line.to_string(),
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

/// `v` as a series line holds it: its text read back. Reading back what was read is the same
/// number again, so a value taken from a file and one just computed agree.
fn as_written(v: f64) -> f64 {
    number(v).parse().unwrap_or(v)
}

/// One line of a series: time, step and values. `{}` writes the shortest text that reads back
/// as the same number; a value that is not finite (a state gone bad) is written as such, never
/// dropped.
fn write_line(w: &mut dyn Write, (step, time, values): &(u64, f64, Vec<f64>)) -> std::io::Result<()> {
    write!(w, "{},{step}", number(*time))?;
    for v in values {
        write!(w, ",{}", number(*v))?;
    }
    writeln!(w)
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::probes::{ProbeGeometry, ProbeInterval};

    fn writer(out: &Path) -> ProbeWriter {
        let probe = |name: &str, every| Probe { name: name.into(), interval: ProbeInterval::Steps(every), geometry: ProbeGeometry::Point { position: [0.0; 3] } };
        ProbeWriter::new(out, &Probes { probes: vec![probe("every", 1), probe("second", 2)] })
    }

    fn samples(steps: std::ops::Range<u64>, offset: f64) -> Vec<ProbeSample> {
        steps.map(|s| ProbeSample { step: s, time: 0.1 * s as f64, previous_time: 0.1 * s.saturating_sub(1) as f64, values: (0..12).map(|k| offset + s as f64 + 0.25 * k as f64).collect() }).collect()
    }

    fn files(out: &Path) -> Vec<String> {
        ["every", "second"].iter().map(|n| std::fs::read_to_string(probe_csv(out, n)).unwrap()).collect()
    }

    /// The series written in batches (appended) is the text written at once; a line replaced on
    /// disk or a file removed during the run makes the file be written whole again.
    #[test]
    fn appended_series_match_the_series_written_whole() {
        let dir = tempfile::tempdir().unwrap();
        let (whole, batches) = (dir.path().join("whole"), dir.path().join("batches"));
        let mut w = writer(&whole);
        w.add(&samples(0..30, 0.0));
        w.write().unwrap();
        let expected = files(&whole);
        assert_eq!(expected[0].lines().count(), 31);
        assert_eq!(expected[1].lines().count(), 16);

        let mut b = writer(&batches);
        for range in [0..7, 7..8, 8..8, 8..30] {
            b.add(&samples(range, 0.0));
            b.write().unwrap();
        }
        assert_eq!(files(&batches), expected);

        // Removed while the run goes on: written whole with the next batch.
        std::fs::remove_file(probe_csv(&batches, "every")).unwrap();
        b.add(&samples(30..32, 0.0));
        b.write().unwrap();
        w.add(&samples(30..32, 0.0));
        w.write().unwrap();
        assert_eq!(files(&batches), files(&whole));

        // Steps sampled again (after a restore) with other values replace their lines on disk.
        for x in [&mut w, &mut b] {
            x.add(&samples(28..32, 100.0));
            x.write().unwrap();
        }
        let replaced = files(&batches);
        assert_eq!(replaced, files(&whole));
        assert_eq!(replaced[0].lines().count(), 33);
        assert!(replaced[0].lines().nth(29).unwrap().contains(",128,"), "{}", replaced[0]);
    }

    /// A run stopped while appending leaves part of a line; a resumed run drops it with the
    /// lines of the steps it samples again.
    #[test]
    fn a_resumed_series_drops_a_partly_written_last_line() {
        let dir = tempfile::tempdir().unwrap();
        let mut w = writer(dir.path());
        w.add(&samples(0..10, 0.0));
        w.write().unwrap();
        let path = probe_csv(dir.path(), "every");
        let before = std::fs::read_to_string(&path).unwrap();
        // Step 10's line cut within its step: read whole, it would pass for a line of step 1.
        std::fs::write(&path, format!("{before}1.0,1")).unwrap();
        let (mut r, missing) = ProbeWriter::resume(dir.path(), &Probes { probes: w.probes.clone() }, 6).unwrap();
        assert!(missing.is_empty());
        r.add(&samples(6..10, 0.0));
        r.write().unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), before);
    }

    /// A resumed writer's series, its early lines read back from the file, holds the numbers of
    /// the writer that never stopped, for values computed in f32 (written as an f32's shortest
    /// text) and in f64 alike: the plots drawn from them are the same picture.
    #[test]
    fn a_resumed_series_holds_the_uninterrupted_series_numbers() {
        let f32_samples = |steps: std::ops::Range<u64>| -> Vec<ProbeSample> {
            samples(steps, 0.0)
                .into_iter()
                .map(|mut s| {
                    // 0.1 + k / 3 in f32: neither f32 nor its text is an exact decimal.
                    s.values = (0..12).map(|k| (0.1f32 + (s.step as f32 + k as f32) / 3.0) as f64).collect();
                    s
                })
                .collect()
        };
        let f64_samples = |steps: std::ops::Range<u64>| -> Vec<ProbeSample> { samples(steps, 1.0 / 7.0) };
        for (how, make) in [("f32", &f32_samples as &dyn Fn(std::ops::Range<u64>) -> Vec<ProbeSample>), ("f64", &f64_samples)] {
            let dir = tempfile::tempdir().unwrap();
            let (whole, cut) = (dir.path().join("whole"), dir.path().join("cut"));
            let mut w = writer(&whole);
            w.add(&make(0..20));
            w.write().unwrap();
            let mut c = writer(&cut);
            c.add(&make(0..12));
            c.write().unwrap();
            let (mut r, missing) = ProbeWriter::resume(&cut, &Probes { probes: w.probes.clone() }, 8).unwrap();
            assert!(missing.is_empty());
            r.add(&make(8..20));
            r.write().unwrap();
            assert_eq!(files(&cut), files(&whole), "{how}");
            let numbers = |x: &ProbeWriter| -> Vec<Vec<(u64, Vec<u64>)>> {
                x.series().into_iter().map(|(_, _, s)| s.iter().map(|(t, v)| (t.to_bits(), v.iter().map(|x| x.to_bits()).collect())).collect()).collect()
            };
            assert_eq!(numbers(&r), numbers(&w), "{how}: the series' numbers differ after the resume");
            // Read back twice is read back once: the numbers are the file's own.
            for (_, _, s) in w.series() {
                assert!(s.iter().all(|(t, v)| as_written(*t) == *t && v.iter().all(|&x| as_written(x) == x)), "{how}");
            }
        }
        // An f32 is not its text read as f64 (what the plot of a resumed run once drew).
        let x = (0.1f32 + 1.0 / 3.0) as f64;
        assert_ne!(as_written(x), x);
    }

    /// A series that is gone restarts (and is named, for the run to say so); a file that is not
    /// the probe's series, by its header or by a line, is refused and left as it was.
    #[test]
    fn a_resumed_series_names_a_missing_file_and_refuses_a_foreign_one() {
        let dir = tempfile::tempdir().unwrap();
        let mut w = writer(dir.path());
        w.add(&samples(0..10, 0.0));
        w.write().unwrap();
        let probes = Probes { probes: w.probes.clone() };
        let (every, second) = (probe_csv(dir.path(), "every"), probe_csv(dir.path(), "second"));
        std::fs::remove_file(&second).unwrap();
        let (_, missing) = ProbeWriter::resume(dir.path(), &probes, 6).unwrap();
        assert_eq!(missing, vec![second.clone()]);

        let kept = std::fs::read_to_string(&every).unwrap();
        let header = kept.lines().next().unwrap().to_string();
        let not_finite = [format!("{header}\nNaN,1,1,2,3,4,5,6\n"), format!("{header}\n0.1,1,1,inf,3,4,5,6\n")];
        for foreign in ["my notes\n".to_string(), format!("{header}\n0,0,1,2\n"), format!("{header}\n0.1,x,1,2,3,4,5,6\n")].into_iter().chain(not_finite) {
            std::fs::write(&every, &foreign).unwrap();
            let e = ProbeWriter::resume(dir.path(), &probes, 6).err().expect("a foreign file is refused");
            assert!(e.downcast_ref::<RunDirError>().is_some(), "{e:#}");
            assert!(e.to_string().contains("every.csv") && e.to_string().contains("move it away"), "{e:#}");
            assert_eq!(std::fs::read_to_string(&every).unwrap(), foreign);
        }
    }
}
