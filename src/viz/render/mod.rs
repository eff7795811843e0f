//! Rendering of the particles with wgpu: sphere impostors coloured by a field (the `particles`
//! style) or a screen-space fluid surface (the `surface` style), drawn straight from the
//! simulation's GPU buffers, into an offscreen texture (frame dumps) or a window (`wgsph view`);
//! or the fluid surface reconstructed as a triangle mesh (the `mesh` style, frame dumps only).
//! The shaders are wgsl/render/particles.wgsl, range.wgsl, surface.wgsl and mesh.wgsl.

pub mod camera;
pub mod frames;

pub use camera::{Bounds, Camera};

use crate::io::surface::{reconstruct, vertex_normals, SurfaceParameters};
use crate::model::scene::Scene;
use crate::model::state::Snapshot;
use crate::solver::gpu::shaders::{assemble, bind_group, buffer_range, dispatch_size, layout, Use};
use crate::solver::gpu::GpuContext;
use clap::ValueEnum;
use glam::Vec3;
use wgpu::util::DeviceExt;

/// The render shaders, by their path under wgsl/.
const SOURCES: &[(&str, &str)] = &[
    ("render/common.wgsl", include_str!("../../../wgsl/render/common.wgsl")),
    ("render/particles.wgsl", include_str!("../../../wgsl/render/particles.wgsl")),
    ("render/range.wgsl", include_str!("../../../wgsl/render/range.wgsl")),
    ("render/surface.wgsl", include_str!("../../../wgsl/render/surface.wgsl")),
    ("render/mesh.wgsl", include_str!("../../../wgsl/render/mesh.wgsl")),
];

/// A render shader with its includes (render files, or the simulation's shared ones).
fn shader(path: &str) -> String {
    let lookup = |p: &str| SOURCES.iter().find(|s| s.0 == p).map(|s| s.1).or_else(|| crate::solver::gpu::shaders::source(p));
    assemble(lookup(path).unwrap_or_else(|| panic!("no render shader {path}")), &lookup)
}

/// The colour of the empty background, linear RGB (matches the surface shader's background).
pub const BACKGROUND: [f64; 3] = [0.02, 0.025, 0.035];
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
const RANGE_WORKGROUP: u64 = 256;

#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum, Default)]
pub enum Style {
    /// Shaded spheres coloured by a field.
    #[default]
    Particles,
    /// A smoothed liquid surface (screen-space fluid rendering).
    Surface,
    /// The fluid surface reconstructed as a triangle mesh (as `--surface-mesh-every` writes it),
    /// shaded; for frame dumps.
    Mesh,
}

#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum, Default)]
pub enum ColorBy {
    #[default]
    Speed,
    Density,
    Pressure,
}

#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum, Default)]
pub enum Walls {
    /// Translucent, so the fluid shows through them.
    #[default]
    Faint,
    /// Not drawn.
    Hidden,
    /// Opaque.
    Solid,
}

/// What a picture shows and how.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderOptions {
    pub width: u32,
    pub height: u32,
    pub style: Style,
    pub color_by: ColorBy,
    /// A fixed colour range; None: each frame's smallest to largest value.
    pub range: Option<(f32, f32)>,
    pub walls: Walls,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions { width: 1280, height: 720, style: Style::Particles, color_by: ColorBy::Speed, range: None, walls: Walls::Faint }
    }
}

/// Parses `WIDTHxHEIGHT`.
pub fn parse_resolution(s: &str) -> Result<(u32, u32), String> {
    let err = || format!("'{s}' is not a resolution; write WIDTHxHEIGHT with each between 16 and 8192, e.g. 1280x720");
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(err)?;
    let w: u32 = w.trim().parse().map_err(|_| err())?;
    let h: u32 = h.trim().parse().map_err(|_| err())?;
    if !(16..=8192).contains(&w) || !(16..=8192).contains(&h) {
        return Err(err());
    }
    Ok((w, h))
}

