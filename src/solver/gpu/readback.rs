//! Reading GPU buffers back: whole buffers or byte ranges through staging buffers, and the
//! particles handed over in pieces, so that a big run never needs one host copy of every array.
//! It knows no file format: the io layer turns the pieces into files.
//!
//! Snapshot rows list the particles in original order; the GPU keeps them in cell order, with
//! each position's w holding the slot's original index (u32 bits). [`visit_rows`] hands them
//! over in passes over ranges of original indices: each pass reads the arrays (positions
//! with ids, velocities, and densities and pressures where they have arrays) back in pieces of `chunk` slots through small
//! staging buffers, keeps the values whose id falls in the pass's range (32 bytes per particle
//! of the range), and passes that range on. At most [`MAX_PASSES`] passes are made, so the host
//! holds `32 * max(chunk, ceil(N / MAX_PASSES))` bytes of rows plus `2 * 40 * chunk` of readback
//! (the staging buffers and their copy): about 4 bytes per particle for big runs, instead of
//! the whole-array path's 40 bytes read back plus 64 in a [`crate::model::state::Snapshot`].
//!
//! A saved state keeps the cell order, so its arrays are read back one after the other in
//! pieces ([`visit_array`]).

use super::buffers::{widen, STREAM_CHUNK};
use super::device::GpuContext;
use crate::solver::backend::{SnapshotRow, StatePiece};

/// Most passes over the GPU arrays per streamed snapshot.
pub const MAX_PASSES: u64 = 8;

/// Copies `buffers` (their first `bytes` each) to mappable staging buffers and reads them back
/// (waits for the GPU).
pub fn read_buffers(ctx: &GpuContext, buffers: &[(&wgpu::Buffer, u64)]) -> anyhow::Result<Vec<Vec<u8>>> {
    let ranges: Vec<(&wgpu::Buffer, u64, u64)> = buffers.iter().map(|&(buffer, bytes)| (buffer, 0, bytes)).collect();
    read_ranges(ctx, &ranges)
}

/// Copies byte ranges `(buffer, offset, bytes)` to mappable staging buffers and reads them back
/// (waits for the GPU). Copies are made in whole 4-byte words, as wgpu requires.
pub fn read_ranges(ctx: &GpuContext, ranges: &[(&wgpu::Buffer, u64, u64)]) -> anyhow::Result<Vec<Vec<u8>>> {
    let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("readback") });
    let staged = stage_ranges(ctx, &mut encoder, ranges);
    ctx.queue.submit([encoder.finish()]);
    read_staged(ctx, &staged, ranges)
}

/// Records into `encoder` copies of byte ranges `(buffer, offset, bytes)` to new mappable
/// staging buffers, for [`read_staged`] once `encoder` is submitted: work recorded before the
/// copies and the read of its results then share one submission and one wait.
pub fn stage_ranges(ctx: &GpuContext, encoder: &mut wgpu::CommandEncoder, ranges: &[(&wgpu::Buffer, u64, u64)]) -> Vec<wgpu::Buffer> {
    ranges
        .iter()
        .map(|&(src, offset, bytes)| {
            let size = bytes.max(4).next_multiple_of(4);
            let dst = ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("staging"),
                size,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            encoder.copy_buffer_to_buffer(src, offset, &dst, 0, size);
            dst
        })
        .collect()
}

/// Waits for the GPU and reads back the staging buffers [`stage_ranges`] recorded the copies
/// of `ranges` into (their submission made).
pub fn read_staged(ctx: &GpuContext, staging: &[wgpu::Buffer], ranges: &[(&wgpu::Buffer, u64, u64)]) -> anyhow::Result<Vec<Vec<u8>>> {
    let device = &ctx.device;
    let (tx, rx) = std::sync::mpsc::channel();
    for (i, s) in staging.iter().enumerate() {
        let tx = tx.clone();
        s.slice(..).map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send((i, r));
        });
    }
    device.poll(wgpu::PollType::Wait { submission_index: None, timeout: None })?;
    ctx.check_device()?;
    for _ in 0..staging.len() {
        let (i, r) = rx.recv()?;
        r.map_err(|e| anyhow::anyhow!("mapping readback buffer {i} failed: {e}"))?;
    }
    let out = staging
        .iter()
        .zip(ranges)
        .map(|(s, &(_, _, bytes))| s.slice(..).get_mapped_range().expect("mapped above")[..bytes as usize].to_vec())
        .collect();
    for s in staging {
        s.unmap();
    }
    Ok(out)
}

/// The arrays of a snapshot, in slot (cell) order.
pub struct RowArrays<'a> {
    /// `vec4<f32>` with the original index in w.
    pub positions: &'a wgpu::Buffer,
    pub velocities: &'a wgpu::Buffer,
    /// `None`: the densities are the w of the velocities.
    pub densities: Option<&'a wgpu::Buffer>,
    /// `None`: each pressure is `pressure_of` its density.
    pub pressures: Option<&'a wgpu::Buffer>,
    pub pressure_of: &'a dyn Fn(f32) -> f32,
    /// Particles.
    pub count: u64,
}

