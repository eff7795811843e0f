//! What every style shares: the render shaders, the frame uniform and its binding, the fluid as
//! the passes read it, the depth buffer, and the helpers that build textures, pipelines and passes.

use super::camera::{Bounds, Camera};
use super::options::{ColorBy, RenderOptions, Walls};
use crate::solver::gpu::shaders::assemble;
use glam::Vec3;

/// The render shaders, by their path under wgsl/.
const SOURCES: &[(&str, &str)] = &[
    ("render/common.wgsl", include_str!("../../../wgsl/render/common.wgsl")),
    ("render/particles.wgsl", include_str!("../../../wgsl/render/particles.wgsl")),
    ("render/range.wgsl", include_str!("../../../wgsl/render/range.wgsl")),
    ("render/surface.wgsl", include_str!("../../../wgsl/render/surface.wgsl")),
    ("render/mesh.wgsl", include_str!("../../../wgsl/render/mesh.wgsl")),
];

/// A render shader with its includes (render files, or the simulation's shared ones).
pub(super) fn shader(path: &str) -> String {
    let lookup = |p: &str| SOURCES.iter().find(|s| s.0 == p).map(|s| s.1).or_else(|| crate::solver::gpu::shaders::source(p));
    assemble(lookup(path).unwrap_or_else(|| panic!("no render shader {path}")), &lookup)
}

/// A shader module of the render shader at `path` (under wgsl/), labelled `label`.
pub(super) fn shader_module(device: &wgpu::Device, label: &str, path: &str) -> wgpu::ShaderModule {
    device.create_shader_module(wgpu::ShaderModuleDescriptor { label: Some(label), source: wgpu::ShaderSource::Wgsl(shader(path).into()) })
}

/// The colour of the empty background, linear RGB (matches the surface shader's background).
pub const BACKGROUND: [f64; 3] = [0.02, 0.025, 0.035];
/// The background as the clear value of a picture.
pub(super) const BACKGROUND_CLEAR: wgpu::Color = wgpu::Color { r: BACKGROUND[0], g: BACKGROUND[1], b: BACKGROUND[2], a: 1.0 };
pub(super) const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// The uniform block `Frame` of render/common.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub(super) struct FrameUniform {
    view: [f32; 16],
    proj: [f32; 16],
    light: [f32; 4],
    sizes: [f32; 4],
    wall_color: [f32; 4],
    fluid_color: [f32; 4],
    viewport: [f32; 4],
    range_keys: [u32; 4],
}
/// Where the colour range reduction copies its keys into the frame uniform.
pub(super) const RANGE_KEYS_OFFSET: u64 = std::mem::offset_of!(FrameUniform, range_keys) as u64;

impl FrameUniform {
    /// The uniform of one picture of `bounds` through `camera`, with spheres of the given radii.
    pub(super) fn new(options: &RenderOptions, camera: &Camera, bounds: &Bounds, fluid_radius: f32, wall_radius: f32) -> Self {
        let aspect = options.width as f32 / options.height as f32;
        let view = camera.view();
        let proj = camera.projection(aspect, bounds);
        let light = (view * Vec3::new(-0.35, 1.0, 0.55).normalize().extend(0.0)).truncate().normalize();
        let (lo, hi) = options.range.unwrap_or((0.0, 1.0));
        let wall_alpha = if options.walls == Walls::Faint { 0.035 } else { 1.0 };
        FrameUniform {
            view: view.to_cols_array(),
            proj: proj.to_cols_array(),
            light: light.extend(0.0).to_array(),
            sizes: [fluid_radius, wall_radius, lo, hi],
            wall_color: [0.45, 0.45, 0.47, wall_alpha],
            // A water blue; absorption per metre scaled to the particle size so that a block a
            // few particles thick is already clearly tinted.
            fluid_color: [0.03, 0.22, 0.55, 0.6 / fluid_radius],
            viewport: [options.width as f32, options.height as f32, fluid_radius * 2.0, 24.0],
            range_keys: [0, 0, options.range.is_none() as u32, 0],
        }
    }
}

/// The frame uniform on the GPU, a bind group of it alone, and the layout of the pipelines that
/// bind nothing else (the spheres and the mesh).
pub(super) struct Frame {
    pub buffer: wgpu::Buffer,
    pub group: wgpu::BindGroup,
    pub pipeline_layout: wgpu::PipelineLayout,
}

impl Frame {
    pub(super) fn new(device: &wgpu::Device) -> Self {
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("render frame"),
            size: std::mem::size_of::<FrameUniform>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("render frame"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer { ty: wgpu::BufferBindingType::Uniform, has_dynamic_offset: false, min_binding_size: None },
                count: None,
            }],
        });
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("render frame"),
            layout: &layout,
            entries: &[wgpu::BindGroupEntry { binding: 0, resource: buffer.as_entire_binding() }],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("render particles"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        Frame { buffer, group, pipeline_layout }
    }
}

/// The fluid of one picture as the passes read it: positions (`vec4<f32>`) and the colouring
/// field (`vec4<f32>` if `vector`, else `f32`), `count` of each.
#[derive(Clone, Copy)]
pub(super) struct Fluid<'a> {
    pub positions: &'a wgpu::Buffer,
    pub field: &'a wgpu::Buffer,
    pub vector: bool,
    pub count: u32,
}