/// Parses `MIN:MAX` for a fixed colour range.
pub fn parse_range(s: &str) -> Result<(f32, f32), String> {
    let err = || format!("'{s}' is not a colour range; write MIN:MAX with finite MIN < MAX, e.g. 0:2.5");
    let (a, b) = s.split_once(':').ok_or_else(err)?;
    let a: f32 = a.trim().parse().map_err(|_| err())?;
    let b: f32 = b.trim().parse().map_err(|_| err())?;
    if !(a.is_finite() && b.is_finite() && a < b) {
        return Err(err());
    }
    Ok((a, b))
}

/// The particle buffers a picture is drawn from, in whatever order they are kept (all four in
/// the same order): positions and velocities as `vec4<f32>`, densities and pressures as `f32`.
/// The simulation's own buffers on the GPU, or the renderer's copy of a host snapshot.
#[derive(Clone, Debug)]
pub struct ParticleBuffers {
    pub positions: wgpu::Buffer,
    pub velocities: wgpu::Buffer,
    pub densities: wgpu::Buffer,
    pub pressures: wgpu::Buffer,
    pub count: u32,
}

impl From<crate::solver::gpu::ParticleBuffers> for ParticleBuffers {
    fn from(p: crate::solver::gpu::ParticleBuffers) -> Self {
        ParticleBuffers { positions: p.positions, velocities: p.velocities, densities: p.densities, pressures: p.pressures, count: p.count }
    }
}

/// The uniform block `Frame` of render_particles.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct FrameUniform {
    view: [f32; 16],
    proj: [f32; 16],
    light: [f32; 4],
    sizes: [f32; 4],
    wall_color: [f32; 4],
    fluid_color: [f32; 4],
    viewport: [f32; 4],
    range_keys: [u32; 4],
}
const RANGE_KEYS_OFFSET: u64 = std::mem::offset_of!(FrameUniform, range_keys) as u64;

/// Textures of the surface style, sized to the picture.
struct SurfaceTargets {
    depth: [wgpu::TextureView; 2],
    thickness: wgpu::TextureView,
    /// Bind group reading depth[i] (and the thickness).
    groups: [wgpu::BindGroup; 2],
}

struct SurfacePipelines {
    linear_depth: wgpu::RenderPipeline,
    thickness: wgpu::RenderPipeline,
    blur: [wgpu::RenderPipeline; 2],
    composite: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
}

/// Draws particles with one device. Built once; `encode` records one picture.
pub struct Renderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    /// Bytes per storage binding of the colour-range reduction (`GpuContext::storage_segment_bytes`).
    segment_bytes: u64,
    pub options: RenderOptions,
    pub camera: Camera,
    pub bounds: Bounds,
    fluid_radius: f32,
    wall_radius: f32,
    frame: wgpu::Buffer,
    frame_group: wgpu::BindGroup,
    range_params: wgpu::Buffer,
    range_keys: wgpu::Buffer,
    range_pipeline: wgpu::ComputePipeline,
    range_layout: wgpu::BindGroupLayout,
    fluid: wgpu::RenderPipeline,
    wall: wgpu::RenderPipeline,
    walls: wgpu::Buffer,
    wall_count: u32,
    depth: wgpu::TextureView,
    /// Format of the linear depth of the surface style.
    depth_format: wgpu::TextureFormat,
    surface: Option<(SurfacePipelines, SurfaceTargets)>,
    /// Buffers of particles handed over from the host (the CPU backend).
    uploaded: Option<ParticleBuffers>,
    /// The pipeline and the last uploaded mesh of the mesh style.
    mesh: Option<MeshDraw>,
}

/// The mesh style's pipeline, its reconstruction parameters and the mesh to draw.
struct MeshDraw {
    pipeline: wgpu::RenderPipeline,
    parameters: SurfaceParameters,
    /// Interleaved position and normal per vertex (6 f32).
    vertices: Option<wgpu::Buffer>,
    indices: Option<wgpu::Buffer>,
    index_count: u32,
}

fn field_is_vector(c: ColorBy) -> bool {
    c == ColorBy::Speed
}

