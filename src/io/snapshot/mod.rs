//! Snapshot files for other programs: the project's CSV, legacy VTK for ParaView (with a
//! `.vtk.series` index so a run opens as an animation) and binary PLY for Blender and
//! splashsurf. Every file is written atomically (see [`crate::io::atomic`]) and a snapshot
//! holding NaN or infinity is refused.

pub mod csv;
pub mod format;
pub mod index;
pub mod pieces;
pub mod ply;
pub mod stream;
pub mod vtk;

use crate::model::state::{Snapshot, SnapshotExtremes};
use crate::solver::{Backend, SnapshotRow};
use format::{snapshot_file, SnapshotFormat, SNAPSHOTS_DIR};
use index::{SnapshotIndex, INDEX_NAME};
use std::path::{Path, PathBuf};
use stream::SnapshotStream;
use vtk::{FileSeries, VTK_SERIES_NAME};

/// Writes a snapshot in one format.
pub fn write_snapshot(path: &Path, format: SnapshotFormat, s: &Snapshot) -> anyhow::Result<()> {
    match format {
        SnapshotFormat::Csv => csv::write_snapshot_csv(path, s),
        SnapshotFormat::Vtk => vtk::write_vtk(path, s),
        SnapshotFormat::Ply => ply::write_ply(path, s),
    }
}


/// Writes every snapshot file a run asked for, and keeps the VTK series index up to date.
pub struct SnapshotWriter {
    out: PathBuf,
    formats: Vec<SnapshotFormat>,
    series: FileSeries,
    index: SnapshotIndex,
}

impl SnapshotWriter {
    /// Formats are de-duplicated, in the order given.
    pub fn new(out: &Path, formats: &[SnapshotFormat]) -> Self {
        let mut fs: Vec<SnapshotFormat> = Vec::new();
        for &f in formats {
            if !fs.contains(&f) {
                fs.push(f);
            }
        }
        let index = SnapshotIndex::new(&fs);
        SnapshotWriter { out: out.to_path_buf(), formats: fs, series: FileSeries::default(), index }
    }

    /// A writer continuing a run that stopped after `last_step`: the series index keeps the
    /// snapshots written up to it.
    pub fn resume(out: &Path, formats: &[SnapshotFormat], last_step: u64) -> anyhow::Result<Self> {
        let mut w = SnapshotWriter::new(out, formats);
        let index = w.series_path();
        if w.formats.contains(&SnapshotFormat::Vtk) && index.exists() {
            // Not the run's own index: what is in the directory is in the way (bad input), and
            // is left as it is.
            w.series = FileSeries::read_up_to(&index, last_step).map_err(|e| crate::io::rundir::RunDirError(format!("{e:#}")))?;
        }
        w.index = SnapshotIndex::read_up_to(&w.index_path(), &w.formats, last_step).map_err(|e| crate::io::rundir::RunDirError(format!("{e:#}")))?;
        Ok(w)
    }

    pub fn series_path(&self) -> PathBuf {
        self.out.join(SNAPSHOTS_DIR).join(VTK_SERIES_NAME)
    }

    /// `DIR/snapshots/index.csv`: each snapshot's step, time and files.
    pub fn index_path(&self) -> PathBuf {
        self.out.join(SNAPSHOTS_DIR).join(INDEX_NAME)
    }

    /// The snapshots up to `step` in the index and in the VTK series, named by the file's path
    /// in the run directory: what a run resumed at `step` keeps of them.
    pub fn lines_up_to(&self, step: u64) -> Vec<(String, u64)> {
        let mut lines = vec![(format!("{SNAPSHOTS_DIR}/{INDEX_NAME}"), self.index.rows().iter().filter(|r| r.0 <= step).count() as u64)];
        if self.formats.contains(&SnapshotFormat::Vtk) {
            let kept = self.series.files.iter().filter(|e| format::step_of_name(&e.name).is_some_and(|s| s <= step)).count();
            lines.push((format!("{SNAPSHOTS_DIR}/{VTK_SERIES_NAME}"), kept as u64));
        }
        lines
    }

    fn add_to_index(&mut self, step: u64, time: f64) -> anyhow::Result<()> {
        let files = self.formats.iter().map(|&f| snapshot_file(&self.out, step, f).file_name().expect("a file name").to_string_lossy().into_owned()).collect();
        let path = self.index_path();
        self.index.add_and_write(&path, step, time, files)
    }

