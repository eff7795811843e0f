//! Shader assembly and compute pipelines, built once per scene.
//!
//! WGSL has no include: a stage file names the files it needs with `//! include PATH` lines
//! (paths under wgsl/), which [`assemble`] replaces by their text, each file once. Nor does it
//! unroll: `//! unroll N STATEMENT` stands for N copies of STATEMENT with `{k}` replaced by 0 to
//! N - 1 (a subgroup shuffle's lane must be a constant to compile to a register permutation).
//! A stage declares its storage arrays with `//! array NAME: TYPE, ACCESS` lines, from which the host
//! generates the bindings and accessors ([`ArrayDecl`]); the arrays' lengths and buffers are
//! then given by name.

use super::device::{GpuContext, GpuError};
use crate::model::params::Params;
use crate::model::scene::{BoundaryPressure, EquationOfState, Kernel};

/// Every WGSL file of the simulation, by its path under wgsl/.
pub const SOURCES: &[(&str, &str)] = &[
    ("shared/common.wgsl", include_str!("../../../wgsl/shared/common.wgsl")),
    ("shared/reduce.wgsl", include_str!("../../../wgsl/shared/reduce.wgsl")),
    ("shared/adaptive_dt.wgsl", include_str!("../../../wgsl/shared/adaptive_dt.wgsl")),
    ("shared/density_write.wgsl", include_str!("../../../wgsl/shared/density_write.wgsl")),
    ("shared/density_write_tiled.wgsl", include_str!("../../../wgsl/shared/density_write_tiled.wgsl")),
    ("shared/status_max.wgsl", include_str!("../../../wgsl/shared/status_max.wgsl")),
    ("shared/tiles.wgsl", include_str!("../../../wgsl/shared/tiles.wgsl")),
    ("shared/tiles_walls.wgsl", include_str!("../../../wgsl/shared/tiles_walls.wgsl")),
    ("shared/neighbour_lists.wgsl", include_str!("../../../wgsl/shared/neighbour_lists.wgsl")),
    ("shared/list_walk.wgsl", include_str!("../../../wgsl/shared/list_walk.wgsl")),
    ("shared/dfsph_tiles.wgsl", include_str!("../../../wgsl/shared/dfsph_tiles.wgsl")),
    ("sim/bin_count.wgsl", include_str!("../../../wgsl/sim/bin_count.wgsl")),
    ("sim/prefix_sum.wgsl", include_str!("../../../wgsl/sim/prefix_sum.wgsl")),
    ("sim/bin_scatter.wgsl", include_str!("../../../wgsl/sim/bin_scatter.wgsl")),
    ("sim/reorder.wgsl", include_str!("../../../wgsl/sim/reorder.wgsl")),
    ("sim/density.wgsl", include_str!("../../../wgsl/sim/density.wgsl")),
    ("sim/density_tiled.wgsl", include_str!("../../../wgsl/sim/density_tiled.wgsl")),
    ("sim/continuity.wgsl", include_str!("../../../wgsl/sim/continuity.wgsl")),
    ("sim/continuity_tiled.wgsl", include_str!("../../../wgsl/sim/continuity_tiled.wgsl")),
    ("sim/forces.wgsl", include_str!("../../../wgsl/sim/forces.wgsl")),
    ("sim/forces_tiled.wgsl", include_str!("../../../wgsl/sim/forces_tiled.wgsl")),
    ("sim/integrate.wgsl", include_str!("../../../wgsl/sim/integrate.wgsl")),
    ("sim/integrate_tiled.wgsl", include_str!("../../../wgsl/sim/integrate_tiled.wgsl")),
    ("sim/forces_integrate.wgsl", include_str!("../../../wgsl/sim/forces_integrate.wgsl")),
    ("shared/dfsph.wgsl", include_str!("../../../wgsl/shared/dfsph.wgsl")),
    ("sim/dfsph_factors.wgsl", include_str!("../../../wgsl/sim/dfsph_factors.wgsl")),
    ("sim/dfsph_factors_tiled.wgsl", include_str!("../../../wgsl/sim/dfsph_factors_tiled.wgsl")),
    ("sim/dfsph_divergence.wgsl", include_str!("../../../wgsl/sim/dfsph_divergence.wgsl")),
    ("sim/dfsph_divergence_tiled.wgsl", include_str!("../../../wgsl/sim/dfsph_divergence_tiled.wgsl")),
    ("sim/dfsph_predict.wgsl", include_str!("../../../wgsl/sim/dfsph_predict.wgsl")),
    ("sim/dfsph_pressure.wgsl", include_str!("../../../wgsl/sim/dfsph_pressure.wgsl")),
    ("sim/dfsph_pressure_tiled.wgsl", include_str!("../../../wgsl/sim/dfsph_pressure_tiled.wgsl")),
    ("sim/dfsph_convergence.wgsl", include_str!("../../../wgsl/sim/dfsph_convergence.wgsl")),
    ("sim/dfsph_integrate.wgsl", include_str!("../../../wgsl/sim/dfsph_integrate.wgsl")),
    ("sim/probes.wgsl", include_str!("../../../wgsl/sim/probes.wgsl")),
    ("sim/wall_pressure.wgsl", include_str!("../../../wgsl/sim/wall_pressure.wgsl")),
    ("sim/surface_normals.wgsl", include_str!("../../../wgsl/sim/surface_normals.wgsl")),
    ("sim/surface_normals_tiled.wgsl", include_str!("../../../wgsl/sim/surface_normals_tiled.wgsl")),
    ("sim/fields.wgsl", include_str!("../../../wgsl/sim/fields.wgsl")),
    ("sim/neighbour_skin.wgsl", include_str!("../../../wgsl/sim/neighbour_skin.wgsl")),
    ("sim/ghost_velocities.wgsl", include_str!("../../../wgsl/sim/ghost_velocities.wgsl")),
    ("sim/ghost_link.wgsl", include_str!("../../../wgsl/sim/ghost_link.wgsl")),
    ("sim/resident_exchange.wgsl", include_str!("../../../wgsl/sim/resident_exchange.wgsl")),
];