fn texture(device: &wgpu::Device, label: &str, w: u32, h: u32, format: wgpu::TextureFormat) -> wgpu::TextureView {
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

fn depth_state(compare: wgpu::CompareFunction, write: bool) -> Option<wgpu::DepthStencilState> {
    Some(wgpu::DepthStencilState {
        format: DEPTH_FORMAT,
        depth_write_enabled: Some(write),
        depth_compare: Some(compare),
        stencil: Default::default(),
        bias: Default::default(),
    })
}

/// Vertex buffers of an instance: its position and (for the fluid) its colouring field.
fn instance_layouts(field: Option<ColorBy>) -> Vec<Option<wgpu::VertexBufferLayout<'static>>> {
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

struct PipelineSpec<'a> {
    label: &'a str,
    module: &'a wgpu::ShaderModule,
    layout: &'a wgpu::PipelineLayout,
    vertex: &'a str,
    buffers: &'a [Option<wgpu::VertexBufferLayout<'a>>],
    fragment: &'a str,
    target: wgpu::ColorTargetState,
    depth: Option<wgpu::DepthStencilState>,
    constants: &'a [(&'a str, f64)],
}

fn render_pipeline(device: &wgpu::Device, s: PipelineSpec) -> wgpu::RenderPipeline {
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

fn vec4_of(v: [f64; 3], w: f32) -> [f32; 4] {
    [v[0] as f32, v[1] as f32, v[2] as f32, w]
}

impl Renderer {
    /// A renderer for `scene` drawing into textures of `color_format`; `walls` are the wall
    /// particle positions (they never move, so they are uploaded once).
    pub fn new(
        ctx: &GpuContext,
        color_format: wgpu::TextureFormat,
        options: RenderOptions,
        scene: &Scene,
        walls: &[[f64; 3]],
    ) -> Self {
        let (device, queue) = (&ctx.device, &ctx.queue);
        // Linear depth wants 32-bit floats; where they cannot be rendered to (some OpenGL
        // adapters), it is kept as the sum of two half floats (about 22 bits of mantissa).
        let depth_format = if ctx.adapter.get_texture_format_features(wgpu::TextureFormat::R32Float).allowed_usages.contains(wgpu::TextureUsages::RENDER_ATTACHMENT) {
            wgpu::TextureFormat::R32Float
        } else {
            wgpu::TextureFormat::Rg16Float
        };
        let split_depth = [("SPLIT_DEPTH", if depth_format == wgpu::TextureFormat::R32Float { 0.0 } else { 1.0 })];
        let bounds = Bounds::of_scene(scene);
        let camera = Camera::for_scene(scene, options.width as f32 / options.height as f32);
        let spacing = scene.physics.particle_spacing as f32;
        // Spheres of the particle spacing's diameter touch their lattice neighbours; the surface
        // style needs larger ones so that no gap between lattice neighbours lets the eye through
        // (the gap in the middle of a square of spheres closes at a radius of spacing / sqrt 2).
        let fluid_radius = if options.style == Style::Surface { 0.8 * spacing } else { 0.5 * spacing };
        let wall_radius = 0.5 * scene.wall_spacing() as f32;

        let frame = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("render frame"),
            size: std::mem::size_of::<FrameUniform>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let frame_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("render frame"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer { ty: wgpu::BufferBindingType::Uniform, has_dynamic_offset: false, min_binding_size: None },
                count: None,
            }],
        });
        let frame_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("render frame"),
            layout: &frame_layout,
            entries: &[wgpu::BindGroupEntry { binding: 0, resource: frame.as_entire_binding() }],
        });

        // The automatic colour range.
        let range_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("render_range"),
            source: wgpu::ShaderSource::Wgsl(shader("render/range.wgsl").into()),
        });
        let range_layout = layout(device, "render_range", &[Use::Uniform, Use::Read, Use::ReadWrite]);
        let range_pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("render_range"),
            layout: Some(&device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("render_range"),
                bind_group_layouts: &[Some(&range_layout)],
                immediate_size: 0,
            })),
            module: &range_module,
            entry_point: Some("range"),
            compilation_options: Default::default(),
            cache: None,
        });
        let range_params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("render range params"),
            size: 16,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let range_keys = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("render range keys"),
            size: 16,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });

        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("render_particles"),
            source: wgpu::ShaderSource::Wgsl(shader("render/particles.wgsl").into()),
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("render particles"),
            bind_group_layouts: &[Some(&frame_layout)],
            immediate_size: 0,
        });
        let fluid_vs = if field_is_vector(options.color_by) { "vs_fluid_vector" } else { "vs_fluid_scalar" };
        let fluid_buffers = instance_layouts(Some(options.color_by));
        let wall_buffers = instance_layouts(None);
        let opaque = wgpu::ColorTargetState { format: color_format, blend: None, write_mask: wgpu::ColorWrites::ALL };
        let fluid = render_pipeline(
            device,
            PipelineSpec {
                label: "fluid spheres",
                module: &module,
                layout: &pipeline_layout,
                vertex: fluid_vs,
                buffers: &fluid_buffers,
                fragment: "fs_shaded",
                target: opaque.clone(),
                depth: depth_state(wgpu::CompareFunction::Less, true),
                constants: &[],
            },
        );
        let wall = render_pipeline(
            device,
            PipelineSpec {
                label: "wall spheres",
                module: &module,
                layout: &pipeline_layout,
                vertex: "vs_wall",
                buffers: &wall_buffers,
                fragment: "fs_shaded",
                target: wgpu::ColorTargetState {
                    format: color_format,
                    blend: (options.walls == Walls::Faint).then_some(wgpu::BlendState::ALPHA_BLENDING),
                    write_mask: wgpu::ColorWrites::ALL,
                },
                depth: depth_state(wgpu::CompareFunction::Less, options.walls == Walls::Solid),
                constants: &[],
            },
        );

        let surface = (options.style == Style::Surface).then(|| {
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("render surface"),
                entries: &[
                    wgpu::BindGroupLayoutEntry {
                        binding: 0,
                        visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                        ty: wgpu::BindingType::Buffer {
                            ty: wgpu::BufferBindingType::Uniform,
                            has_dynamic_offset: false,
                            min_binding_size: None,
                        },
                        count: None,
                    },
                    texture_entry(1),
                    texture_entry(2),
                ],
            });
            let surface_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("render_surface"),
                source: wgpu::ShaderSource::Wgsl(shader("render/surface.wgsl").into()),
            });
            let surface_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("render surface"),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            let r32 = wgpu::ColorTargetState { format: depth_format, blend: None, write_mask: wgpu::ColorWrites::ALL };
            let add = wgpu::BlendComponent {
                src_factor: wgpu::BlendFactor::One,
                dst_factor: wgpu::BlendFactor::One,
                operation: wgpu::BlendOperation::Add,
            };
            let pipelines = SurfacePipelines {
                linear_depth: render_pipeline(
                    device,
                    PipelineSpec {
                        label: "fluid depth",
                        module: &module,
                        layout: &pipeline_layout,
                        vertex: fluid_vs,
                        buffers: &fluid_buffers,
                        fragment: "fs_linear_depth",
                        target: r32.clone(),
                        depth: depth_state(wgpu::CompareFunction::Less, true),
                        constants: &split_depth,
                    },
                ),
                thickness: render_pipeline(
                    device,
                    PipelineSpec {
                        label: "fluid thickness",
                        module: &module,
                        layout: &pipeline_layout,
                        vertex: fluid_vs,
                        buffers: &fluid_buffers,
                        fragment: "fs_thickness",
                        target: wgpu::ColorTargetState {
                            format: wgpu::TextureFormat::R16Float,
                            blend: Some(wgpu::BlendState { color: add, alpha: add }),
                            write_mask: wgpu::ColorWrites::ALL,
                        },
                        depth: None,
                        constants: &[],
                    },
                ),
                blur: [true, false].map(|x| {
                    render_pipeline(
                        device,
                        PipelineSpec {
                            label: "depth blur",
                            module: &surface_module,
                            layout: &surface_layout,
                            vertex: "vs_fullscreen",
                            buffers: &[],
                            fragment: "fs_blur",
                            target: r32.clone(),
                            depth: None,
                            constants: &[("BLUR_AXIS_X", if x { 1.0 } else { 0.0 }), split_depth[0]],
                        },
                    )
                }),
                composite: render_pipeline(
                    device,
                    PipelineSpec {
                        label: "surface composite",
                        module: &surface_module,
                        layout: &surface_layout,
                        vertex: "vs_fullscreen",
                        buffers: &[],
                        fragment: "fs_composite",
                        target: opaque.clone(),
                        depth: depth_state(wgpu::CompareFunction::Always, true),
                        constants: &split_depth,
                    },
                ),
                layout,
            };
            let targets = surface_targets(device, &pipelines.layout, &frame, depth_format, options.width, options.height);
            (pipelines, targets)
        });

        let mesh = (options.style == Style::Mesh).then(|| {
            let mesh_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("render_mesh"),
                source: wgpu::ShaderSource::Wgsl(shader("render/mesh.wgsl").into()),
            });
            const VERTEX: [wgpu::VertexAttribute; 2] = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3];
            let buffers =
                [Some(wgpu::VertexBufferLayout { array_stride: 24, step_mode: wgpu::VertexStepMode::Vertex, attributes: &VERTEX })];
            MeshDraw {
                pipeline: render_pipeline(
                    device,
                    PipelineSpec {
                        label: "fluid mesh",
                        module: &mesh_module,
                        layout: &pipeline_layout,
                        vertex: "vs_mesh",
                        buffers: &buffers,
                        fragment: "fs_mesh",
                        target: opaque.clone(),
                        depth: depth_state(wgpu::CompareFunction::Less, true),
                        constants: &[],
                    },
                ),
                parameters: SurfaceParameters::for_scene(&scene.params(), scene.physics.particle_spacing),
                vertices: None,
                indices: None,
                index_count: 0,
            }
        });

        let wall_data: Vec<[f32; 4]> = walls.iter().map(|&p| vec4_of(p, 0.0)).collect();
        let walls_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("render walls"),
            contents: if wall_data.is_empty() { &[0u8; 16] } else { bytemuck::cast_slice(&wall_data) },
            usage: wgpu::BufferUsages::VERTEX,
        });
        let depth = depth_texture(device, options.width, options.height);
        Renderer {
            device: device.clone(),
            queue: queue.clone(),
            segment_bytes: ctx.storage_segment_bytes(),
            camera,
            bounds,
            fluid_radius,
            wall_radius,
            frame,
            frame_group,
            range_params,
            range_keys,
            range_pipeline,
            range_layout,
            fluid,
            wall,
            walls: walls_buffer,
            wall_count: walls.len() as u32,
            depth,
            depth_format,
            surface,
            uploaded: None,
            mesh,
            options,
        }
    }

    /// Changes the picture size (the window was resized).
    pub fn resize(&mut self, width: u32, height: u32) {
        self.options.width = width.max(1);
        self.options.height = height.max(1);
        self.depth = depth_texture(&self.device, self.options.width, self.options.height);
        if let Some((p, t)) = &mut self.surface {
            *t = surface_targets(&self.device, &p.layout, &self.frame, self.depth_format, self.options.width, self.options.height);
        }
    }

    /// Copies particles held by the host to the renderer's own buffers (for the CPU backend).
    pub fn upload(&mut self, s: &Snapshot) -> ParticleBuffers {
        let n = s.len();
        let positions: Vec<[f32; 4]> = s.positions.iter().map(|&p| vec4_of(p, 0.0)).collect();
        let velocities: Vec<[f32; 4]> = s.velocities.iter().map(|&v| vec4_of(v, 0.0)).collect();
        let densities: Vec<f32> = s.densities.iter().map(|&v| v as f32).collect();
        let pressures: Vec<f32> = s.pressures.iter().map(|&v| v as f32).collect();
        let fits = self.uploaded.as_ref().is_some_and(|u| u.count as usize == n);
        if !fits {
            let make = |label, bytes: u64| {
                self.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: bytes.max(16),
                    usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                })
            };
            let n = n as u64;
            self.uploaded = Some(ParticleBuffers {
                positions: make("render positions", n * 16),
                velocities: make("render velocities", n * 16),
                densities: make("render densities", n * 4),
                pressures: make("render pressures", n * 4),
                count: n as u32,
            });
        }
        let u = self.uploaded.clone().expect("made above");
        if n > 0 {
            self.queue.write_buffer(&u.positions, 0, bytemuck::cast_slice(&positions));
            self.queue.write_buffer(&u.velocities, 0, bytemuck::cast_slice(&velocities));
            self.queue.write_buffer(&u.densities, 0, bytemuck::cast_slice(&densities));
            self.queue.write_buffer(&u.pressures, 0, bytemuck::cast_slice(&pressures));
        }
        u
    }

    /// Hands a triangle mesh (positions, unit normals per vertex, triangles as vertex indices) to
    /// the mesh style; the next pictures draw it. Does nothing in the other styles.
    pub fn upload_mesh(&mut self, vertices: &[[f32; 3]], normals: &[[f32; 3]], triangles: &[[u32; 3]]) {
        assert_eq!(vertices.len(), normals.len(), "one normal per vertex");
        let Some(m) = &mut self.mesh else { return };
        let interleaved: Vec<[f32; 6]> =
            vertices.iter().zip(normals).map(|(p, n)| [p[0], p[1], p[2], n[0], n[1], n[2]]).collect();
        // Buffers grow to fit and are reused while they do.
        let fit = |buffer: &mut Option<wgpu::Buffer>, bytes: &[u8], usage: wgpu::BufferUsages, label: &str| {
            if buffer.as_ref().is_none_or(|b| b.size() < bytes.len() as u64) {
                *buffer = Some(self.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: (bytes.len() as u64).max(16),
                    usage: usage | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                }));
            }
            if !bytes.is_empty() {
                self.queue.write_buffer(buffer.as_ref().expect("made above"), 0, bytes);
            }
        };
        fit(&mut m.vertices, bytemuck::cast_slice(&interleaved), wgpu::BufferUsages::VERTEX, "render mesh vertices");
        fit(&mut m.indices, bytemuck::cast_slice(triangles), wgpu::BufferUsages::INDEX, "render mesh indices");
        m.index_count = 3 * triangles.len() as u32;
    }

    /// For the mesh style: reconstructs the fluid surface of `s` (as `--surface-mesh-every`
    /// does) and uploads it. Does nothing in the other styles.
    pub fn reconstruct_mesh(&mut self, s: &Snapshot) -> anyhow::Result<()> {
        let Some(m) = &self.mesh else { return Ok(()) };
        let mesh = reconstruct(&s.positions, &m.parameters)?;
        let normals = vertex_normals(&mesh);
        self.upload_mesh(&mesh.vertices, &normals, &mesh.triangles);
        Ok(())
    }

    fn field<'a>(&self, p: &'a ParticleBuffers) -> &'a wgpu::Buffer {
        match self.options.color_by {
            ColorBy::Speed => &p.velocities,
            ColorBy::Density => &p.densities,
            ColorBy::Pressure => &p.pressures,
        }
    }

    fn frame_uniform(&self) -> FrameUniform {
        let aspect = self.options.width as f32 / self.options.height as f32;
        let view = self.camera.view();
        let proj = self.camera.projection(aspect, &self.bounds);
        let light = (view * Vec3::new(-0.35, 1.0, 0.55).normalize().extend(0.0)).truncate().normalize();
        let (lo, hi) = self.options.range.unwrap_or((0.0, 1.0));
        let wall_alpha = if self.options.walls == Walls::Faint { 0.035 } else { 1.0 };
        FrameUniform {
            view: view.to_cols_array(),
            proj: proj.to_cols_array(),
            light: light.extend(0.0).to_array(),
            sizes: [self.fluid_radius, self.wall_radius, lo, hi],
            wall_color: [0.45, 0.45, 0.47, wall_alpha],
            // A water blue; absorption per metre scaled to the particle size so that a block a
            // few particles thick is already clearly tinted.
            fluid_color: [0.03, 0.22, 0.55, 0.6 / self.fluid_radius],
            viewport: [self.options.width as f32, self.options.height as f32, self.fluid_radius * 2.0, 24.0],
            range_keys: [0, 0, self.options.range.is_none() as u32, 0],
        }
    }

    /// Records one picture of `particles` into `target` (a view of a texture of the colour
    /// format and the size of the options). The mesh style draws the last uploaded mesh instead.
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, target: &wgpu::TextureView, particles: &ParticleBuffers) {
        self.queue.write_buffer(&self.frame, 0, bytemuck::bytes_of(&self.frame_uniform()));
        let n = particles.count;
        if self.options.range.is_none() && n > 0 && self.mesh.is_none() {
            self.queue.write_buffer(&self.range_params, 0, bytemuck::cast_slice(&[n, field_is_vector(self.options.color_by) as u32, 0, 0]));
            encoder.clear_buffer(&self.range_keys, 0, None);
            // One dispatch per segment of the field, so that no binding exceeds the adapter's
            // storage binding size however many particles there are.
            let value_bytes = if field_is_vector(self.options.color_by) { 16 } else { 4 };
            let per_segment = self.segment_bytes / value_bytes;
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("colour range"), timestamp_writes: None });
            pass.set_pipeline(&self.range_pipeline);
            for first in (0..n as u64).step_by(per_segment as usize) {
                let count = per_segment.min(n as u64 - first);
                let values = buffer_range(self.field(particles), first * value_bytes, count * value_bytes);
                let group = bind_group(
                    &self.device,
                    "render_range",
                    &self.range_layout,
                    &[self.range_params.as_entire_binding(), values, self.range_keys.as_entire_binding()],
                );
                let (x, y) = dispatch_size(count, RANGE_WORKGROUP as u32, self.device.limits().max_compute_workgroups_per_dimension);
                pass.set_bind_group(0, &group, &[]);
                pass.dispatch_workgroups(x, y, 1);
            }
            drop(pass);
            encoder.copy_buffer_to_buffer(&self.range_keys, 0, &self.frame, RANGE_KEYS_OFFSET, 8);
        }
        let clear = wgpu::Color { r: BACKGROUND[0], g: BACKGROUND[1], b: BACKGROUND[2], a: 1.0 };
        let depth_clear = wgpu::RenderPassDepthStencilAttachment {
            view: &self.depth,
            depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Store }),
            stencil_ops: None,
        };
        let color = |view, load| wgpu::RenderPassColorAttachment {
            view,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations { load, store: wgpu::StoreOp::Store },
        };
        let field = self.field(particles);
        let draw_fluid = |pass: &mut wgpu::RenderPass, pipeline: &wgpu::RenderPipeline| {
            if n > 0 {
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, &self.frame_group, &[]);
                pass.set_vertex_buffer(0, particles.positions.slice(..n as u64 * 16));
                let field_bytes = if field_is_vector(self.options.color_by) { 16 } else { 4 };
                pass.set_vertex_buffer(1, field.slice(..n as u64 * field_bytes));
                pass.draw(0..6, 0..n);
            }
        };
        if let Some((p, t)) = &self.surface {
            let empty = wgpu::Color { r: 0.0, g: 0.0, b: 0.0, a: 0.0 };
            // The nearest sphere depth, then the summed thickness.
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("fluid depth"),
                color_attachments: &[Some(color(&t.depth[0], wgpu::LoadOp::Clear(empty)))],
                depth_stencil_attachment: Some(depth_clear.clone()),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            draw_fluid(&mut pass, &p.linear_depth);
            drop(pass);
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("fluid thickness"),
                color_attachments: &[Some(color(&t.thickness, wgpu::LoadOp::Clear(empty)))],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            draw_fluid(&mut pass, &p.thickness);
            drop(pass);
            // Rounds of the separable bilateral filter: 0 -> 1 along x, 1 -> 0 along y.
            for _ in 0..3 {
                for (axis, (from, to)) in [(0usize, 1usize), (1, 0)].into_iter().enumerate() {
                    let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                        label: Some("depth blur"),
                        color_attachments: &[Some(color(&t.depth[to], wgpu::LoadOp::Clear(empty)))],
                        depth_stencil_attachment: None,
                        timestamp_writes: None,
                        occlusion_query_set: None,
                        multiview_mask: None,
                    });
                    pass.set_pipeline(&p.blur[axis]);
                    pass.set_bind_group(0, &t.groups[from], &[]);
                    pass.draw(0..3, 0..1);
                }
            }
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("surface"),
                color_attachments: &[Some(color(target, wgpu::LoadOp::Clear(clear)))],
                depth_stencil_attachment: Some(depth_clear),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&p.composite);
            pass.set_bind_group(0, &t.groups[0], &[]);
            pass.draw(0..3, 0..1);
            self.draw_walls(&mut pass);
        } else if let Some(m) = &self.mesh {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("fluid mesh"),
                color_attachments: &[Some(color(target, wgpu::LoadOp::Clear(clear)))],
                depth_stencil_attachment: Some(depth_clear),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            if let (Some(vertices), Some(indices), true) = (&m.vertices, &m.indices, m.index_count > 0) {
                pass.set_pipeline(&m.pipeline);
                pass.set_bind_group(0, &self.frame_group, &[]);
                pass.set_vertex_buffer(0, vertices.slice(..));
                pass.set_index_buffer(indices.slice(..), wgpu::IndexFormat::Uint32);
                pass.draw_indexed(0..m.index_count, 0, 0..1);
            }
            self.draw_walls(&mut pass);
        } else {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("particles"),
                color_attachments: &[Some(color(target, wgpu::LoadOp::Clear(clear)))],
                depth_stencil_attachment: Some(depth_clear),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            draw_fluid(&mut pass, &self.fluid);
            self.draw_walls(&mut pass);
        }
    }

    fn draw_walls(&self, pass: &mut wgpu::RenderPass) {
        if self.options.walls != Walls::Hidden && self.wall_count > 0 {
            pass.set_pipeline(&self.wall);
            pass.set_bind_group(0, &self.frame_group, &[]);
            pass.set_vertex_buffer(0, self.walls.slice(..));
            pass.draw(0..6, 0..self.wall_count);
        }
    }

    pub fn device(&self) -> &wgpu::Device {
        &self.device
    }
    pub fn queue(&self) -> &wgpu::Queue {
        &self.queue
    }
}

fn texture_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::FRAGMENT,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable: false },
            view_dimension: wgpu::TextureViewDimension::D2,
            multisampled: false,
        },
        count: None,
    }
}

fn depth_texture(device: &wgpu::Device, w: u32, h: u32) -> wgpu::TextureView {
    texture(device, "render depth", w, h, DEPTH_FORMAT)
}

fn surface_targets(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    frame: &wgpu::Buffer,
    depth_format: wgpu::TextureFormat,
    w: u32,
    h: u32,
) -> SurfaceTargets {
    let depth = [0, 1].map(|i| texture(device, &format!("surface depth {i}"), w, h, depth_format));
    let thickness = texture(device, "surface thickness", w, h, wgpu::TextureFormat::R16Float);
    let groups = [0, 1].map(|i| {
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("render surface"),
            layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: frame.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&depth[i]) },
                wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(&thickness) },
            ],
        })
    });
    SurfaceTargets { depth, thickness, groups }
}