    /// Writes the backend's current state in every format through its streamed path, without
    /// one host copy of every array; returns the path of the first format's file and what
    /// the snapshot shows of the state's health, or `None` where the backend has no streamed path.
    pub fn write_streamed(&mut self, backend: &mut dyn Backend) -> Option<anyhow::Result<(PathBuf, SnapshotExtremes)>> {
        if !backend.streams_snapshots() {
            return None;
        }
        let step = backend.steps_done();
        let files: Vec<(SnapshotFormat, PathBuf)> = self.formats.iter().map(|&f| (f, snapshot_file(&self.out, step, f))).collect();
        let written = write_streamed(backend, &files);
        Some(written.and_then(|s| {
            for (f, path) in &files {
                if *f == SnapshotFormat::Vtk {
                    self.add_to_series(path, s.time)?;
                }
                log::info!("wrote {}", path.display());
            }
            self.add_to_index(s.step, s.time)?;
            let (_, first) = files.into_iter().next().ok_or_else(|| anyhow::anyhow!("no snapshot format chosen"))?;
            Ok((first, s.extremes))
        }))
    }

    /// Across ranks: every rank writes its piece of the backend's snapshot into the one file
    /// of each format ([`pieces::write_pieces`], collective); rank 0 keeps the VTK series and
    /// the index up to date. Returns the path of the first format's file and what the
    /// snapshot shows of the state's health, or `None` alone.
    pub fn write_pieces(&mut self, backend: &mut dyn Backend) -> Option<anyhow::Result<(PathBuf, SnapshotExtremes)>> {
        let piece = backend.snapshot_piece()?;
        Some(piece.and_then(|piece| {
            let files: Vec<(SnapshotFormat, PathBuf)> = self.formats.iter().map(|&f| (f, snapshot_file(&self.out, piece.step, f))).collect();
            let s = pieces::write_pieces(&files, &piece)?;
            if piece.comm.rank() == 0 {
                for (f, path) in &files {
                    if *f == SnapshotFormat::Vtk {
                        self.add_to_series(path, s.time)?;
                    }
                    log::info!("wrote {} (in pieces, by {} ranks)", path.display(), piece.comm.size());
                }
                self.add_to_index(s.step, s.time)?;
            }
            let (_, first) = files.into_iter().next().ok_or_else(|| anyhow::anyhow!("no snapshot format chosen"))?;
            Ok((first, s.extremes))
        }))
    }

    fn add_to_series(&mut self, vtk_file: &Path, time: f64) -> anyhow::Result<()> {
        let name = vtk_file.file_name().expect("a file name").to_string_lossy().into_owned();
        let index = self.series_path();
        self.series.add_and_write(&index, name, time)
    }

    /// Writes `s` in every format; returns the path of the first format's file.
    pub fn write(&mut self, s: &Snapshot) -> anyhow::Result<PathBuf> {
        let mut first = None;
        for f in self.formats.clone() {
            let path = snapshot_file(&self.out, s.step, f);
            write_snapshot(&path, f, s)?;
            if f == SnapshotFormat::Vtk {
                self.add_to_series(&path, s.time)?;
            }
            log::info!("wrote {}", path.display());
            first.get_or_insert(path);
        }
        self.add_to_index(s.step, s.time)?;
        first.ok_or_else(|| anyhow::anyhow!("no snapshot format chosen"))
    }
}


/// Writes the backend's current state as a snapshot in every `(format, path)` given, from the
/// rows it hands over in pieces (the same bytes as the whole-array writers of
/// [`Backend::snapshot`]). The files are written atomically, so a refused or failed snapshot
/// leaves none.
pub fn write_streamed(backend: &mut dyn Backend, files: &[(SnapshotFormat, PathBuf)]) -> anyhow::Result<stream::StreamedSnapshot> {
    let (particles, step, time) = (backend.fluid_count() as u64, backend.steps_done(), backend.time());
    write_rows(files, particles, step, time, |visit| backend.visit_snapshot_rows(visit))
}

/// Writes a snapshot of `particles` particles at `step` and `time` in every `(format, path)`
/// given, from the rows that `rows` hands to the visitor it gets, in original order.
pub fn write_rows(
    files: &[(SnapshotFormat, PathBuf)],
    particles: u64,
    step: u64,
    time: f64,
    rows: impl FnOnce(&mut dyn FnMut(u64, &[SnapshotRow]) -> anyhow::Result<()>) -> anyhow::Result<()>,
) -> anyhow::Result<stream::StreamedSnapshot> {
    let mut out = SnapshotStream::create(files, particles, step, time)?;
    rows(&mut |first, r| out.write_rows(first, r))?;
    out.finish()
}