/// The text of a simulation file (`sim/density.wgsl`, `shared/common.wgsl`, ...).
pub fn source(path: &str) -> Option<&'static str> {
    SOURCES.iter().find(|s| s.0 == path).map(|s| s.1)
}

/// `text` with every `//! include PATH` line replaced by the text of PATH (found by `lookup`),
/// recursively, each file at most once (a second include of it is dropped).
pub fn assemble(text: &str, lookup: &dyn Fn(&str) -> Option<&'static str>) -> String {
    let mut done = Vec::new();
    let mut out = String::new();
    include_into(text, lookup, &mut done, &mut out);
    out
}

fn include_into(text: &str, lookup: &dyn Fn(&str) -> Option<&'static str>, done: &mut Vec<String>, out: &mut String) {
    for line in text.lines() {
        if let Some(rest) = line.trim().strip_prefix("//! unroll ") {
            let (count, statement) = rest.split_once(' ').unwrap_or_else(|| panic!("WGSL unroll without a statement: '{line}'"));
            let count: u32 = count.parse().unwrap_or_else(|_| panic!("WGSL unroll count '{count}' is not a number"));
            let indent = &line[..line.len() - line.trim_start().len()];
            for k in 0..count {
                out.push_str(indent);
                out.push_str(&statement.replace("{k}", &k.to_string()));
                out.push('\n');
            }
            continue;
        }
        match line.trim().strip_prefix("//! include ") {
            Some(path) => {
                let path = path.trim();
                if done.iter().any(|d| d == path) {
                    continue;
                }
                done.push(path.to_string());
                let included = lookup(path).unwrap_or_else(|| panic!("WGSL include '{path}' is not a known shader file"));
                include_into(included, lookup, done, out);
            }
            None => {
                out.push_str(line);
                out.push('\n');
            }
        }
    }
}

