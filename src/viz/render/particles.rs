//! The spheres: fluid and wall particles drawn as sphere impostors (render/particles.wgsl). The
//! fluid spheres are the `particles` style, the walls are drawn in every style, and the surface
//! style draws its first passes with the fluid spheres' vertex stage.

use super::common::{
    begin_pass, depth_state, field_is_vector, instance_layouts, opaque, render_pipeline, shader_module, vec4_of, Fluid, Frame,
    PipelineSpec, BACKGROUND_CLEAR,
};
use super::options::{RenderOptions, Style, Walls};
use crate::model::scene::Scene;
use wgpu::util::DeviceExt;

pub(super) struct Spheres {
    fluid_stage: FluidStage,
    /// The fluid shaded and coloured by its field (the particles style).
    fluid: wgpu::RenderPipeline,
    wall: wgpu::RenderPipeline,
    /// Wall particle positions (they never move, so they are uploaded once).
    walls: wgpu::Buffer,
    wall_count: u32,
    walls_hidden: bool,
    /// The sphere radii, which the frame uniform hands to every shader.
    pub fluid_radius: f32,
    pub wall_radius: f32,
}

/// The vertex stage of the fluid spheres, for the colouring field of the options.
struct FluidStage {
    module: wgpu::ShaderModule,
    layout: wgpu::PipelineLayout,
    vertex: &'static str,
    buffers: Vec<Option<wgpu::VertexBufferLayout<'static>>>,
}

impl FluidStage {
    fn pipeline(
        &self,
        device: &wgpu::Device,
        label: &str,
        fragment: &str,
        target: wgpu::ColorTargetState,
        depth: Option<wgpu::DepthStencilState>,
        constants: &[(&str, f64)],
    ) -> wgpu::RenderPipeline {
        render_pipeline(
            device,
            PipelineSpec {
                label,
                module: &self.module,
                layout: &self.layout,
                vertex: self.vertex,
                buffers: &self.buffers,
                fragment,
                target,
                depth,
                constants,
            },
        )
    }
}

impl Spheres {
    /// The sphere pipelines for `options`, drawing into textures of `color_format`, and the
    /// walls at the wall particle positions `walls`.
    pub(super) fn new(
        device: &wgpu::Device,
        frame: &Frame,
        color_format: wgpu::TextureFormat,
        options: &RenderOptions,
        scene: &Scene,
        walls: &[[f64; 3]],
    ) -> Self {
        let spacing = scene.physics.particle_spacing as f32;
        // Spheres of the particle spacing's diameter touch their lattice neighbours; the surface
        // style needs larger ones so that no gap between lattice neighbours lets the eye through
        // (the gap in the middle of a square of spheres closes at a radius of spacing / sqrt 2).
        let fluid_radius = if options.style == Style::Surface { 0.8 * spacing } else { 0.5 * spacing };
        let wall_radius = 0.5 * scene.wall_spacing() as f32;

        let fluid_stage = FluidStage {
            module: shader_module(device, "render_particles", "render/particles.wgsl"),
            layout: frame.pipeline_layout.clone(),
            vertex: if field_is_vector(options.color_by) { "vs_fluid_vector" } else { "vs_fluid_scalar" },
            buffers: instance_layouts(Some(options.color_by)),
        };
        let fluid = fluid_stage.pipeline(
            device,
            "fluid spheres",
            "fs_shaded",
            opaque(color_format),
            depth_state(wgpu::CompareFunction::Less, true),
            &[],
        );
        let wall = render_pipeline(
            device,
            PipelineSpec {
                label: "wall spheres",
                module: &fluid_stage.module,
                layout: &frame.pipeline_layout,
                vertex: "vs_wall",
                buffers: &instance_layouts(None),
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
        let wall_data: Vec<[f32; 4]> = walls.iter().map(|&p| vec4_of(p, 0.0)).collect();
        let walls_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("render walls"),
            contents: if wall_data.is_empty() { &[0u8; 16] } else { bytemuck::cast_slice(&wall_data) },
            usage: wgpu::BufferUsages::VERTEX,
        });
        Spheres {
            fluid_stage,
            fluid,
            wall,
            walls: walls_buffer,
            wall_count: walls.len() as u32,
            walls_hidden: options.walls == Walls::Hidden,
            fluid_radius,
            wall_radius,
        }
    }

    /// A pipeline of the fluid spheres with the fragment stage `fragment` of particles.wgsl.
    pub(super) fn fluid_pipeline(
        &self,
        device: &wgpu::Device,
        label: &str,
        fragment: &str,
        target: wgpu::ColorTargetState,
        depth: Option<wgpu::DepthStencilState>,
        constants: &[(&str, f64)],
    ) -> wgpu::RenderPipeline {
        self.fluid_stage.pipeline(device, label, fragment, target, depth, constants)
    }

    /// Draws the fluid spheres with `pipeline`, one of `fluid_pipeline`'s.
    pub(super) fn draw_fluid(&self, pass: &mut wgpu::RenderPass, pipeline: &wgpu::RenderPipeline, frame: &Frame, fluid: Fluid) {
        let n = fluid.count;
        if n > 0 {
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &frame.group, &[]);
            pass.set_vertex_buffer(0, fluid.positions.slice(..n as u64 * 16));
            pass.set_vertex_buffer(1, fluid.field.slice(..n as u64 * fluid.field_bytes()));
            pass.draw(0..6, 0..n);
        }
    }

    /// The particles style: the fluid spheres, shaded and coloured by their field, into
    /// `target`. Returns the pass, for the walls.
    pub(super) fn encode<'e>(
        &self,
        encoder: &'e mut wgpu::CommandEncoder,
        target: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        frame: &Frame,
        fluid: Fluid,
    ) -> wgpu::RenderPass<'e> {
        let mut pass = begin_pass(encoder, "particles", target, BACKGROUND_CLEAR, Some(depth));
        self.draw_fluid(&mut pass, &self.fluid, frame, fluid);
        pass
    }

    /// Draws the walls (unless hidden) into a style's last pass.
    pub(super) fn draw_walls(&self, pass: &mut wgpu::RenderPass, frame: &Frame) {
        if !self.walls_hidden && self.wall_count > 0 {
            pass.set_pipeline(&self.wall);
            pass.set_bind_group(0, &frame.group, &[]);
            pass.set_vertex_buffer(0, self.walls.slice(..));
            pass.draw(0..6, 0..self.wall_count);
        }
    }
}
