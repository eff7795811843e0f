//! Snapshots and checkpoints streamed from the GPU in pieces, so a big run never needs one host
//! copy of every array.
//!
//! Snapshots list the particles in original order; the GPU keeps them in cell order, with each
//! position's w holding the slot's original index (u32 bits). [`GpuSolver::visit_rows`] hands
//! them over in passes over ranges of original indices: each pass reads the four arrays
//! (positions with ids, velocities, densities, pressures) back in pieces of `chunk` slots through small staging buffers, keeps
//! the values whose id falls in the pass's range (32 bytes per particle of the range), and
//! passes that range on, in order, to every format's file ([`SnapshotStream`]). At most
//! [`MAX_PASSES`] passes are made, so the host holds `32 * max(chunk, ceil(N / MAX_PASSES))`
//! bytes of rows plus `2 * 40 * chunk` of readback (the staging buffers and their copy): about
//! 4 bytes per particle for big runs, instead of the whole-array path's 40 bytes read back plus
//! 64 in the [`crate::sim::Snapshot`] (plus the writers' own copies).
//!
//! Checkpoints keep the cell order, so their arrays are read back one after the other in pieces
//! and serialised as they come (see `state`).

use super::{read_ranges, GpuSolver};
use crate::export::stream::{Row, SnapshotStream};
use crate::export::SnapshotFormat;
use crate::sim::Backend;
use std::path::{Path, PathBuf};

mod state;

pub use crate::export::stream::StreamedSnapshot;

/// Particles per piece read back when streaming snapshots and checkpoints.
pub const STREAM_CHUNK: u64 = 1 << 20;
/// Most passes over the GPU arrays per streamed snapshot.
pub const MAX_PASSES: u64 = 8;

impl GpuSolver {
    /// Hands the current particles (as they are: call `refresh_fields` first for a snapshot's
    /// density and pressure) to `visit` in original order, a range of original indices at a time:
    /// `visit(first, rows)` gets particles `first..first + rows.len()`. The GPU arrays are read
    /// `chunk` slots at a time, in at most [`MAX_PASSES`] passes.
    fn visit_rows(&self, chunk: u64, mut visit: impl FnMut(u64, &[Row]) -> anyhow::Result<()>) -> anyhow::Result<()> {
        let n = self.fluid_count as u64;
        let chunk = chunk.max(1);
        let per_pass = chunk.max(n.div_ceil(MAX_PASSES)).max(1);
        let st = &self.state[self.current];
        let buffers = [(&st.positions, 16u64), (&st.velocities, 16), (&self.densities, 4), (&self.pressures, 4)];
        let mut rows = vec![[0f32; 8]; per_pass.min(n) as usize];
        for first in (0..n).step_by(per_pass as usize) {
            let end = (first + per_pass).min(n);
            for slot in (0..n).step_by(chunk as usize) {
                let count = chunk.min(n - slot);
                let ranges: Vec<_> = buffers.iter().map(|&(b, size)| (b, slot * size, count * size)).collect();
                let data = read_ranges(&self.ctx, &ranges)?;
                let pos: &[[f32; 4]] = bytemuck::cast_slice(&data[0]);
                let vel: &[[f32; 4]] = bytemuck::cast_slice(&data[1]);
                let (rho, p): (&[f32], &[f32]) = (bytemuck::cast_slice(&data[2]), bytemuck::cast_slice(&data[3]));
                for (j, x) in pos.iter().enumerate() {
                    // The particle's original index rides in w as u32 bits.
                    let id = x[3].to_bits() as u64;
                    if (first..end).contains(&id) {
                        let (x, v) = (pos[j], vel[j]);
                        rows[(id - first) as usize] = [x[0], x[1], x[2], v[0], v[1], v[2], rho[j], p[j]];
                    }
                }
            }
            visit(first, &rows[..(end - first) as usize])?;
        }
        Ok(())
    }

    /// Writes the current state as a snapshot in every `(format, path)` given (the same bytes as
    /// [`crate::export::write_snapshot`] of [`crate::sim::Backend::snapshot`]), reading the GPU
    /// arrays back `chunk` particles at a time. Refuses NaN or infinity like the whole-array
    /// writers; the files are written atomically, so a refused or failed snapshot leaves none.
    pub fn write_snapshot_in_pieces(&mut self, files: &[(SnapshotFormat, PathBuf)], chunk: u64) -> anyhow::Result<StreamedSnapshot> {
        self.refresh_fields();
        let mut out = SnapshotStream::create(files, self.fluid_count as u64, self.steps, self.time())?;
        self.visit_rows(chunk, |first, rows| out.write_rows(first, rows))?;
        out.finish()
    }

    /// [`GpuSolver::write_snapshot_in_pieces`] of a CSV snapshot alone.
    pub fn write_snapshot_csv_streamed(&mut self, path: &Path, chunk: u64) -> anyhow::Result<StreamedSnapshot> {
        self.write_snapshot_in_pieces(&[(SnapshotFormat::Csv, path.to_path_buf())], chunk)
    }
}
