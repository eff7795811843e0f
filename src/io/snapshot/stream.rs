//! Snapshot files written in pieces, for backends that never hold every particle on the host:
//! the rows arrive in original particle order, a range of particles at a time, and go to every
//! format's file at once. Each file is the same bytes as the whole-array writer's
//! ([`super::csv::write_snapshot_csv`], [`super::vtk::write_vtk`], [`super::ply::write_ply`]).
//!
//! CSV and PLY store one particle after the other, so a piece is appended. Legacy VTK stores
//! the particles array by array (points, cells, cell types, velocity, density, pressure); every
//! section's size follows from the particle count, so each piece is written at its place in
//! every section (the file is seekable: [`AtomicFile`]). Nothing but the piece is held.

use super::csv::{write_snapshot_row, SNAPSHOT_HEADER};
use super::format::SnapshotFormat;
use super::ply::{ply_header, PlyVertex};
use super::vtk::{vtk_title, VtkLayout};
use crate::io::atomic::AtomicFile;
use crate::model::state::SnapshotExtremes;
use crate::solver::SnapshotRow;
use anyhow::Context;
use std::io::Write;
use std::path::{Path, PathBuf};

/// What a streamed snapshot reports besides its files.
#[derive(Clone, Debug, PartialEq)]
pub struct StreamedSnapshot {
    pub step: u64,
    pub time: f64,
    pub particles: u64,
    pub extremes: SnapshotExtremes,
}

/// The snapshot files of one step being written piece by piece. Dropped before
/// [`SnapshotStream::finish`] (an error, a refused snapshot), it leaves no file behind.
pub struct SnapshotStream {
    files: Vec<FormatFile>,
    particles: u64,
    step: u64,
    time: f64,
    /// The first particle of the next piece: pieces come in order.
    next: u64,
    non_finite: u64,
    extremes: SnapshotExtremes,
}

enum FormatFile {
    Csv(AtomicFile),
    Ply(AtomicFile, ply_rs_bw::ply::ElementDef),
    Vtk(AtomicFile, VtkLayout),
}

impl SnapshotStream {
    /// Opens the files (`(format, path)`, one per format) of a snapshot of `particles`
    /// particles, and writes what precedes the particles' values.
    pub fn create(files: &[(SnapshotFormat, PathBuf)], particles: u64, step: u64, time: f64) -> anyhow::Result<Self> {
        let files = files
            .iter()
            .map(|(format, path)| {
                let mut file = AtomicFile::create(path)?;
                let cannot = || format!("cannot write {}", path.display());
                let opened = match format {
                    SnapshotFormat::Csv => {
                        writeln!(file, "{SNAPSHOT_HEADER}").with_context(cannot)?;
                        FormatFile::Csv(file)
                    }
                    SnapshotFormat::Ply => {
                        let header = ply_header(step, time, particles as usize);
                        ply_rs_bw::writer::Writer::<PlyVertex>::new().write_header(&mut file, &header).with_context(cannot)?;
                        let vertex = header.elements["vertex"].clone();
                        FormatFile::Ply(file, vertex)
                    }
                    SnapshotFormat::Vtk => {
                        let layout = VtkLayout::new(particles, &vtk_title(step, time));
                        layout.write_text(&mut file).with_context(cannot)?;
                        FormatFile::Vtk(file, layout)
                    }
                };
                Ok(opened)
            })
            .collect::<anyhow::Result<_>>()?;
        Ok(SnapshotStream { files, particles, step, time, next: 0, non_finite: 0, extremes: SnapshotExtremes::NONE })
    }

    /// Writes the rows of particles `first..first + rows.len()` (the next ones in original
    /// order) to every file.
    pub fn write_rows(&mut self, first: u64, rows: &[SnapshotRow]) -> anyhow::Result<()> {
        anyhow::ensure!(
            first == self.next && first + rows.len() as u64 <= self.particles,
            "snapshot rows {first}..{} arrive out of order (expected {} of {})",
            first + rows.len() as u64,
            self.next,
            self.particles
        );
        for r in rows {
            let v = r.map(|x| x as f64);
            if v.iter().all(|x| x.is_finite()) {
                self.extremes.add([v[3], v[4], v[5]], v[6]);
            } else {
                self.non_finite += 1;
            }
        }
        for file in &mut self.files {
            let written = match file {
                FormatFile::Csv(f) => rows.iter().try_for_each(|r| write_snapshot_row(f, &r.map(|x| x as f64))),
                FormatFile::Ply(f, vertex) => {
                    let writer = ply_rs_bw::writer::Writer::<PlyVertex>::new();
                    rows.iter().try_for_each(|r| writer.write_little_endian_element(f, &PlyVertex(*r), vertex).map(|_| ()))
                }
                FormatFile::Vtk(f, layout) => layout.write_rows(f, first, &rows.iter().map(|r| r.map(f64::from)).collect::<Vec<_>>()),
            };
            written.with_context(|| format!("cannot write {}", file.file().path().display()))?;
        }
        self.next += rows.len() as u64;
        Ok(())
    }

    /// Checks that every particle was written and none is NaN or infinite, then renames every
    /// file into place.
    pub fn finish(self) -> anyhow::Result<StreamedSnapshot> {
        let first = self.files.first().map_or(Path::new(""), |f| f.file().path()).to_path_buf();
        if self.non_finite > 0 {
            anyhow::bail!(
                "refusing to write {}: {} particles hold NaN or infinity at step {}",
                first.display(),
                self.non_finite,
                self.step
            );
        }
        anyhow::ensure!(self.next == self.particles, "{}: only {} of {} particles were written", first.display(), self.next, self.particles);
        for f in self.files {
            match f {
                FormatFile::Csv(f) | FormatFile::Ply(f, _) | FormatFile::Vtk(f, _) => f.commit()?,
            }
        }
        Ok(StreamedSnapshot { step: self.step, time: self.time, particles: self.particles, extremes: self.extremes })
    }
}

impl FormatFile {
    fn file(&self) -> &AtomicFile {
        match self {
            FormatFile::Csv(f) | FormatFile::Ply(f, _) | FormatFile::Vtk(f, _) => f,
        }
    }
}