/// Default threads per workgroup of the particle stages (WORKGROUP_SIZE in common.wgsl, a
/// pipeline-overridable constant set per stage).
pub const WORKGROUP_SIZE: u32 = 128;
/// Values per workgroup of the scan (SCAN_BLOCK in prefix_sum.wgsl, whose workgroups have
/// SCAN_WORKGROUP_SIZE = 128 threads).
pub const SCAN_BLOCK: u32 = 256;

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
        ("KERNEL", Kernel::ALL.iter().position(|&k| k == params.kernel).expect("every kernel is listed") as f64),
        ("EOS", match params.eos { EquationOfState::Linear => 0.0, EquationOfState::Tait => 1.0 }),
        ("CLAMP_NEGATIVE_PRESSURE", flag(params.clamp_negative_pressure)),
        ("CONSISTENT_WALL_PRESSURE", flag(params.boundary_pressure == BoundaryPressure::Consistent)),
        ("ADAMI_WALL_PRESSURE", flag(params.boundary_pressure == BoundaryPressure::Adami)),
        ("VISCOSITY", flag(params.uses_viscosity())),
        ("PLANES", flag(!params.planes.is_empty())),
        ("SOLID_BOXES", flag(!params.solid_boxes.is_empty())),
        ("GRAVITY", flag(params.uses_gravity())),
        ("ADAPTIVE_DT", flag(params.adaptive.is_some())),
        ("CONTINUITY", flag(params.continuity_density)),
        ("DENSITY_DIFFUSION", flag(params.continuity_density && params.density_diffusion > 0.0)),
        ("ARTIFICIAL_VISCOSITY", flag(params.artificial_viscosity > 0.0)),
        ("SURFACE_TENSION", flag(params.surface_tension > 0.0)),
        ("WALL_ADHESION", flag(params.wall_adhesion > 0.0)),
    ]
}

/// How a stage uses one of its storage arrays (the `//! array` lines of its WGSL file).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Access {
    Read,
    ReadWrite,
    /// `array<atomic<u32>>`.
    Atomic,
}

/// A storage array a stage declares with a line `//! array NAME: TYPE, ACCESS[, whole|optional]`.
///
/// The host turns each declaration into one binding per segment of at most
/// [`GpuContext::storage_segment_bytes`] bytes (so no binding exceeds the adapter's
/// `max_storage_buffer_binding_size`, however many particles there are) and into accessor
/// functions `NAME_at(i)`, `NAME_set(i, v)` (read_write) and `NAME_add(i, v)` (atomic) that pick
/// the segment of element `i`. A `whole` array is bound as one binding under its own name and is
/// indexed directly (small arrays such as the status words). An `optional` array of length 0
/// (a feature the scene does not use) has no binding at all: its accessors are stubs (`_at`
/// returns zero), which the feature's specialisation constant keeps from ever being called, so
/// the stage binds exactly what it bound before the feature existed.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ArrayDecl {
    pub name: String,
    /// The element type as written (`vec4<f32>`, `vec2<f32>`, `f32` or `u32`).
    pub ty: String,
    pub access: Access,
    pub whole: bool,
    pub optional: bool,
}

impl ArrayDecl {
    pub fn element_bytes(&self) -> u64 {
        match self.ty.as_str() {
            "vec4<f32>" | "vec4<u32>" => 16,
            "vec2<f32>" | "vec2<u32>" => 8,
            "f32" | "u32" | "i32" => 4,
            other => panic!("array '{}' has element type '{other}', which the segmenting does not know", self.name),
        }
    }

    /// Elements per segment for segments of `segment_bytes` bytes (a power of two).
    pub fn segment_len(&self, segment_bytes: u64) -> u64 {
        segment_bytes / self.element_bytes()
    }

    /// Bindings of this array for `len` elements.
    pub fn segments(&self, len: u64, segment_bytes: u64) -> u64 {
        if self.optional && len == 0 {
            0
        } else if self.whole {
            1
        } else {
            len.div_ceil(self.segment_len(segment_bytes)).max(1)
        }
    }
}

