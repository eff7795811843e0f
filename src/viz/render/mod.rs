//! Rendering of the particles with wgpu: sphere impostors coloured by a field (the `particles`
//! style) or a screen-space fluid surface (the `surface` style), drawn straight from the
//! simulation's GPU buffers, into an offscreen texture (frame dumps) or a window (`wgsph view`);
//! or the fluid surface reconstructed as a triangle mesh (the `mesh` style, frame dumps only).
//! The shaders are wgsl/render/particles.wgsl, range.wgsl, surface.wgsl and mesh.wgsl. Each
//! style, the spheres every style draws the walls with, and the colour range have a file of
//! their own; here they are assembled into the `Renderer`.

pub mod camera;
mod common;
pub mod frames;
mod mesh;
mod options;
mod particles;
mod range;
mod surface;

pub use camera::{Bounds, Camera};
pub use common::BACKGROUND;
pub use options::{parse_range, parse_resolution, ColorBy, RenderOptions, Style, Walls};

use crate::model::scene::Scene;
use crate::model::state::Snapshot;
use crate::solver::gpu::GpuContext;
use common::{depth_texture, field_is_vector, vec4_of, Fluid, Frame, FrameUniform};
use mesh::Mesh;
use particles::Spheres;
use range::ColorRange;
use surface::Surface;

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

/// What only the chosen style has; the particles style draws with the spheres alone.
enum StyleParts {
    Particles,
    Surface(Surface),
    Mesh(Mesh),
}

/// Draws particles with one device. Built once; `encode` records one picture.
pub struct Renderer {
    /// The device's context, for its error check (`GpuContext::check_device`).
    context: GpuContext,
    device: wgpu::Device,
    queue: wgpu::Queue,
    pub options: RenderOptions,
    pub camera: Camera,
    pub bounds: Bounds,
    frame: Frame,
    range: ColorRange,
    spheres: Spheres,
    style: StyleParts,
    depth: wgpu::TextureView,
    /// Buffers of particles handed over from the host (the CPU backend).
    uploaded: Option<ParticleBuffers>,
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
        let device = &ctx.device;
        let bounds = Bounds::of_scene(scene);
        let camera = Camera::for_scene(scene, options.width as f32 / options.height as f32);
        let frame = Frame::new(device);
        let range = ColorRange::new(device, ctx.storage_segment_bytes());
        let spheres = Spheres::new(device, &frame, color_format, &options, scene, walls);
        let style = match options.style {
            Style::Particles => StyleParts::Particles,
            Style::Surface => {
                StyleParts::Surface(Surface::new(&ctx.adapter, device, &frame, &spheres, color_format, options.width, options.height))
            }
            Style::Mesh => StyleParts::Mesh(Mesh::new(device, &frame, color_format, scene)),
        };
        let depth = depth_texture(device, options.width, options.height);
        Renderer {
            context: ctx.clone(),
            device: device.clone(),
            queue: ctx.queue.clone(),
            options,
            camera,
            bounds,
            frame,
            range,
            spheres,
            style,
            depth,
            uploaded: None,
        }
    }

    /// Changes the picture size (the window was resized).
    pub fn resize(&mut self, width: u32, height: u32) {
        self.options.width = width.max(1);
        self.options.height = height.max(1);
        self.depth = depth_texture(&self.device, self.options.width, self.options.height);
        if let StyleParts::Surface(s) = &mut self.style {
            s.resize(&self.device, &self.frame, self.options.width, self.options.height);
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
        if let StyleParts::Mesh(m) = &mut self.style {
            m.upload(&self.device, &self.queue, vertices, normals, triangles);
        }
    }

    /// For the mesh style: reconstructs the fluid surface of `s` (as `--surface-mesh-every`
    /// does) and uploads it. Does nothing in the other styles.
    pub fn reconstruct_mesh(&mut self, s: &Snapshot) -> anyhow::Result<()> {
        match &mut self.style {
            StyleParts::Mesh(m) => m.reconstruct(&self.device, &self.queue, s),
            _ => Ok(()),
        }
    }

    /// The fluid of `p` as the passes read it: the positions and the field of the options.
    fn fluid<'a>(&self, p: &'a ParticleBuffers) -> Fluid<'a> {
        let field = match self.options.color_by {
            ColorBy::Speed => &p.velocities,
            ColorBy::Density => &p.densities,
            ColorBy::Pressure => &p.pressures,
        };
        Fluid { positions: &p.positions, field, vector: field_is_vector(self.options.color_by), count: p.count }
    }

    /// Records one picture of `particles` into `target` (a view of a texture of the colour
    /// format and the size of the options). The mesh style draws the last uploaded mesh instead.
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, target: &wgpu::TextureView, particles: &ParticleBuffers) {
        let uniform = FrameUniform::new(&self.options, &self.camera, &self.bounds, self.spheres.fluid_radius, self.spheres.wall_radius);
        self.queue.write_buffer(&self.frame.buffer, 0, bytemuck::bytes_of(&uniform));
        let fluid = self.fluid(particles);
        // The mesh is not coloured by a field.
        let mesh = matches!(self.style, StyleParts::Mesh(_));
        if self.options.range.is_none() && fluid.count > 0 && !mesh {
            self.range.encode(&self.device, &self.queue, encoder, fluid, &self.frame.buffer);
        }
        let mut pass = match &self.style {
            StyleParts::Particles => self.spheres.encode(encoder, target, &self.depth, &self.frame, fluid),
            StyleParts::Surface(s) => s.encode(encoder, target, &self.depth, &self.frame, &self.spheres, fluid),
            StyleParts::Mesh(m) => m.encode(encoder, target, &self.depth, &self.frame),
        };
        // The walls last, into the style's final pass, so that faint walls blend over the fluid.
        self.spheres.draw_walls(&mut pass, &self.frame);
    }

    /// An error if the device reported one (a picture drawn after it is not to be trusted).
    pub fn check_device(&self) -> anyhow::Result<()> {
        self.context.check_device()
    }
    pub fn device(&self) -> &wgpu::Device {
        &self.device
    }
    pub fn queue(&self) -> &wgpu::Queue {
        &self.queue
    }
}
