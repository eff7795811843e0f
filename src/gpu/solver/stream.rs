//! CSV snapshots streamed from the GPU in pieces, so a big run never needs one host copy of
//! every array.
//!
//! The GPU keeps the particles in cell order, with each position's w giving the slot's original
//! index; the file lists them in original order. The rows are written in passes over ranges of
//! original indices: each pass reads the four arrays (positions with ids, velocities, densities,
//! pressures) back in pieces of `chunk` slots through small staging buffers, keeps the values
//! whose id falls in the pass's range (32 bytes per particle of the range), then formats and
//! appends them. At most [`MAX_PASSES`] passes are made, so the host holds
//! `32 * max(chunk, ceil(N / MAX_PASSES)) + 40 * chunk` bytes: about 4 bytes per particle for
//! big runs, instead of the whole-array path's 40 bytes read back plus 64 in the snapshot.

use super::{read_ranges, GpuSolver};
use crate::output::{write_atomic, write_snapshot_row, SNAPSHOT_HEADER};
use crate::sim::Backend;
use std::path::Path;

/// Particles per piece read back when streaming snapshots.
pub const STREAM_CHUNK: u64 = 1 << 20;
/// Most passes over the GPU arrays per streamed snapshot.
pub const MAX_PASSES: u64 = 8;

/// What a streamed snapshot reports besides its file.
#[derive(Clone, Debug, PartialEq)]
pub struct StreamedSnapshot {
    pub step: u64,
    pub time: f64,
    pub particles: u64,
    pub max_speed: f64,
}

impl GpuSolver {
    /// Writes the current state as a snapshot CSV (the same bytes as
    /// [`crate::output::write_snapshot_csv`] of [`crate::sim::Backend::snapshot`]), reading the
    /// GPU arrays back `chunk` particles at a time. Refuses NaN or infinity like the whole-array
    /// writer; the file is written atomically, so a refused or failed snapshot leaves none.
    pub fn write_snapshot_csv_streamed(&mut self, path: &Path, chunk: u64) -> anyhow::Result<StreamedSnapshot> {
        self.refresh_fields();
        let n = self.fluid_count as u64;
        let chunk = chunk.max(1);
        let per_pass = chunk.max(n.div_ceil(MAX_PASSES)).max(1);
        let st = &self.state[self.current];
        let buffers = [(&st.positions, 16u64), (&st.velocities, 16), (&self.densities, 4), (&self.pressures, 4)];
        let mut rows = vec![[0f32; 8]; per_pass.min(n) as usize];
        let (mut bad, mut max_speed) = (0u64, 0f64);
        write_atomic(path, |w| {
            writeln!(w, "{SNAPSHOT_HEADER}")?;
            for first in (0..n).step_by(per_pass as usize) {
                let end = (first + per_pass).min(n);
                for slot in (0..n).step_by(chunk as usize) {
                    let count = chunk.min(n - slot);
                    let ranges: Vec<_> = buffers.iter().map(|&(b, size)| (b, slot * size, count * size)).collect();
                    let data = read_ranges(&self.ctx, &ranges).map_err(std::io::Error::other)?;
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
                for r in &rows[..(end - first) as usize] {
                    let values = r.map(|x| x as f64);
                    if values.iter().any(|x| !x.is_finite()) {
                        bad += 1;
                        continue;
                    }
                    max_speed = max_speed.max((values[3] * values[3] + values[4] * values[4] + values[5] * values[5]).sqrt());
                    write_snapshot_row(w, &values)?;
                }
            }
            if bad > 0 {
                return Err(std::io::Error::other(format!("refusing to write it: {bad} particles hold NaN or infinity at step {}", self.steps)));
            }
            Ok(())
        })?;
        Ok(StreamedSnapshot { step: self.steps, time: self.time(), particles: n, max_speed })
    }
}
