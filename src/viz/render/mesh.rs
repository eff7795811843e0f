//! The `mesh` style: the fluid surface reconstructed as a triangle mesh (as
//! `--surface-mesh-every` writes it) and drawn shaded (render/mesh.wgsl); for frame dumps.

use super::common::{begin_pass, depth_state, opaque, render_pipeline, shader_module, Frame, PipelineSpec, BACKGROUND_CLEAR};
use crate::io::surface::{reconstruct, vertex_normals, SurfaceParameters};
use crate::model::scene::Scene;
use crate::model::state::Snapshot;

/// The mesh style's pipeline, its reconstruction parameters and the mesh to draw.
pub(super) struct Mesh {
    pipeline: wgpu::RenderPipeline,
    parameters: SurfaceParameters,
    /// Interleaved position and normal per vertex (6 f32).
    vertices: Option<wgpu::Buffer>,
    indices: Option<wgpu::Buffer>,
    index_count: u32,
}

impl Mesh {
    /// The mesh pipeline, drawing into textures of `color_format`, with no mesh yet.
    pub(super) fn new(device: &wgpu::Device, frame: &Frame, color_format: wgpu::TextureFormat, scene: &Scene) -> Self {
        let module = shader_module(device, "render_mesh", "render/mesh.wgsl");
        const VERTEX: [wgpu::VertexAttribute; 2] = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3];
        let buffers = [Some(wgpu::VertexBufferLayout { array_stride: 24, step_mode: wgpu::VertexStepMode::Vertex, attributes: &VERTEX })];
        Mesh {
            pipeline: render_pipeline(
                device,
                PipelineSpec {
                    label: "fluid mesh",
                    module: &module,
                    layout: &frame.pipeline_layout,
                    vertex: "vs_mesh",
                    buffers: &buffers,
                    fragment: "fs_mesh",
                    target: opaque(color_format),
                    depth: depth_state(wgpu::CompareFunction::Less, true),
                    constants: &[],
                },
            ),
            parameters: SurfaceParameters::for_scene(&scene.params(), scene.physics.particle_spacing),
            vertices: None,
            indices: None,
            index_count: 0,
        }
    }

    /// Copies a triangle mesh (positions, unit normals per vertex, triangles as vertex indices)
    /// to the GPU; the next pictures draw it. `Renderer::upload_mesh` checks that there is one
    /// normal per vertex.
    pub(super) fn upload(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        vertices: &[[f32; 3]],
        normals: &[[f32; 3]],
        triangles: &[[u32; 3]],
    ) {
        let interleaved: Vec<[f32; 6]> =
            vertices.iter().zip(normals).map(|(p, n)| [p[0], p[1], p[2], n[0], n[1], n[2]]).collect();
        // Buffers grow to fit and are reused while they do.
        let fit = |buffer: &mut Option<wgpu::Buffer>, bytes: &[u8], usage: wgpu::BufferUsages, label: &str| {
            if buffer.as_ref().is_none_or(|b| b.size() < bytes.len() as u64) {
                *buffer = Some(device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: (bytes.len() as u64).max(16),
                    usage: usage | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                }));
            }
            if !bytes.is_empty() {
                queue.write_buffer(buffer.as_ref().expect("made above"), 0, bytes);
            }
        };
        fit(&mut self.vertices, bytemuck::cast_slice(&interleaved), wgpu::BufferUsages::VERTEX, "render mesh vertices");
        fit(&mut self.indices, bytemuck::cast_slice(triangles), wgpu::BufferUsages::INDEX, "render mesh indices");
        self.index_count = 3 * triangles.len() as u32;
    }

    /// Reconstructs the fluid surface of `s` (as `--surface-mesh-every` does) and uploads it.
    pub(super) fn reconstruct(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, s: &Snapshot) -> anyhow::Result<()> {
        let mesh = reconstruct(&s.positions, &self.parameters)?;
        let normals = vertex_normals(&mesh);
        self.upload(device, queue, &mesh.vertices, &normals, &mesh.triangles);
        Ok(())
    }

    /// The mesh style's pass into `target`: the last uploaded mesh, if any. Returns the pass, for
    /// the walls.
    pub(super) fn encode<'e>(
        &self,
        encoder: &'e mut wgpu::CommandEncoder,
        target: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        frame: &Frame,
    ) -> wgpu::RenderPass<'e> {
        let mut pass = begin_pass(encoder, "fluid mesh", target, BACKGROUND_CLEAR, Some(depth));
        if let (Some(vertices), Some(indices), true) = (&self.vertices, &self.indices, self.index_count > 0) {
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &frame.group, &[]);
            pass.set_vertex_buffer(0, vertices.slice(..));
            pass.set_index_buffer(indices.slice(..), wgpu::IndexFormat::Uint32);
            pass.draw_indexed(0..self.index_count, 0, 0..1);
        }
        pass
    }
}
