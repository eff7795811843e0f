//! Snapshots across ranks, written in pieces into one file per format and step: every rank
//! writes the particles of its block of original ids ([`crate::solver::id_block`]) at their
//! place in the file, so the file is byte for byte the one a single process writes and every
//! reader opens it as before (docs/scale-out.md, "Snapshots in pieces").
//!
//! Rank 0 creates each format's temporary file ([`AtomicFile`]) and writes the text before and
//! between the particles' values; every rank opens the same temporary file and writes its rows
//! where they belong. Legacy VTK and PLY store values of fixed size, so a particle's place
//! follows from its id; CSV lines vary in length, so a rank's lines start after the lower
//! ranks' lines (their byte counts all-gathered). Once every rank has written and synced its
//! piece, rank 0 renames the files into place. A rank that fails makes every rank return an
//! error, and rank 0's temporary files are removed: no half-written snapshot is left. The
//! output directory must be one every rank sees (one machine, or a shared file system, as for
//! MPI-IO).

use super::csv::{write_snapshot_row, SNAPSHOT_HEADER};
use super::format::SnapshotFormat;
use super::ply::ply_header;
use super::stream::StreamedSnapshot;
use super::vtk::{vtk_title, VtkLayout};
use crate::io::atomic::{temporary_path, AtomicFile};
use crate::model::state::SnapshotExtremes;
use crate::solver::communicator::Communicator;
use crate::solver::SnapshotPiece;
use anyhow::Context;
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// Bytes of one PLY vertex: eight little-endian `float`s.
const PLY_VERTEX_BYTES: u64 = 32;

/// Writes every rank's `piece` of one snapshot into the files `(format, path)` (collective:
/// every rank calls it with the same files). Refused on every rank, with no file written, when
/// any rank's rows hold NaN or infinity.
pub fn write_pieces(files: &[(SnapshotFormat, PathBuf)], piece: &SnapshotPiece) -> anyhow::Result<StreamedSnapshot> {
    let comm = &*piece.comm;
    let first_path = files.first().map_or(PathBuf::new(), |(_, p)| p.clone());
    let non_finite = piece.rows.iter().filter(|r| !r.iter().all(|x| x.is_finite())).count();
    let mut own = SnapshotExtremes::NONE;
    for r in piece.rows.iter().filter(|r| r.iter().all(|x| x.is_finite())) {
        own.add([r[3], r[4], r[5]], r[6]);
    }
    let csv = files.iter().any(|(f, _)| *f == SnapshotFormat::Csv).then(|| csv_lines(&piece.rows)).transpose()?;
    let counts = comm.all_gather(&[
        non_finite as f64,
        own.max_speed,
        piece.rows.len() as f64,
        csv.as_ref().map_or(0, Vec::len) as f64,
        own.min_density,
        own.max_density,
        own.non_positive_density as f64,
    ])?;
    let non_finite: f64 = counts.iter().map(|c| c[0]).sum();
    if non_finite > 0.0 {
        anyhow::bail!("refusing to write {}: {non_finite} particles hold NaN or infinity at step {}", first_path.display(), piece.step);
    }
    let rows: f64 = counts.iter().map(|c| c[2]).sum();
    anyhow::ensure!(rows == piece.total as f64, "the ranks hold {rows} snapshot rows of {} particles", piece.total);
    let csv_offset: f64 = counts[..comm.rank()].iter().map(|c| c[3]).sum();
    let extremes = counts.iter().fold(SnapshotExtremes::NONE, |e, c| {
        e.merge(SnapshotExtremes { max_speed: c[1], min_density: c[4], max_density: c[5], non_positive_density: c[6] as u64 })
    });

    // Rank 0 creates the files; every rank learns their temporary names.
    let created = match comm.rank() {
        0 => Some(files.iter().map(|(_, path)| AtomicFile::create(path)).collect::<anyhow::Result<Vec<_>>>()),
        _ => None,
    };
    let tokens: Vec<f64> = match &created {
        Some(Ok(made)) => made.iter().flat_map(|f| [(f.token() >> 32) as f64, (f.token() & 0xffff_ffff) as f64]).collect(),
        _ => Vec::new(),
    };
    let tokens = comm.all_gather(&tokens)?.swap_remove(0);
    let mut created = match created {
        Some(made) => made?,
        None if tokens.len() != 2 * files.len() => anyhow::bail!("rank 0 could not create {}", first_path.display()),
        None => Vec::new(),
    };
    let tokens: Vec<u64> = tokens.chunks_exact(2).map(|t| ((t[0] as u64) << 32) | t[1] as u64).collect();

    // Every rank writes its piece; rank 0 also what surrounds the particles.
    let mut written = (|| -> anyhow::Result<()> {
        for (((format, path), &token), made) in files.iter().zip(&tokens).zip(created.iter_mut().map(Some).chain(std::iter::repeat_with(|| None))) {
            let cannot = || format!("cannot write {}", path.display());
            let header = header(*format, piece)?;
            if let Some(f) = made {
                match format {
                    SnapshotFormat::Vtk => VtkLayout::new(piece.total, &vtk_title(piece.step, piece.time)).write_text(f),
                    _ => f.write_all(&header),
                }
                .with_context(cannot)?;
            }
            let temporary = std::fs::OpenOptions::new().write(true).open(temporary_path(path, token)).with_context(|| {
                format!(
                    "rank {} of {} cannot open the file rank 0 created for {}: every rank must see the output directory (one machine, or a file system shared by the ranks' machines)",
                    comm.rank(),
                    comm.size(),
                    path.display()
                )
            })?;
            let mut out = std::io::BufWriter::new(temporary);
            write_rows(&mut out, *format, piece, header.len() as u64, csv_offset as u64, csv.as_deref()).with_context(cannot)?;
            out.into_inner().map_err(|e| e.into_error()).and_then(|f| f.sync_all()).with_context(cannot)?;
        }
        Ok(())
    })();
    agree(comm, &mut written, "write its piece of", &first_path)?;

    // Rank 0 renames the files into place (dropped unrenamed, they are removed).
    let mut committed = created.into_iter().try_for_each(AtomicFile::commit);
    agree(comm, &mut committed, "move into place", &first_path)?;
    Ok(StreamedSnapshot { step: piece.step, time: piece.time, particles: piece.total, extremes })
}

