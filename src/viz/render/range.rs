//! The automatic colour range: the smallest and largest value of the colouring field, reduced
//! on the GPU (render/range.wgsl) straight into the frame uniform, so that no particle data
//! leaves the GPU.

use super::common::{shader_module, Fluid, RANGE_KEYS_OFFSET};
use crate::solver::gpu::shaders::{bind_group, buffer_range, dispatch_size, layout, Use};

const RANGE_WORKGROUP: u64 = 256;

pub(super) struct ColorRange {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    params: wgpu::Buffer,
    /// The reduced keys of the smallest and largest value.
    keys: wgpu::Buffer,
    /// Bytes per storage binding (`GpuContext::storage_segment_bytes`).
    segment_bytes: u64,
}

impl ColorRange {
    pub(super) fn new(device: &wgpu::Device, segment_bytes: u64) -> Self {
        let module = shader_module(device, "render_range", "render/range.wgsl");
        let layout = layout(device, "render_range", &[Use::Uniform, Use::Read, Use::ReadWrite]);
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("render_range"),
            layout: Some(&device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("render_range"),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            })),
            module: &module,
            entry_point: Some("range"),
            compilation_options: Default::default(),
            cache: None,
        });
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("render range params"),
            size: 16,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let keys = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("render range keys"),
            size: 16,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        ColorRange { pipeline, layout, params, keys, segment_bytes }
    }

    /// Records the reduction of the colouring field of `fluid` (at least one particle) and the
    /// copy of its keys into `frame`, the frame uniform.
    pub(super) fn encode(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        fluid: Fluid,
        frame: &wgpu::Buffer,
    ) {
        let n = fluid.count;
        queue.write_buffer(&self.params, 0, bytemuck::cast_slice(&[n, fluid.vector as u32, 0, 0]));
        encoder.clear_buffer(&self.keys, 0, None);
        // One dispatch per segment of the field, so that no binding exceeds the adapter's
        // storage binding size however many particles there are.
        let value_bytes = fluid.field_bytes();
        let per_segment = self.segment_bytes / value_bytes;
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("colour range"), timestamp_writes: None });
        pass.set_pipeline(&self.pipeline);
        for first in (0..n as u64).step_by(per_segment as usize) {
            let count = per_segment.min(n as u64 - first);
            let values = buffer_range(fluid.field, first * value_bytes, count * value_bytes);
            let group = bind_group(device, "render_range", &self.layout, &[self.params.as_entire_binding(), values, self.keys.as_entire_binding()]);
            let (x, y) = dispatch_size(count, RANGE_WORKGROUP as u32, device.limits().max_compute_workgroups_per_dimension);
            pass.set_bind_group(0, &group, &[]);
            pass.dispatch_workgroups(x, y, 1);
        }
        drop(pass);
        encoder.copy_buffer_to_buffer(&self.keys, 0, frame, RANGE_KEYS_OFFSET, 8);
    }
}