/// Hands the particles of `arrays` to `visit` in original order, a range of original indices
/// at a time: `visit(first, rows)` gets particles `first..first + rows.len()`. The arrays are
/// read `chunk` slots at a time, in at most [`MAX_PASSES`] passes.
pub fn visit_rows(ctx: &GpuContext, arrays: &RowArrays, chunk: u64, visit: &mut dyn FnMut(u64, &[SnapshotRow]) -> anyhow::Result<()>) -> anyhow::Result<()> {
    let n = arrays.count;
    let chunk = chunk.max(1);
    let per_pass = chunk.max(n.div_ceil(MAX_PASSES)).max(1);
    let mut buffers = vec![(arrays.positions, 16u64), (arrays.velocities, 16)];
    buffers.extend(arrays.densities.map(|d| (d, 4)));
    buffers.extend(arrays.pressures.map(|p| (p, 4)));
    let mut rows = vec![[0f32; 8]; per_pass.min(n) as usize];
    for first in (0..n).step_by(per_pass as usize) {
        let end = (first + per_pass).min(n);
        for slot in (0..n).step_by(chunk as usize) {
            let count = chunk.min(n - slot);
            let ranges: Vec<_> = buffers.iter().map(|&(b, size)| (b, slot * size, count * size)).collect();
            let data = read_ranges(ctx, &ranges)?;
            let pos: &[[f32; 4]] = bytemuck::cast_slice(&data[0]);
            let vel: &[[f32; 4]] = bytemuck::cast_slice(&data[1]);
            let stored = |k: usize| -> &[f32] { bytemuck::cast_slice(&data[k]) };
            let rho: Vec<f32> = match arrays.densities {
                Some(_) => stored(2).to_vec(),
                None => vel.iter().map(|v| v[3]).collect(),
            };
            let p: Vec<f32> = match arrays.pressures {
                Some(_) => stored(buffers.len() - 1).to_vec(),
                None => rho.iter().map(|&r| (arrays.pressure_of)(r)).collect(),
            };
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

/// What [`visit_array`] reads from a `vec4<f32>` array.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Element {
    /// The xyz, widened to f64.
    Vector,
    /// The u32 bits in the w (the ids in the positions).
    IdInW,
    /// The float in the w, widened (the carried densities in the velocities).
    ScalarInW,
}

/// Hands `count` elements of a `vec4<f32>` array to `visit` in slot order, `chunk` at a time.
pub fn visit_array(ctx: &GpuContext, buffer: &wgpu::Buffer, count: u64, element: Element, chunk: u64, visit: &mut dyn FnMut(StatePiece) -> anyhow::Result<()>) -> anyhow::Result<()> {
    let chunk = if chunk == 0 { STREAM_CHUNK } else { chunk };
    for slot in (0..count).step_by(chunk as usize) {
        let n = chunk.min(count - slot);
        let data = read_ranges(ctx, &[(buffer, slot * 16, n * 16)])?;
        let values: &[[f32; 4]] = bytemuck::cast_slice(&data[0]);
        match element {
            Element::Vector => visit(StatePiece::Vectors(&values.iter().map(widen).collect::<Vec<_>>()))?,
            Element::IdInW => visit(StatePiece::Ids(&values.iter().map(|v| v[3].to_bits()).collect::<Vec<_>>()))?,
            Element::ScalarInW => visit(StatePiece::Scalars(&values.iter().map(|v| v[3] as f64).collect::<Vec<_>>()))?,
        }
    }
    Ok(())
}

/// Hands `count` pairs of two `f32` arrays (widened) to `visit` in order, `chunk` at a time.
pub fn visit_pairs(ctx: &GpuContext, first: &wgpu::Buffer, second: &wgpu::Buffer, count: u64, chunk: u64, visit: &mut dyn FnMut(StatePiece) -> anyhow::Result<()>) -> anyhow::Result<()> {
    let chunk = if chunk == 0 { STREAM_CHUNK } else { chunk };
    for slot in (0..count).step_by(chunk as usize) {
        let n = chunk.min(count - slot);
        let data = read_ranges(ctx, &[(first, slot * 4, n * 4), (second, slot * 4, n * 4)])?;
        let (a, b): (&[f32], &[f32]) = (bytemuck::cast_slice(&data[0]), bytemuck::cast_slice(&data[1]));
        visit(StatePiece::Pairs(&a.iter().zip(b).map(|(&x, &y)| [x as f64, y as f64]).collect::<Vec<_>>()))?;
    }
    Ok(())
}