/// Whether every rank succeeded: this rank's own error, or which rank failed.
fn agree(comm: &dyn Communicator, result: &mut anyhow::Result<()>, what: &str, path: &Path) -> anyhow::Result<()> {
    let all = comm.all_gather(&[result.is_ok() as u8 as f64])?;
    let result = std::mem::replace(result, Ok(()));
    result?;
    match all.iter().position(|ok| ok[0] == 0.0) {
        Some(rank) => anyhow::bail!("rank {rank} of {} could not {what} {}", comm.size(), path.display()),
        None => Ok(()),
    }
}

/// This rank's CSV lines, as the whole-file writer formats them.
fn csv_lines(rows: &[[f64; 8]]) -> anyhow::Result<Vec<u8>> {
    let mut out = Vec::new();
    rows.iter().try_for_each(|r| write_snapshot_row(&mut out, r))?;
    Ok(out)
}

/// The bytes before the first particle's values (CSV and PLY; VTK's texts lie between its
/// arrays and are placed by its layout).
fn header(format: SnapshotFormat, piece: &SnapshotPiece) -> anyhow::Result<Vec<u8>> {
    let mut out = Vec::new();
    match format {
        SnapshotFormat::Csv => writeln!(out, "{SNAPSHOT_HEADER}")?,
        SnapshotFormat::Ply => {
            let header = ply_header(piece.step, piece.time, piece.total as usize);
            ply_rs_bw::writer::Writer::<super::ply::PlyVertex>::new().write_header(&mut out, &header)?;
        }
        SnapshotFormat::Vtk => {}
    }
    Ok(out)
}

/// This rank's rows at their place in a file of `format` whose particles start after
/// `header_bytes` (CSV: after the lower ranks' `csv_offset` bytes of lines).
fn write_rows(out: &mut (impl Write + Seek), format: SnapshotFormat, piece: &SnapshotPiece, header_bytes: u64, csv_offset: u64, csv: Option<&[u8]>) -> std::io::Result<()> {
    match format {
        SnapshotFormat::Csv => {
            out.seek(SeekFrom::Start(header_bytes + csv_offset))?;
            out.write_all(csv.unwrap_or_default())
        }
        SnapshotFormat::Ply => {
            out.seek(SeekFrom::Start(header_bytes + piece.first * PLY_VERTEX_BYTES))?;
            for r in &piece.rows {
                for x in r {
                    out.write_all(&(*x as f32).to_le_bytes())?;
                }
            }
            Ok(())
        }
        SnapshotFormat::Vtk => VtkLayout::new(piece.total, &vtk_title(piece.step, piece.time)).write_rows(out, piece.first, &piece.rows),
    }
}
