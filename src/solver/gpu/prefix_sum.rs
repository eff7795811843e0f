//! The host of the multi-level exclusive scan (wgsl/sim/prefix_sum.wgsl, twin
//! src/solver/cpu/prefix_sum.rs) over a buffer of u32, for any length.

use super::device::{GpuContext, GpuError};
use super::params::GpuParams;
use super::readback::read_buffers;
use super::shaders::{buffer_range, dispatch_size, stage, Stage, SCAN_BLOCK};

/// The levels of a scan of `len` values held in `data`: level 0 scans the data in blocks, each
/// higher level scans the block totals of the level below, until one block remains. A level
/// longer than one storage segment (`GpuContext::storage_segment_bytes`) is scanned segment by
/// segment: a segment holds whole blocks, so its block totals are a contiguous, aligned range of
/// the level above, and the levels above make the result one scan of the whole array.
pub struct Scan {
    scan_blocks: Stage,
    add_offsets: Stage,
    /// (bind group, values of its segment) per segment, per level, lowest level first.
    levels: Vec<Vec<(wgpu::BindGroup, u64)>>,
    _sums: Vec<wgpu::Buffer>,
    max_per_dim: u32,
}

/// `count` u32 values of `buffer` from value `first`.
fn range(buffer: &wgpu::Buffer, first: u64, count: u64) -> wgpu::BindingResource<'_> {
    buffer_range(buffer, first * 4, count * 4)
}

impl Scan {
    pub fn new(ctx: &GpuContext, uniform: &wgpu::Buffer, data: &wgpu::Buffer, len: u64) -> Result<Scan, GpuError> {
        let device = &ctx.device;
        // Both arrays are bound by range, segment by segment (`whole` in the stage file).
        let scan_blocks = stage(ctx, "prefix_sum", "scan_blocks", &|_| 0, &[])?;
        let add_offsets = stage(ctx, "prefix_sum", "add_block_offsets", &|_| 0, &[])?;
        let segment = ctx.storage_segment_bytes() / 4;
        let block = SCAN_BLOCK as u64;
        let mut sums: Vec<wgpu::Buffer> = Vec::new();
        let mut levels = Vec::new();
        let mut level_len = len;
        for sum_bytes in Scan::sum_buffer_bytes(len) {
            let sum_buffer = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("scan block sums"),
                size: sum_bytes,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            });
            let source = if levels.is_empty() { data } else { sums.last().unwrap() };
            let mut segments = Vec::new();
            for first in (0..level_len).step_by(segment as usize) {
                let count = segment.min(level_len - first);
                let bg = scan_blocks.bind_group_of(
                    device,
                    "scan level",
                    &[uniform.as_entire_binding(), range(source, first, count), range(&sum_buffer, first / block, count.div_ceil(block))],
                );
                segments.push((bg, count));
            }
            levels.push(segments);
            sums.push(sum_buffer);
            level_len = sum_bytes / 4;
        }
        Ok(Scan { scan_blocks, add_offsets, levels, _sums: sums, max_per_dim: device.limits().max_compute_workgroups_per_dimension })
    }

    /// Bytes of the block-sum buffer of each level of a scan of `len` values, lowest first: one
    /// u32 per block, up to the level that fits in one block.
    pub fn sum_buffer_bytes(len: u64) -> Vec<u64> {
        let mut out = Vec::new();
        let mut level_len = len;
        loop {
            let blocks = level_len.div_ceil(SCAN_BLOCK as u64).max(1);
            out.push(blocks * 4);
            if blocks == 1 {
                return out;
            }
            level_len = blocks;
        }
    }

    /// Bytes of the block-sum buffers.
    pub fn bytes(&self) -> u64 {
        self._sums.iter().map(|b| b.size()).sum()
    }

    /// Records the scan into a compute pass.
    pub fn record(&self, pass: &mut wgpu::ComputePass) {
        pass.set_pipeline(&self.scan_blocks.pipeline);
        for (bg, len) in self.levels.iter().flatten() {
            let (x, y) = dispatch_size(*len, SCAN_BLOCK, self.max_per_dim);
            pass.set_bind_group(0, bg, &[]);
            pass.dispatch_workgroups(x, y, 1);
        }
        pass.set_pipeline(&self.add_offsets.pipeline);
        for (bg, len) in self.levels.iter().rev().skip(1).flatten() {
            let (x, y) = dispatch_size(*len, SCAN_BLOCK, self.max_per_dim);
            pass.set_bind_group(0, bg, &[]);
            pass.dispatch_workgroups(x, y, 1);
        }
    }
}

/// Exclusive prefix sum of `values` on the GPU (the same pipeline the step uses for cell
/// starts); returns `values.len() + 1` sums, the last being the total.
pub fn exclusive_scan(ctx: &GpuContext, values: &[u32]) -> anyhow::Result<Vec<u32>> {
    use wgpu::util::DeviceExt;
    let device = &ctx.device;
    let mut data = values.to_vec();
    data.push(0);
    let uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("params"),
        contents: &GpuParams::default().bytes(),
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("scan data"),
        contents: bytemuck::cast_slice(&data),
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
    });
    let scan = Scan::new(ctx, &uniform, &buffer, data.len() as u64)?;
    let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("scan") });
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("scan"), timestamp_writes: None });
        scan.record(&mut pass);
    }
    ctx.queue.submit([encoder.finish()]);
    let bytes = read_buffers(ctx, &[(&buffer, data.len() as u64 * 4)])?;
    Ok(bytemuck::pod_collect_to_vec(&bytes[0]))
}