/// The `//! array` declarations of an assembled stage, in binding order (binding 0 is the
/// uniform): each array once, in order of first appearance, read_write if any of its files
/// writes it (a fused stage includes two stage files that share arrays).
pub fn array_decls(source: &str) -> Vec<ArrayDecl> {
    let mut decls: Vec<ArrayDecl> = Vec::new();
    for rest in source.lines().filter_map(|l| l.trim().strip_prefix("//! array ")) {
        let (name, rest) = rest.split_once(':').unwrap_or_else(|| panic!("malformed array declaration '{rest}'"));
        let parts: Vec<&str> = rest.split(',').map(str::trim).collect();
        let access = match parts.get(1).copied() {
            Some("read") => Access::Read,
            Some("read_write") => Access::ReadWrite,
            Some("atomic") => Access::Atomic,
            other => panic!("array '{name}' has access {other:?}; allowed: read, read_write, atomic"),
        };
        let d = ArrayDecl { name: name.trim().into(), ty: parts[0].into(), access, whole: parts.get(2) == Some(&"whole"), optional: parts.get(2) == Some(&"optional") };
        match decls.iter_mut().find(|e| e.name == d.name) {
            Some(e) => {
                assert!(
                    e.ty == d.ty && e.whole == d.whole && e.optional == d.optional && (e.access == Access::Atomic) == (d.access == Access::Atomic),
                    "array '{}' declared twice differently",
                    d.name
                );
                if d.access == Access::ReadWrite {
                    e.access = Access::ReadWrite;
                }
            }
            None => decls.push(d),
        }
    }
    decls
}

/// WGSL declarations and accessors of `arrays` with `segments[i]` bindings each.
pub fn array_bindings_wgsl(arrays: &[ArrayDecl], segments: &[u64], segment_bytes: u64) -> String {
    use std::fmt::Write;
    let mut out = String::from("// Generated by the host from the stage's `//! array` lines (src/solver/gpu/shaders.rs).\n");
    let mut binding = 1;
    for (a, &count) in arrays.iter().zip(segments) {
        let (access, ty) = match a.access {
            Access::Read => ("read", a.ty.clone()),
            Access::ReadWrite => ("read_write", a.ty.clone()),
            Access::Atomic => ("read_write", format!("atomic<{}>", a.ty)),
        };
        if a.whole {
            writeln!(out, "@group(0) @binding({binding}) var<storage, {access}> {}: array<{ty}>;", a.name).unwrap();
            binding += 1;
            continue;
        }
        if count == 0 {
            // An optional array the scene does not use: no binding, stub accessors.
            let n = &a.name;
            writeln!(out, "fn {n}_at(i: u32) -> {ty} {{ return {ty}(); }}").unwrap();
            if a.access == Access::ReadWrite {
                writeln!(out, "fn {n}_set(i: u32, v: {ty}) {{}}").unwrap();
            }
            continue;
        }
        for s in 0..count {
            writeln!(out, "@group(0) @binding({binding}) var<storage, {access}> {}_{s}: array<{ty}>;", a.name).unwrap();
            binding += 1;
        }
        let len = a.segment_len(segment_bytes);
        let shift = len.trailing_zeros();
        // `body(segment, index)` is the statement acting on element `index` of one segment.
        let accessor = |out: &mut String, head: &str, body: &dyn Fn(u64, &str) -> String| {
            if count == 1 {
                writeln!(out, "{head} {{ {} }}", body(0, "i")).unwrap();
                return;
            }
            writeln!(out, "{head} {{\n    let k = i & {}u;\n    switch (i >> {shift}u) {{", len - 1).unwrap();
            for s in 0..count {
                let label = if s + 1 == count { "default".to_string() } else { format!("case {s}u") };
                writeln!(out, "        {label}: {{ {} }}", body(s, "k")).unwrap();
            }
            writeln!(out, "    }}\n}}").unwrap();
        };
        let n = &a.name;
        match a.access {
            Access::Read | Access::ReadWrite => {
                accessor(&mut out, &format!("fn {n}_at(i: u32) -> {ty}"), &|s, k| format!("return {n}_{s}[{k}];"));
                if a.access == Access::ReadWrite {
                    accessor(&mut out, &format!("fn {n}_set(i: u32, v: {ty})"), &|s, k| format!("{n}_{s}[{k}] = v;"));
                    // One component of a vector element, stored alone (see `Alias::Lane`).
                    if ty.starts_with("vec") {
                        let scalar = scalar_of(&ty);
                        accessor(&mut out, &format!("fn {n}_set_lane(i: u32, lane: u32, v: {scalar})"), &|s, k| format!("{n}_{s}[{k}][lane] = v;"));
                    }
                }
            }
            Access::Atomic => {
                accessor(&mut out, &format!("fn {n}_add(i: u32, v: {}) -> {}", a.ty, a.ty), &|s, k| format!("return atomicAdd(&{n}_{s}[{k}], v);"));
            }
        }
    }
    out
}

