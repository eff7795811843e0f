//! The `surface` style: screen-space fluid rendering (render/surface.wgsl). The fluid spheres
//! leave their nearest depth and summed thickness in textures the size of the picture; the depth
//! is smoothed in rounds of a bilateral filter, and a full-screen pass shades the surface.

use super::common::{begin_pass, depth_state, opaque, render_pipeline, shader_module, texture, Fluid, Frame, PipelineSpec, BACKGROUND_CLEAR};
use super::particles::Spheres;

pub(super) struct Surface {
    linear_depth: wgpu::RenderPipeline,
    thickness: wgpu::RenderPipeline,
    /// Along x, along y.
    blur: [wgpu::RenderPipeline; 2],
    composite: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    /// Format of the linear depth.
    depth_format: wgpu::TextureFormat,
    targets: Targets,
}

/// Textures of the surface style, sized to the picture.
struct Targets {
    depth: [wgpu::TextureView; 2],
    thickness: wgpu::TextureView,
    /// Bind group reading depth[i] (and the thickness).
    groups: [wgpu::BindGroup; 2],
}

impl Surface {
    /// The pipelines of the surface style, drawing into textures of `color_format`, and its
    /// textures for pictures of `width` x `height`.
    pub(super) fn new(
        adapter: &wgpu::Adapter,
        device: &wgpu::Device,
        frame: &Frame,
        spheres: &Spheres,
        color_format: wgpu::TextureFormat,
        width: u32,
        height: u32,
    ) -> Self {
        // Linear depth wants 32-bit floats; where they cannot be rendered to (some OpenGL
        // adapters), it is kept as the sum of two half floats (about 22 bits of mantissa).
        let depth_format = if adapter.get_texture_format_features(wgpu::TextureFormat::R32Float).allowed_usages.contains(wgpu::TextureUsages::RENDER_ATTACHMENT) {
            wgpu::TextureFormat::R32Float
        } else {
            wgpu::TextureFormat::Rg16Float
        };
        let split_depth = [("SPLIT_DEPTH", if depth_format == wgpu::TextureFormat::R32Float { 0.0 } else { 1.0 })];
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("render surface"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                    ty: wgpu::BindingType::Buffer { ty: wgpu::BufferBindingType::Uniform, has_dynamic_offset: false, min_binding_size: None },
                    count: None,
                },
                texture_entry(1),
                texture_entry(2),
            ],
        });
        let module = shader_module(device, "render_surface", "render/surface.wgsl");
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("render surface"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let r32 = opaque(depth_format);
        let add = wgpu::BlendComponent { src_factor: wgpu::BlendFactor::One, dst_factor: wgpu::BlendFactor::One, operation: wgpu::BlendOperation::Add };
        let linear_depth = spheres.fluid_pipeline(
            device,
            "fluid depth",
            "fs_linear_depth",
            r32.clone(),
            depth_state(wgpu::CompareFunction::Less, true),
            &split_depth,
        );
        let thickness = spheres.fluid_pipeline(
            device,
            "fluid thickness",
            "fs_thickness",
            wgpu::ColorTargetState {
                format: wgpu::TextureFormat::R16Float,
                blend: Some(wgpu::BlendState { color: add, alpha: add }),
                write_mask: wgpu::ColorWrites::ALL,
            },
            None,
            &[],
        );
        let blur = [true, false].map(|x| {
            render_pipeline(
                device,
                PipelineSpec {
                    label: "depth blur",
                    module: &module,
                    layout: &pipeline_layout,
                    vertex: "vs_fullscreen",
                    buffers: &[],
                    fragment: "fs_blur",
                    target: r32.clone(),
                    depth: None,
                    constants: &[("BLUR_AXIS_X", if x { 1.0 } else { 0.0 }), split_depth[0]],
                },
            )
        });
        let composite = render_pipeline(
            device,
            PipelineSpec {
                label: "surface composite",
                module: &module,
                layout: &pipeline_layout,
                vertex: "vs_fullscreen",
                buffers: &[],
                fragment: "fs_composite",
                target: opaque(color_format),
                depth: depth_state(wgpu::CompareFunction::Always, true),
                constants: &split_depth,
            },
        );
        let targets = Targets::new(device, &layout, frame, depth_format, width, height);
        Surface { linear_depth, thickness, blur, composite, layout, depth_format, targets }
    }

    /// Remakes the textures for pictures of `width` x `height`.
    pub(super) fn resize(&mut self, device: &wgpu::Device, frame: &Frame, width: u32, height: u32) {
        self.targets = Targets::new(device, &self.layout, frame, self.depth_format, width, height);
    }

    /// The surface style's passes, the last of them into `target`. Returns that pass, for the
    /// walls.
    pub(super) fn encode<'e>(
        &self,
        encoder: &'e mut wgpu::CommandEncoder,
        target: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        frame: &Frame,
        spheres: &Spheres,
        fluid: Fluid,
    ) -> wgpu::RenderPass<'e> {
        let t = &self.targets;
        let empty = wgpu::Color::TRANSPARENT;
        // The nearest sphere depth, then the summed thickness.
        let mut pass = begin_pass(encoder, "fluid depth", &t.depth[0], empty, Some(depth));
        spheres.draw_fluid(&mut pass, &self.linear_depth, frame, fluid);
        drop(pass);
        let mut pass = begin_pass(encoder, "fluid thickness", &t.thickness, empty, None);
        spheres.draw_fluid(&mut pass, &self.thickness, frame, fluid);
        drop(pass);
        // Rounds of the separable bilateral filter: 0 -> 1 along x, 1 -> 0 along y.
        for _ in 0..3 {
            for (axis, (from, to)) in [(0usize, 1usize), (1, 0)].into_iter().enumerate() {
                let mut pass = begin_pass(encoder, "depth blur", &t.depth[to], empty, None);
                pass.set_pipeline(&self.blur[axis]);
                pass.set_bind_group(0, &t.groups[from], &[]);
                pass.draw(0..3, 0..1);
            }
        }
        let mut pass = begin_pass(encoder, "surface", target, BACKGROUND_CLEAR, Some(depth));
        pass.set_pipeline(&self.composite);
        pass.set_bind_group(0, &t.groups[0], &[]);
        pass.draw(0..3, 0..1);
        pass
    }
}

impl Targets {
    fn new(
        device: &wgpu::Device,
        layout: &wgpu::BindGroupLayout,
        frame: &Frame,
        depth_format: wgpu::TextureFormat,
        w: u32,
        h: u32,
    ) -> Self {
        let depth = [0, 1].map(|i| texture(device, &format!("surface depth {i}"), w, h, depth_format));
        let thickness = texture(device, "surface thickness", w, h, wgpu::TextureFormat::R16Float);
        let groups = [0, 1].map(|i| {
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("render surface"),
                layout,
                entries: &[
                    wgpu::BindGroupEntry { binding: 0, resource: frame.buffer.as_entire_binding() },
                    wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&depth[i]) },
                    wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(&thickness) },
                ],
            })
        });
        Targets { depth, thickness, groups }
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
