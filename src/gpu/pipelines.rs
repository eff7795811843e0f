//! Shader assembly, bind-group layouts and compute pipelines, built once per scene.

use crate::scene::{BoundaryPressure, EquationOfState, Kernel, Params};

/// Shared definitions, prepended to each stage (WGSL has no include).
pub const COMMON: &str = include_str!("../../wgsl/common.wgsl");

/// The WGSL stage files, in dispatch order.
pub const STAGES: &[(&str, &str)] = &[
    ("bin_count", include_str!("../../wgsl/bin_count.wgsl")),
    ("prefix_sum", include_str!("../../wgsl/prefix_sum.wgsl")),
    ("bin_scatter", include_str!("../../wgsl/bin_scatter.wgsl")),
    ("reorder", include_str!("../../wgsl/reorder.wgsl")),
    ("density", include_str!("../../wgsl/density.wgsl")),
    ("forces", include_str!("../../wgsl/forces.wgsl")),
    ("integrate", include_str!("../../wgsl/integrate.wgsl")),
];

/// Threads per workgroup of the particle stages (WORKGROUP_SIZE in common.wgsl).
pub const WORKGROUP_SIZE: u32 = 128;
/// Values per workgroup of the scan (SCAN_BLOCK in prefix_sum.wgsl).
pub const SCAN_BLOCK: u32 = 2 * WORKGROUP_SIZE;

/// The source of one stage, with the common definitions.
pub fn stage_source(name: &str) -> String {
    let stage = STAGES.iter().find(|s| s.0 == name).unwrap_or_else(|| panic!("no stage {name}")).1;
    format!("{COMMON}\n{stage}")
}

/// How a binding is used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Use {
    Uniform,
    Read,
    ReadWrite,
}

/// A bind-group layout whose binding i has use `uses[i]`.
pub fn layout(device: &wgpu::Device, label: &str, uses: &[Use]) -> wgpu::BindGroupLayout {
    let entries: Vec<_> = uses
        .iter()
        .enumerate()
        .map(|(i, u)| wgpu::BindGroupLayoutEntry {
            binding: i as u32,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: match u {
                    Use::Uniform => wgpu::BufferBindingType::Uniform,
                    Use::Read => wgpu::BufferBindingType::Storage { read_only: true },
                    Use::ReadWrite => wgpu::BufferBindingType::Storage { read_only: false },
                },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        })
        .collect();
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries: &entries })
}

/// A bind group binding `buffers[i]` at binding i.
pub fn bind_group(device: &wgpu::Device, label: &str, layout: &wgpu::BindGroupLayout, buffers: &[wgpu::BindingResource]) -> wgpu::BindGroup {
    let entries: Vec<_> = buffers
        .iter()
        .enumerate()
        .map(|(i, b)| wgpu::BindGroupEntry { binding: i as u32, resource: b.clone() })
        .collect();
    device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(label), layout, entries: &entries })
}

/// The specialisation constants of a scene (pipeline-overridable constants in common.wgsl):
/// a term the scene does not use is compiled out rather than branched over per particle.
pub fn constants(params: &Params) -> Vec<(&'static str, f64)> {
    let flag = |on: bool| if on { 1.0 } else { 0.0 };
    vec![
        ("KERNEL", match params.kernel { Kernel::Mueller => 0.0, Kernel::CubicSpline => 1.0 }),
        ("EOS", match params.eos { EquationOfState::Linear => 0.0, EquationOfState::Tait => 1.0 }),
        ("CLAMP_NEGATIVE_PRESSURE", flag(params.clamp_negative_pressure)),
        ("CONSISTENT_WALL_PRESSURE", flag(params.boundary_pressure == BoundaryPressure::Consistent)),
        ("VISCOSITY", flag(params.uses_viscosity())),
        ("PLANES", flag(!params.planes.is_empty())),
        ("GRAVITY", flag(params.uses_gravity())),
        ("ADAPTIVE_DT", flag(params.adaptive.is_some())),
    ]
}

/// A compute pipeline with its bind-group layout.
pub struct Stage {
    pub pipeline: wgpu::ComputePipeline,
    pub layout: wgpu::BindGroupLayout,
}

/// Builds the pipeline of `entry` in stage file `name` with a layout of `uses`.
pub fn stage(device: &wgpu::Device, name: &str, entry: &str, uses: &[Use], constants: &[(&str, f64)]) -> Stage {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(name),
        source: wgpu::ShaderSource::Wgsl(stage_source(name).into()),
    });
    let layout = layout(device, name, uses);
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(name),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(entry),
        layout: Some(&pipeline_layout),
        module: &module,
        entry_point: Some(entry),
        compilation_options: wgpu::PipelineCompilationOptions { constants, zero_initialize_workgroup_memory: true },
        cache: None,
    });
    Stage { pipeline, layout }
}

/// Workgroup counts for `threads` threads: wraps into y beyond the per-dimension limit.
pub fn dispatch_size(threads: u64, per_group: u32, max_per_dim: u32) -> (u32, u32) {
    let groups = threads.div_ceil(per_group as u64).max(1);
    if groups <= max_per_dim as u64 {
        (groups as u32, 1)
    } else {
        let y = groups.div_ceil(max_per_dim as u64);
        (max_per_dim, y as u32)
    }
}