/// The length in elements of each array a stage declares, by the array's name.
pub type ArrayLengths<'a> = &'a dyn Fn(&str) -> u64;
/// The buffer that holds each array a stage declares, by the array's name (a handle: wgpu
/// buffers are shared, not copied, when cloned).
pub type ArrayBuffers<'a> = &'a dyn Fn(&str) -> wgpu::Buffer;

/// A compute pipeline with its bind-group layout and the arrays it binds.
pub struct Stage {
    pub pipeline: wgpu::ComputePipeline,
    pub layout: wgpu::BindGroupLayout,
    /// The declared arrays with their lengths in elements.
    arrays: Vec<(ArrayDecl, u64)>,
    /// Threads per workgroup (the `WORKGROUP_SIZE` constant it was built with).
    pub threads_per_group: u32,
    segment_bytes: u64,
}

/// The storage bindings of a stage exceed what the adapter allows.
pub fn check_bindings(ctx: &GpuContext, stage: &str, storage_bindings: u64) -> Result<(), GpuError> {
    let have = ctx.device.limits().max_storage_buffers_per_shader_stage as u64;
    if storage_bindings > have {
        return Err(GpuError::Limit {
            adapter: ctx.info.name.clone(),
            backend: format!("{:?}", ctx.info.backend),
            what: format!(
                "stage '{stage}', with its arrays bound in segments of {} bytes (fewer particles or a coarser grid need fewer segments),",
                ctx.storage_segment_bytes()
            ),
            limit: "max_storage_buffers_per_shader_stage",
            need: storage_bindings,
            have,
        });
    }
    Ok(())
}

/// The assembled text of stage file `sim/NAME.wgsl`.
pub fn stage_text(name: &str) -> String {
    let path = format!("sim/{name}.wgsl");
    assemble(source(&path).unwrap_or_else(|| panic!("no stage file {path}")), &source)
}

/// Bindings of each array of `decls` with the lengths `lens` gives.
fn segment_counts(decls: &[ArrayDecl], lens: ArrayLengths, segment_bytes: u64) -> Vec<u64> {
    decls.iter().map(|d| d.segments(lens(&d.name), segment_bytes)).collect()
}

/// Storage bindings that stage `name` needs for arrays of the lengths `lens` gives.
pub fn storage_bindings(ctx: &GpuContext, name: &str, lens: ArrayLengths) -> u64 {
    segment_counts(&array_decls(&stage_text(name)), lens, ctx.storage_segment_bytes()).iter().sum()
}

/// A binding of `bytes` bytes of `buffer` from `offset`.
pub fn buffer_range(buffer: &wgpu::Buffer, offset: u64, bytes: u64) -> wgpu::BindingResource<'_> {
    wgpu::BindingResource::Buffer(wgpu::BufferBinding { buffer, offset, size: std::num::NonZeroU64::new(bytes) })
}

/// Builds the pipeline of `entry` in stage file `sim/NAME.wgsl`, whose `//! array` declarations
/// have the lengths `lens` gives: one binding per segment (see [`ArrayDecl`]).
pub fn stage(ctx: &GpuContext, name: &str, entry: &str, lens: ArrayLengths, constants: &[(&str, f64)]) -> Result<Stage, GpuError> {
    stage_with_aliases(ctx, name, entry, lens, constants, &[])
}

