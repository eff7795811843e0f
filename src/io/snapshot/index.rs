//! `DIR/snapshots/index.csv`: one line per snapshot with its step, its simulated time and its
//! file in each format, so that a CSV reader finds each snapshot's time (with adaptive dt the
//! step alone does not tell it) while every snapshot keeps its header as its first line. It is
//! rewritten atomically after every snapshot, like the VTK series index.

use super::format::SnapshotFormat;
use crate::io::atomic::write_atomic;
use anyhow::Context;
use std::path::Path;

/// The index's file name in `snapshots/`.
pub const INDEX_NAME: &str = "index.csv";

/// The rows of the index: step, time, and a file name per format.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SnapshotIndex {
    formats: Vec<SnapshotFormat>,
    rows: Vec<(u64, f64, Vec<String>)>,
}

impl SnapshotIndex {
    pub fn new(formats: &[SnapshotFormat]) -> Self {
        SnapshotIndex { formats: formats.to_vec(), rows: Vec::new() }
    }

    /// The header line: `step,time,` and the formats' extensions.
    pub fn header(&self) -> String {
        let mut h = String::from("step,time");
        for f in &self.formats {
            h.push(',');
            h.push_str(f.extension());
        }
        h
    }

    /// The index of an earlier run up to `last_step` (a resumed run goes on from there). A
    /// missing file gives an empty index; what follows its last line break (a line being
    /// written when the run stopped) is dropped. A file that does not start with this run's
    /// header, or holds a line that is not a snapshot's, is not the run's index: an error (the
    /// caller refuses to resume, and leaves it as it is).
    pub fn read_up_to(path: &Path, formats: &[SnapshotFormat], last_step: u64) -> anyhow::Result<Self> {
        let mut index = SnapshotIndex::new(formats);
        let text = match std::fs::read_to_string(path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(index),
            Err(e) => return Err(e).with_context(|| format!("cannot read {}", path.display())),
        };
        let whole = &text[..text.rfind('\n').map_or(0, |i| i + 1)];
        let mut lines = whole.lines();
        let header = index.header();
        match lines.next() {
            None => return Ok(index),
            Some(first) if first == header => {}
            Some(first) => anyhow::bail!(
                "{}: its first line is '{}', where this run's index starts '{header}': it is not the run's index, and resuming would replace it; move it away (the index then restarts at the checkpoint)",
                path.display(),
                first.chars().take(80).collect::<String>()
            ),
        }
        for (n, line) in lines.enumerate() {
            let bad = || anyhow::anyhow!("{}: line {} is not step,time,files: '{}'; move the file away to resume (the index then restarts at the checkpoint)", path.display(), n + 2, line.chars().take(80).collect::<String>());
            let mut fields = line.split(',');
            let step: u64 = fields.next().and_then(|s| s.parse().ok()).ok_or_else(bad)?;
            let time: f64 = fields.next().and_then(|s| s.parse().ok()).filter(|t: &f64| t.is_finite()).ok_or_else(bad)?;
            let files: Vec<String> = fields.map(str::to_string).collect();
            if files.len() != formats.len() {
                return Err(bad());
            }
            if step <= last_step {
                index.rows.push((step, time, files));
            }
        }
        Ok(index)
    }

    /// Adds a snapshot (its files' names, in the order of the formats) and rewrites the index.
    pub fn add_and_write(&mut self, path: &Path, step: u64, time: f64, files: Vec<String>) -> anyhow::Result<()> {
        self.rows.retain(|r| r.0 != step);
        self.rows.push((step, time, files));
        let header = self.header();
        write_atomic(path, |w| {
            writeln!(w, "{header}")?;
            for (step, time, files) in &self.rows {
                // `{}` writes the shortest text that reads back as the same f64.
                writeln!(w, "{step},{time},{}", files.join(","))?;
            }
            Ok(())
        })
    }

    pub fn rows(&self) -> &[(u64, f64, Vec<String>)] {
        &self.rows
    }
}