impl Fluid<'_> {
    /// Bytes of one value of the colouring field.
    pub(super) fn field_bytes(&self) -> u64 {
        if self.vector {
            16
        } else {
            4
        }
    }
}

pub(super) fn field_is_vector(c: ColorBy) -> bool {
    c == ColorBy::Speed
}

pub(super) fn vec4_of(v: [f64; 3], w: f32) -> [f32; 4] {
    [v[0] as f32, v[1] as f32, v[2] as f32, w]
}

pub(super) fn texture(device: &wgpu::Device, label: &str, w: u32, h: u32, format: wgpu::TextureFormat) -> wgpu::TextureView {
    device
        .create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        })
        .create_view(&Default::default())
}

/// The depth buffer every style draws with, sized to the picture.
pub(super) fn depth_texture(device: &wgpu::Device, w: u32, h: u32) -> wgpu::TextureView {
    texture(device, "render depth", w, h, DEPTH_FORMAT)
}

pub(super) fn depth_state(compare: wgpu::CompareFunction, write: bool) -> Option<wgpu::DepthStencilState> {
    Some(wgpu::DepthStencilState {
        format: DEPTH_FORMAT,
        depth_write_enabled: Some(write),
        depth_compare: Some(compare),
        stencil: Default::default(),
        bias: Default::default(),
    })
}

/// Vertex buffers of an instance: its position and (for the fluid) its colouring field.
pub(super) fn instance_layouts(field: Option<ColorBy>) -> Vec<Option<wgpu::VertexBufferLayout<'static>>> {
    const POSITION: [wgpu::VertexAttribute; 1] = wgpu::vertex_attr_array![0 => Float32x4];
    const VECTOR: [wgpu::VertexAttribute; 1] = wgpu::vertex_attr_array![1 => Float32x4];
    const SCALAR: [wgpu::VertexAttribute; 1] = wgpu::vertex_attr_array![1 => Float32];
    let mut out =
        vec![Some(wgpu::VertexBufferLayout { array_stride: 16, step_mode: wgpu::VertexStepMode::Instance, attributes: &POSITION })];
    if let Some(c) = field {
        out.push(Some(if field_is_vector(c) {
            wgpu::VertexBufferLayout { array_stride: 16, step_mode: wgpu::VertexStepMode::Instance, attributes: &VECTOR }
        } else {
            wgpu::VertexBufferLayout { array_stride: 4, step_mode: wgpu::VertexStepMode::Instance, attributes: &SCALAR }
        }));
    }
    out
}

pub(super) struct PipelineSpec<'a> {
    pub label: &'a str,
    pub module: &'a wgpu::ShaderModule,
    pub layout: &'a wgpu::PipelineLayout,
    pub vertex: &'a str,
    pub buffers: &'a [Option<wgpu::VertexBufferLayout<'a>>],
    pub fragment: &'a str,
    pub target: wgpu::ColorTargetState,
    pub depth: Option<wgpu::DepthStencilState>,
    pub constants: &'a [(&'a str, f64)],
}

pub(super) fn render_pipeline(device: &wgpu::Device, s: PipelineSpec) -> wgpu::RenderPipeline {
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(s.label),
        layout: Some(s.layout),
        vertex: wgpu::VertexState {
            module: s.module,
            entry_point: Some(s.vertex),
            compilation_options: wgpu::PipelineCompilationOptions { constants: s.constants, zero_initialize_workgroup_memory: false },
            buffers: s.buffers,
        },
        primitive: wgpu::PrimitiveState::default(),
        depth_stencil: s.depth,
        multisample: wgpu::MultisampleState::default(),
        fragment: Some(wgpu::FragmentState {
            module: s.module,
            entry_point: Some(s.fragment),
            compilation_options: wgpu::PipelineCompilationOptions { constants: s.constants, zero_initialize_workgroup_memory: false },
            targets: &[Some(s.target)],
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// A colour target of `format` written as is (no blending).
pub(super) fn opaque(format: wgpu::TextureFormat) -> wgpu::ColorTargetState {
    wgpu::ColorTargetState { format, blend: None, write_mask: wgpu::ColorWrites::ALL }
}

/// Begins a pass drawing into `target`, cleared to `clear`, and where given testing against
/// `depth`, cleared to the far plane. Every pass starts from a clear picture: nothing is kept
/// from the one before.
pub(super) fn begin_pass<'e>(
    encoder: &'e mut wgpu::CommandEncoder,
    label: &str,
    target: &wgpu::TextureView,
    clear: wgpu::Color,
    depth: Option<&wgpu::TextureView>,
) -> wgpu::RenderPass<'e> {
    encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view: target,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations { load: wgpu::LoadOp::Clear(clear), store: wgpu::StoreOp::Store },
        })],
        depth_stencil_attachment: depth.map(|view| wgpu::RenderPassDepthStencilAttachment {
            view,
            depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Store }),
            stencil_ops: None,
        }),
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}