/// Where an array a stage declares lives instead of a buffer of its own (see [`apply_aliases`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Alias {
    /// The same elements as another array of the stage: a stage that reads one array and
    /// writes another then works in place on one buffer (wgpu refuses one buffer bound both
    /// read-only and read_write in one dispatch).
    Same(&'static str),
    /// One component (`lane`) of each element of a vector array `target` of type `ty`, which the
    /// stage then binds even where it does not declare it; the values are bit casts where the
    /// scalar types differ (a u32 in a float lane). Writes are component stores, so threads that
    /// write one lane of their own element never touch a word that another thread reads.
    Lane { target: &'static str, ty: &'static str, lane: u32 },
    /// Computed by the WGSL expression (in `i`) where it is read, from the arrays `arrays`
    /// (name, element type; read-only, declared if the stage does not declare them); writes
    /// are dropped (the pressure from the density, with the equation of state).
    Derived { expr: &'static str, arrays: &'static [(&'static str, &'static str)] },
}

/// The scalar type of a vector type (`vec4<f32>` -> `f32`), or the type itself.
fn scalar_of(ty: &str) -> &str {
    ty.split_once('<').map_or(ty, |(_, rest)| rest.trim_end_matches('>'))
}

/// Drops the declaration of each aliased array from `decls` (an alias the stage does not declare
/// is skipped) and returns the WGSL accessors that act on where it lives instead. The target of
/// a [`Alias::Same`] or [`Alias::Lane`] becomes read_write where the alias is, and a lane's
/// target is declared if the stage does not declare it.
pub fn apply_aliases(decls: &mut Vec<ArrayDecl>, aliases: &[(&str, Alias)]) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    for &(alias, place) in aliases {
        let Some(at) = decls.iter().position(|d| d.name == alias) else { continue };
        let a = decls.remove(at);
        assert!(a.access != Access::Atomic && !a.whole, "array '{alias}' cannot be an alias");
        let ty = &a.ty;
        let writes = a.access == Access::ReadWrite;
        let target = |decls: &mut Vec<ArrayDecl>, name: &str, target_ty: &str| {
            let t = match decls.iter_mut().position(|d| d.name == name) {
                Some(k) => &mut decls[k],
                None => {
                    let decl = ArrayDecl { name: name.into(), ty: target_ty.into(), access: Access::Read, whole: false, optional: false };
                    let k = at.min(decls.len());
                    decls.insert(k, decl);
                    &mut decls[k]
                }
            };
            assert!(t.ty == target_ty && t.access != Access::Atomic, "array '{alias}' cannot live in '{name}'");
            if writes {
                t.access = Access::ReadWrite;
            }
        };
        match place {
            Alias::Same(name) => {
                target(decls, name, ty);
                writeln!(out, "fn {alias}_at(i: u32) -> {ty} {{ return {name}_at(i); }}").unwrap();
                if writes {
                    writeln!(out, "fn {alias}_set(i: u32, v: {ty}) {{ {name}_set(i, v); }}").unwrap();
                }
            }
            Alias::Lane { target: name, ty: target_ty, lane } => {
                target(decls, name, target_ty);
                let lane_ty = scalar_of(target_ty);
                let (read, write) = if lane_ty == ty.as_str() { (String::new(), String::new()) } else { (format!("bitcast<{ty}>"), format!("bitcast<{lane_ty}>")) };
                writeln!(out, "fn {alias}_at(i: u32) -> {ty} {{ return {read}({name}_at(i)[{lane}u]); }}").unwrap();
                if writes {
                    writeln!(out, "fn {alias}_set(i: u32, v: {ty}) {{ {name}_set_lane(i, {lane}u, {write}(v)); }}").unwrap();
                }
            }
            Alias::Derived { expr, arrays } => {
                for &(name, array_ty) in arrays {
                    if !decls.iter().any(|d| d.name == name) {
                        let k = at.min(decls.len());
                        decls.insert(k, ArrayDecl { name: name.into(), ty: array_ty.into(), access: Access::Read, whole: false, optional: false });
                    }
                }
                writeln!(out, "fn {alias}_at(i: u32) -> {ty} {{ return {expr}; }}").unwrap();
                if writes {
                    writeln!(out, "fn {alias}_set(i: u32, v: {ty}) {{}}").unwrap();
                }
            }
        }
    }
    out
}

/// [`stage`] with the arrays of `aliases` bound as others (see [`apply_aliases`]).
pub fn stage_with_aliases(ctx: &GpuContext, name: &str, entry: &str, lens: ArrayLengths, constants: &[(&str, f64)], aliases: &[(&str, Alias)]) -> Result<Stage, GpuError> {
    let device = &ctx.device;
    let segment_bytes = ctx.storage_segment_bytes();
    let text = stage_text(name);
    let mut decls = array_decls(&text);
    let forwarding = apply_aliases(&mut decls, aliases);
    let segments = segment_counts(&decls, lens, segment_bytes);
    check_bindings(ctx, name, segments.iter().sum())?;
    let source = format!("{}{forwarding}\n{text}", array_bindings_wgsl(&decls, &segments, segment_bytes));
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor { label: Some(name), source: wgpu::ShaderSource::Wgsl(source.into()) });
    let mut uses = vec![Use::Uniform];
    for (d, &count) in decls.iter().zip(&segments) {
        let u = if d.access == Access::Read { Use::Read } else { Use::ReadWrite };
        uses.extend(std::iter::repeat_n(u, count as usize));
    }
    let layout = layout(device, name, &uses);
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
    let threads_per_group = constants.iter().find(|c| c.0 == "WORKGROUP_SIZE").map_or(WORKGROUP_SIZE, |c| c.1 as u32);
    let arrays = decls.into_iter().map(|d| {
        let len = lens(&d.name);
        (d, len)
    });
    Ok(Stage { pipeline, layout, arrays: arrays.collect(), segment_bytes, threads_per_group })
}

impl Stage {
    /// A bind group of `uniform` and the buffer `buffers` names for each declared array, each
    /// split into the ranges of its segments.
    pub fn bind_group(&self, device: &wgpu::Device, label: &str, uniform: &wgpu::Buffer, buffers: ArrayBuffers) -> wgpu::BindGroup {
        // An optional array of length 0 has no binding (and no buffer to ask for).
        let bound: Vec<&(ArrayDecl, u64)> = self.arrays.iter().filter(|(decl, len)| !(decl.optional && *len == 0)).collect();
        let held: Vec<wgpu::Buffer> = bound.iter().map(|(decl, _)| buffers(&decl.name)).collect();
        let mut resources = vec![uniform.as_entire_binding()];
        for ((decl, len), buffer) in bound.into_iter().zip(&held) {
            let bytes = decl.element_bytes();
            // A whole array, or an empty one (its buffer is a 16-byte stand-in), is bound as its
            // buffer; the others exactly as long as the array, in segments: a buffer may be
            // longer than the array it holds (an array kept in another array's dead storage).
            if decl.whole || *len == 0 {
                resources.push(buffer.as_entire_binding());
                continue;
            }
            let seg = decl.segment_len(self.segment_bytes);
            for s in 0..decl.segments(*len, self.segment_bytes) {
                let elements = seg.min(len - s * seg);
                assert!(elements * bytes <= self.segment_bytes && (s * seg + elements) * bytes <= buffer.size(), "array {} of {label}", decl.name);
                resources.push(buffer_range(buffer, s * seg * bytes, elements * bytes));
            }
        }
        bind_group(device, label, &self.layout, &resources)
    }

    /// A bind group of explicit resources (for stages that bind ranges themselves, like the scan).
    pub fn bind_group_of(&self, device: &wgpu::Device, label: &str, resources: &[wgpu::BindingResource]) -> wgpu::BindGroup {
        bind_group(device, label, &self.layout, resources)
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn includes_come_once_and_unrolls_count_their_lanes() {
        let lookup = |path: &str| match path {
            "a.wgsl" => Some("fn a() {}\n"),
            _ => None,
        };
        let text = "//! include a.wgsl\n//! include a.wgsl\nfn f() {\n    //! unroll 3 s += g({k}u, b + {k}u);\n}\n";
        assert_eq!(assemble(text, &lookup), "fn a() {}\nfn f() {\n    s += g(0u, b + 0u);\n    s += g(1u, b + 1u);\n    s += g(2u, b + 2u);\n}\n");
    }
}
