//! The GPU solver: structure-of-arrays storage buffers, the pipelines of every stage, and the
//! dispatch order of a step. The step loop only records dispatches; nothing is read back, waited
//! for or created inside it.

use super::device::GpuContext;
use super::memory::MemoryPlan;
use super::pipelines::{constants, dispatch_size, stage, stage_of, storage_bindings, Stage};
use super::scan::Scan;
use crate::cpu::common::{GridR, KernelCoefficients};
use crate::cpu::sort_by_cell;
use crate::real::V3;
use crate::scene::{InitialState, Params, MAX_PLANES};
use crate::sim::{Backend, BackendState, DtStats, Health, Snapshot, StepFields};
use encase::{ShaderType, UniformBuffer};
use wgpu::util::DeviceExt;

mod profiled;
pub use profiled::PROFILED_STAGES;
mod stream;
pub use stream::{StreamedSnapshot, MAX_PASSES, STREAM_CHUNK};

/// A WGSL `vec4<T>` for encase (which has no glam support of its own).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Vec4<T>(pub [T; 4]);
impl<T> AsRef<[T; 4]> for Vec4<T> {
    fn as_ref(&self) -> &[T; 4] {
        &self.0
    }
}
impl<T> AsMut<[T; 4]> for Vec4<T> {
    fn as_mut(&mut self) -> &mut [T; 4] {
        &mut self.0
    }
}
impl<T> From<[T; 4]> for Vec4<T> {
    fn from(v: [T; 4]) -> Self {
        Vec4(v)
    }
}
encase::impl_vector!(4, Vec4<T>; (T); using AsRef AsMut From);
pub type Vec4f = Vec4<f32>;
pub type Vec4u = Vec4<u32>;

/// The uniform parameter block: `struct Params` in wgsl/common.wgsl.
#[derive(ShaderType, Clone, Debug, Default)]
pub struct GpuParams {
    pub domain_min: Vec4f,
    pub domain_max: Vec4f,
    pub gravity: Vec4f,
    pub grid_origin: Vec4f,
    pub grid_dims: Vec4u,
    pub h: f32,
    pub h2: f32,
    pub inv_cell: f32,
    pub dt: f32,
    pub fluid_mass: f32,
    pub rest_density: f32,
    pub stiffness: f32,
    pub viscosity: f32,
    pub boundary_friction: f32,
    pub w_coef: f32,
    pub grad_coef: f32,
    pub lap_coef: f32,
    pub fluid_count: u32,
    pub wall_count: u32,
    pub plane_count: u32,
    pub pad0: u32,
    pub planes: [Vec4f; MAX_PLANES],
    pub plane_restitution: [Vec4f; MAX_PLANES],
    pub speed_of_sound: f32,
    pub cfl_number: f32,
    pub force_number: f32,
    pub viscous_number: f32,
    pub dt_min: f32,
    pub dt_max: f32,
    pub pad1: u32,
    pub pad2: u32,
}

fn v4(v: [f64; 3]) -> Vec4f {
    Vec4([v[0] as f32, v[1] as f32, v[2] as f32, 0.0])
}

impl GpuParams {
    /// The f32 constants, converted exactly as the f32 CPU path converts them.
    pub fn new(p: &Params, fluid_count: u32, wall_count: u32, viscosity: f64) -> Self {
        let k = KernelCoefficients::<f32>::new(p.kernel, p.h);
        let g = GridR::<f32>::new(p);
        let mut planes = [Vec4f::default(); MAX_PLANES];
        let mut restitution = [Vec4f::default(); MAX_PLANES];
        for (i, pl) in p.planes.iter().enumerate() {
            planes[i] = Vec4([pl.normal[0] as f32, pl.normal[1] as f32, pl.normal[2] as f32, pl.offset as f32]);
            restitution[i] = Vec4([pl.restitution as f32, 0.0, 0.0, 0.0]);
        }
        GpuParams {
            domain_min: v4(p.domain_min),
            domain_max: v4(p.domain_max),
            gravity: v4(p.gravity),
            grid_origin: Vec4([g.origin.0[0], g.origin.0[1], g.origin.0[2], 0.0]),
            grid_dims: Vec4([g.dims[0], g.dims[1], g.dims[2], 0]),
            h: k.h,
            h2: k.h2,
            inv_cell: g.inv_cell,
            dt: p.dt as f32,
            fluid_mass: p.fluid_mass as f32,
            rest_density: p.rest_density as f32,
            stiffness: p.stiffness as f32,
            viscosity: viscosity as f32,
            boundary_friction: p.boundary_friction as f32,
            w_coef: k.w,
            grad_coef: k.grad,
            lap_coef: k.lap,
            fluid_count,
            wall_count,
            plane_count: p.planes.len() as u32,
            pad0: 0,
            planes,
            plane_restitution: restitution,
            speed_of_sound: p.speed_of_sound() as f32,
            cfl_number: p.adaptive.map_or(0.0, |a| a.cfl_number as f32),
            force_number: p.adaptive.map_or(0.0, |a| a.force_number as f32),
            viscous_number: p.adaptive.map_or(0.0, |a| a.viscous_number as f32),
            dt_min: p.adaptive.map_or(p.dt, |a| a.dt_min) as f32,
            dt_max: p.adaptive.map_or(p.dt, |a| a.dt_max) as f32,
            pad1: 0,
            pad2: 0,
        }
    }

    pub fn bytes(&self) -> Vec<u8> {
        let mut buf = UniformBuffer::new(Vec::new());
        buf.write(self).expect("the parameter block serialises");
        buf.into_inner()
    }
}

/// Particle state (ping-pong pair): the binning gathers one buffer of the pair into the other in
/// cell order, and the integration writes the next state back into the first. The w component
/// of a position holds the particle's original index as u32 bits.
struct StateBuffers {
    positions: wgpu::Buffer,
    velocities: wgpu::Buffer,
}

/// Bind groups of one parity: reading state `c`, writing state `1 - c`.
struct ParityBindGroups {
    bin_count: wgpu::BindGroup,
    bin_scatter: wgpu::BindGroup,
    reorder: wgpu::BindGroup,
    density: wgpu::BindGroup,
    /// The integration (after `forces`, adaptive dt) or the fused forces and integration.
    advance: wgpu::BindGroup,
}

struct Pipelines {
    bin_count: Stage,
    bin_scatter: Stage,
    reorder: Stage,
    density: Stage,
    /// The forces alone: every step with adaptive dt; otherwise only when the accelerations are
    /// asked for (`step_fields`).
    forces: Stage,
    /// `integrate` (two passes) or `forces_and_integrate` (fused, see `fused`).
    advance: Stage,
    finish_step: Stage,
    /// Adaptive dt only: the reduction of |v|max and |a|max, and the choice of dt.
    adaptive: Option<(Stage, Stage)>,
    /// Forces and integration in one pass (fixed dt only; see `GpuOptions`): no accelerations
    /// array.
    fused: bool,
}

/// Steps per command buffer: enough to amortise submission, few enough to check health often.
pub const STEPS_PER_SUBMIT: u64 = 32;

/// The status buffer: health counters, and the adaptive step's maxima, dt and time (see
/// wgsl/integrate.wgsl).
const STATUS_WORDS: u64 = 12;
pub(super) const STATUS_BYTES: u64 = STATUS_WORDS * 4;
const NO_BAD_STEP: u32 = u32::MAX;

/// The stage files of the fused forces and integration.
const FUSED_STAGE: &[&str] = &["forces", "integrate", "forces_integrate"];

/// The accelerations array with the forces' bind groups of each parity.
struct Accelerations {
    buffer: wgpu::Buffer,
    groups: [wgpu::BindGroup; 2],
}

pub struct GpuSolver {
    ctx: GpuContext,
    params: Params,
    fluid_count: u32,
    wall_count: u32,
    uniform: wgpu::Buffer,
    /// Viscosity currently in the uniform block.
    uniform_viscosity: f64,
    state: [StateBuffers; 2],
    /// Which of `state` holds the current particles.
    current: usize,
    /// Which of `state` the densities and pressures (and accelerations, when valid) belong to:
    /// the state the last step or refresh evaluated them on.
    fields_state: usize,
    /// Whether `accelerations` holds the accelerations of `fields_state`.
    accelerations_valid: bool,
    /// Cell counts, scanned in place into cell starts (cells + 1 values).
    starts: wgpu::Buffer,
    /// Also the binning's unordered cell slots (u32), which are dead once the state is reordered.
    densities: wgpu::Buffer,
    /// Also the binning's cell keys (u32), which are dead once the state is reordered.
    pressures: wgpu::Buffer,
    /// Every step with two passes; with the fused step created on the first `step_fields`.
    accelerations: Option<Accelerations>,
    /// Bound where a fused stage declares the accelerations it does not use.
    placeholder: wgpu::Buffer,
    status: wgpu::Buffer,
    wall_positions: wgpu::Buffer,
    wall_starts: wgpu::Buffer,
    scan: Scan,
    pipelines: Pipelines,
    groups: [ParityBindGroups; 2],
    finish_group: wgpu::BindGroup,
    steps: u64,
    /// The adapter's `max_compute_workgroups_per_dimension`.
    max_groups_per_dim: u32,
    /// Steps per command buffer.
    steps_per_submit: u64,
    /// Bytes of every buffer the solver allocated.
    memory: u64,
}

fn storage(device: &wgpu::Device, label: &str, bytes: u64, extra: wgpu::BufferUsages) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes.max(16),
        // VERTEX: the renderer draws particles straight from these buffers.
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::VERTEX | extra,
        mapped_at_creation: false,
    })
}

fn storage_init(device: &wgpu::Device, label: &str, contents: &[u8]) -> wgpu::Buffer {
    let mut data = contents.to_vec();
    data.resize(data.len().max(16), 0);
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: &data,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::VERTEX,
    })
}

fn vec4s(points: &[[f64; 3]], w: impl Fn(usize) -> f32) -> Vec<[f32; 4]> {
    points.iter().enumerate().map(|(i, p)| [p[0] as f32, p[1] as f32, p[2] as f32, w(i)]).collect()
}

/// Positions as vec4s whose w holds each particle's id as u32 bits.
fn positions_with_ids(points: &[[f64; 3]], ids: impl Fn(usize) -> u32) -> Vec<[f32; 4]> {
    vec4s(points, |i| f32::from_bits(ids(i)))
}

/// Writes positions (with the ids `id(i)` in their w) and velocities (w = 0, as the integration
/// writes them) into `state`, `STREAM_CHUNK` particles at a time with a submission after each
/// piece, so the host converts and stages one piece instead of two whole `vec4` arrays
/// (32 bytes per particle).
fn upload_state(ctx: &GpuContext, state: &StateBuffers, positions: &[[f64; 3]], velocities: &[[f64; 3]], id: impl Fn(usize) -> u32) {
    let chunk = STREAM_CHUNK as usize;
    for first in (0..positions.len()).step_by(chunk) {
        let end = (first + chunk).min(positions.len());
        let pos = positions_with_ids(&positions[first..end], |i| id(first + i));
        let vel = vec4s(&velocities[first..end], |_| 0.0);
        ctx.queue.write_buffer(&state.positions, first as u64 * 16, bytemuck::cast_slice(&pos));
        ctx.queue.write_buffer(&state.velocities, first as u64 * 16, bytemuck::cast_slice(&vel));
        ctx.queue.submit([]);
        // Lets the device free the piece's staging memory before the next one.
        let _ = ctx.device.poll(wgpu::PollType::Wait { submission_index: None, timeout: None });
    }
}

/// The ids carried in the w components of positions read back from the GPU.
fn ids_of(positions: &[[f32; 4]]) -> Vec<u32> {
    positions.iter().map(|p| p[3].to_bits()).collect()
}

/// Choices of the GPU step that do not change its results.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GpuOptions {
    /// Fuse the forces and the integration into one pass when dt is fixed: the same values,
    /// without the accelerations array (16 bytes per fluid particle) and a second pass over the
    /// state. `None` (the default) fuses on every adapter but software ones (llvmpipe, lavapipe,
    /// WARP), where the fused pass measured 3-20 % slower, unless only the fused step fits the
    /// adapter's buffers.
    pub fuse_forces_and_integration: Option<bool>,
    /// Threads per workgroup of each particle stage.
    pub workgroup_sizes: super::workgroups::WorkgroupSizes,
    /// Steps recorded into one command buffer (0: [`STEPS_PER_SUBMIT`]).
    pub steps_per_submit: u64,
    /// Visit the neighbour stencil as 27 single cells instead of 9 runs of 3 (to measure what
    /// the runs gain; the same values).
    pub single_cells: bool,
}

impl GpuSolver {
    /// Uploads a scene's particles and builds every pipeline and bind group.
    pub fn new(ctx: GpuContext, params: &Params, initial: &InitialState) -> anyhow::Result<Self> {
        Self::with_options(ctx, params, initial, GpuOptions::default())
    }

    /// Like [`GpuSolver::new`], with `options`.
    pub fn with_options(ctx: GpuContext, params: &Params, initial: &InitialState, options: GpuOptions) -> anyhow::Result<Self> {
        let n = initial.fluid_positions.len() as u64;
        let cells = params.grid.cell_count() as u64;
        let viscosity = params.viscosity_at_step(0);
        let gpu_params = GpuParams::new(params, n as u32, initial.wall_positions.len() as u32, viscosity);
        // Every buffer is checked against the device's limits before the first is created.
        let w = initial.wall_positions.len() as u64;
        // Without walls the shaders never read the wall arrays (WALLS = false): no per-cell array.
        let has_walls = w > 0;
        let wall_cells = if has_walls { cells + 1 } else { 0 };
        let c1 = cells + 1;
        // The fused module binds forces.wgsl's arrays, then integrate.wgsl's new ones; its
        // accelerations slot gets a placeholder.
        let fused_lens = [n, n, n, n, c1, w, wall_cells, 0, n, n, 0];
        // Forces and integration can be fused with fixed dt, unless the fused stage's bindings
        // exceed the adapter's (arrays in many segments): then they run as two passes.
        let can_fuse = params.adaptive.is_none()
            && storage_bindings(&ctx, FUSED_STAGE, &fused_lens) <= ctx.device.limits().max_storage_buffers_per_shader_stage as u64;
        let uniform_bytes = gpu_params.bytes().len() as u64;
        let fused = can_fuse
            && options.fuse_forces_and_integration.unwrap_or_else(|| {
                ctx.info.device_type != wgpu::DeviceType::Cpu || MemoryPlan::new(n, Some(w), cells, uniform_bytes, true).check(&ctx).is_err()
            });
        let plan = MemoryPlan::new(n, Some(w), cells, uniform_bytes, !fused);
        plan.check(&ctx)?;

        // The pipelines come first: they check that the stages' bindings (one per segment of
        // each array) fit the adapter before any buffer exists.
        let mut k = constants(params);
        k.push(("WALLS", if has_walls { 1.0 } else { 0.0 }));
        k.push(("STENCIL_RUNS", if options.single_cells { 0.0 } else { 1.0 }));
        let ws = options.workgroup_sizes;
        ws.check(&ctx)?;
        // The constants of a stage with `size` threads per workgroup.
        let sized = |size: u32| {
            let mut c = k.clone();
            c.push(("WORKGROUP_SIZE", size as f64));
            c
        };
        let integrate_lens = [n, n, n, n, n, 0];
        let forces_lens = [n, n, n, n, c1, w, wall_cells, n];
        let pipelines = Pipelines {
            bin_count: stage(&ctx, "bin_count", "main", &[n, n, n, c1], &sized(ws.bin_count))?,
            bin_scatter: stage(&ctx, "bin_scatter", "main", &[n, n, c1, n], &sized(ws.bin_scatter))?,
            reorder: stage(&ctx, "reorder", "main", &[n, c1, n, n, n, n, n], &sized(ws.reorder))?,
            density: stage(&ctx, "density", "main", &[n, c1, w, wall_cells, n, n, 0], &sized(ws.density))?,
            forces: stage(&ctx, "forces", "forces", &forces_lens, &sized(ws.forces))?,
            advance: if fused {
                stage_of(&ctx, FUSED_STAGE, "forces_and_integrate", &fused_lens, &sized(ws.forces))?
            } else {
                stage(&ctx, "integrate", "integrate", &integrate_lens, &sized(ws.integrate))?
            },
            // One thread on the status words: its accelerations slot gets the placeholder.
            finish_step: stage(&ctx, "integrate", "finish_step", &[n, n, 0, n, n, 0], &k)?,
            adaptive: match params.adaptive {
                Some(_) => Some((
                    stage(&ctx, "integrate", "reduce_maxima", &integrate_lens, &sized(ws.integrate))?,
                    stage(&ctx, "integrate", "choose_dt", &integrate_lens, &k)?,
                )),
                None => None,
            },
            fused,
        };

        let device = &ctx.device;
        let uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("params"),
            contents: &gpu_params.bytes(),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        });

        // Walls never move: sorted by cell once, on the host, with the same counting sort.
        let grid = GridR::<f32>::new(params);
        let wall_f32: Vec<V3<f32>> = initial.wall_positions.iter().map(|&p| V3::from64(p)).collect();
        let (wall_order, wall_starts) = sort_by_cell(&grid, &wall_f32);
        let walls_sorted: Vec<[f64; 3]> = wall_order.iter().map(|&i| initial.wall_positions[i as usize]).collect();
        let wall_masses: Vec<f32> = wall_order.iter().map(|&i| initial.wall_masses[i as usize] as f32).collect();
        let wall_positions = storage_init(device, "wall positions", bytemuck::cast_slice(&vec4s(&walls_sorted, |i| wall_masses[i])));
        let wall_starts = if has_walls { wall_starts } else { Vec::new() };
        let wall_starts = storage_init(device, "wall cell starts", bytemuck::cast_slice(&wall_starts));

        let state0 = StateBuffers {
            positions: storage(device, "positions 0", n * 16, wgpu::BufferUsages::empty()),
            velocities: storage(device, "velocities 0", n * 16, wgpu::BufferUsages::empty()),
        };
        upload_state(&ctx, &state0, &initial.fluid_positions, &initial.fluid_velocities, |i| i as u32);
        let state1 = StateBuffers {
            positions: storage(device, "positions 1", n * 16, wgpu::BufferUsages::empty()),
            velocities: storage(device, "velocities 1", n * 16, wgpu::BufferUsages::empty()),
        };
        let starts = storage(device, "cell starts", (cells + 1) * 4, wgpu::BufferUsages::empty());
        let densities = storage(device, "densities", n * 4, wgpu::BufferUsages::empty());
        let pressures = storage(device, "pressures", n * 4, wgpu::BufferUsages::empty());
        let placeholder = storage(device, "placeholder", 16, wgpu::BufferUsages::empty());
        let accelerations = (!fused).then(|| storage(device, "accelerations", n * 16, wgpu::BufferUsages::empty()));
        let mut status_init = [0u32; STATUS_WORDS as usize];
        status_init[3] = NO_BAD_STEP;
        status_init[10] = f32::INFINITY.to_bits();
        let status = storage_init(device, "status", bytemuck::cast_slice(&status_init));
        let scan = Scan::new(&ctx, &uniform, &starts, cells + 1)?;

        let state = [state0, state1];
        let u = &uniform;
        let p = &pipelines;
        // The binning's arrays live in arrays that are dead while it runs: the cell keys and the
        // unordered slots in the pressures and densities (written again only after the reorder),
        // the ranks in the velocities of the state being gathered into (written by the reorder,
        // after the scatter has read the ranks).
        let (keys, unordered) = (&pressures, &densities);
        let make_parity = |c: usize| {
            let (src, dst) = (&state[c], &state[1 - c]);
            let ranks = &dst.velocities;
            ParityBindGroups {
                bin_count: p.bin_count.bind_group(device, "bin_count", u, &[&src.positions, keys, ranks, &starts]),
                bin_scatter: p.bin_scatter.bind_group(device, "bin_scatter", u, &[keys, ranks, &starts, unordered]),
                reorder: p.reorder.bind_group(
                    device,
                    "reorder",
                    u,
                    &[keys, &starts, unordered, &src.positions, &src.velocities, &dst.positions, &dst.velocities],
                ),
                density: p.density.bind_group(device, "density", u, &[&src.positions, &starts, &wall_positions, &wall_starts, &densities, &pressures, &status]),
                advance: if fused {
                    p.advance.bind_group(
                        device,
                        "forces_and_integrate",
                        u,
                        &[
                            &src.positions,
                            &src.velocities,
                            &densities,
                            &pressures,
                            &starts,
                            &wall_positions,
                            &wall_starts,
                            &placeholder,
                            &dst.positions,
                            &dst.velocities,
                            &status,
                        ],
                    )
                } else {
                    let a = accelerations.as_ref().expect("made without fusion");
                    p.advance.bind_group(device, "integrate", u, &[&src.positions, &src.velocities, a, &dst.positions, &dst.velocities, &status])
                },
            }
        };
        let groups = [make_parity(0), make_parity(1)];
        let finish_group = p.finish_step.bind_group(
            device,
            "finish_step",
            u,
            &[&state[0].positions, &state[0].velocities, &placeholder, &state[1].positions, &state[1].velocities, &status],
        );
        let max_groups_per_dim = device.limits().max_compute_workgroups_per_dimension;
        let memory = plan.total();
        let mut solver = GpuSolver {
            params: params.clone(),
            fluid_count: n as u32,
            wall_count: w as u32,
            uniform,
            uniform_viscosity: viscosity,
            state,
            current: 0,
            fields_state: 0,
            accelerations_valid: false,
            starts,
            densities,
            pressures,
            accelerations: None,
            placeholder,
            status,
            wall_positions,
            wall_starts,
            scan,
            groups,
            pipelines,
            finish_group,
            steps: 0,
            max_groups_per_dim,
            steps_per_submit: if options.steps_per_submit == 0 { STEPS_PER_SUBMIT } else { options.steps_per_submit },
            memory,
            ctx,
        };
        if let Some(buffer) = accelerations {
            solver.accelerations = Some(solver.forces_groups(buffer));
        }
        Ok(solver)
    }

    /// The forces' bind groups of both parities, writing into `buffer`.
    fn forces_groups(&self, buffer: wgpu::Buffer) -> Accelerations {
        let device = &self.ctx.device;
        let group = |c: usize| {
            let st = &self.state[c];
            self.pipelines.forces.bind_group(
                device,
                "forces",
                &self.uniform,
                &[&st.positions, &st.velocities, &self.densities, &self.pressures, &self.starts, &self.wall_positions, &self.wall_starts, &buffer],
            )
        };
        let groups = [group(0), group(1)];
        Accelerations { buffer, groups }
    }

    /// Makes `accelerations` hold the accelerations of `fields_state`: the fused
    /// step keeps them in registers, so they are evaluated again here (same inputs, same
    /// shader code: the same values), into an array created on first use.
    fn ensure_accelerations(&mut self) {
        if self.accelerations_valid {
            return;
        }
        if self.accelerations.is_none() {
            let buffer = storage(&self.ctx.device, "accelerations", self.fluid_count as u64 * 16, wgpu::BufferUsages::empty());
            self.accelerations = Some(self.forces_groups(buffer));
        }
        let acc = self.accelerations.as_ref().expect("made above");
        let mut encoder = self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("accelerations") });
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("forces"), timestamp_writes: None });
        self.dispatch_particles(&mut pass, &self.pipelines.forces, &acc.groups[self.fields_state]);
        drop(pass);
        self.ctx.queue.submit([encoder.finish()]);
        self.accelerations_valid = true;
    }

    /// Whether forces and integration run as one pass.
    pub fn fused(&self) -> bool {
        self.pipelines.fused
    }
    /// Blocks until the GPU has finished everything submitted (for timing).
    pub fn wait(&self) -> anyhow::Result<()> {
        self.ctx.device.poll(wgpu::PollType::Wait { submission_index: None, timeout: None })?;
        Ok(())
    }

    pub fn context(&self) -> &GpuContext {
        &self.ctx
    }

    fn dispatch_particles(&self, pass: &mut wgpu::ComputePass, stage: &Stage, group: &wgpu::BindGroup) {
        pass.set_pipeline(&stage.pipeline);
        pass.set_bind_group(0, group, &[]);
        let (x, y) = dispatch_size(self.fluid_count as u64, stage.threads_per_group, self.max_groups_per_dim);
        pass.dispatch_workgroups(x, y, 1);
    }

    /// Records the binning (count, scan, scatter, reorder) of the current state into the other
    /// buffer of the pair, which becomes the current one.
    fn record_bin(&mut self, encoder: &mut wgpu::CommandEncoder) {
        encoder.clear_buffer(&self.starts, 0, None);
        let g = &self.groups[self.current];
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("binning"), timestamp_writes: None });
        self.dispatch_particles(&mut pass, &self.pipelines.bin_count, &g.bin_count);
        self.scan.record(&mut pass);
        self.dispatch_particles(&mut pass, &self.pipelines.bin_scatter, &g.bin_scatter);
        self.dispatch_particles(&mut pass, &self.pipelines.reorder, &g.reorder);
        drop(pass);
        self.current = 1 - self.current;
    }

    /// Whether the step about to run rebuilds the neighbour grid (every `rebuild_every` steps;
    /// in between, the stages use the cells of the last rebuild).
    fn rebuilds(&self) -> bool {
        self.steps % self.params.rebuild_every.max(1) as u64 == 0
    }

    /// Records one full step: the binning (when due) into the other buffer of the pair, the
    /// fields on it, and the integration back into the first.
    fn record_step(&mut self, encoder: &mut wgpu::CommandEncoder) {
        if self.rebuilds() {
            self.record_bin(encoder);
        }
        let read = self.current;
        encoder.clear_buffer(&self.status, 4, Some(8));
        let g = &self.groups[read];
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("step"), timestamp_writes: None });
        self.dispatch_particles(&mut pass, &self.pipelines.density, &g.density);
        if let Some(acc) = self.accelerations.as_ref().filter(|_| !self.pipelines.fused) {
            self.dispatch_particles(&mut pass, &self.pipelines.forces, &acc.groups[read]);
        }
        self.record_integration(&mut pass, g);
        drop(pass);
        self.finish_step(read);
    }

    /// The bookkeeping after a step that read state `read` and wrote the other one.
    fn finish_step(&mut self, read: usize) {
        self.current = 1 - read;
        self.fields_state = read;
        self.accelerations_valid = !self.pipelines.fused;
    }

    /// The integration with its bookkeeping: the adaptive step's reduction and choice of dt,
    /// the integration itself (fused with the forces, or after them) and the per-step status
    /// update.
    fn record_integration(&self, pass: &mut wgpu::ComputePass, g: &ParityBindGroups) {
        if let Some((reduce, choose)) = &self.pipelines.adaptive {
            self.dispatch_particles(pass, reduce, &g.advance);
            pass.set_pipeline(&choose.pipeline);
            pass.set_bind_group(0, &g.advance, &[]);
            pass.dispatch_workgroups(1, 1, 1);
        }
        self.dispatch_particles(pass, &self.pipelines.advance, &g.advance);
        pass.set_pipeline(&self.pipelines.finish_step.pipeline);
        pass.set_bind_group(0, &self.finish_group, &[]);
        pass.dispatch_workgroups(1, 1, 1);
    }

    fn set_viscosity(&mut self, nu: f64) {
        if nu != self.uniform_viscosity {
            let p = GpuParams::new(&self.params, self.fluid_count, self.wall_count, nu);
            self.ctx.queue.write_buffer(&self.uniform, 0, &p.bytes());
            self.uniform_viscosity = nu;
        }
    }

    /// Advances `n` steps, `STEPS_PER_SUBMIT` (or `GpuOptions::steps_per_submit`) per command
    /// buffer; a viscosity change from the schedule starts a new command buffer after a uniform
    /// write.
    pub fn advance(&mut self, n: u64) {
        let mut left = n;
        // Without a schedule the viscosity never changes: no per-step look-up.
        let scheduled = self.params.viscosity.len() > 1;
        while left > 0 {
            let nu = self.params.viscosity_at_step(self.steps);
            self.set_viscosity(nu);
            let mut encoder = self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("steps") });
            let mut batch = 0;
            while batch < left.min(self.steps_per_submit) {
                if scheduled && batch > 0 && self.params.viscosity_at_step(self.steps) != nu {
                    break;
                }
                self.record_step(&mut encoder);
                self.steps += 1;
                batch += 1;
            }
            self.ctx.queue.submit([encoder.finish()]);
            left -= batch;
        }
    }

    /// Sorts the current state by cell (idempotent: a sorted state stays as it is) and
    /// evaluates density and pressure for it, without advancing time.
    fn refresh_fields(&mut self) {
        let mut encoder = self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("refresh") });
        self.record_bin(&mut encoder);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("density"), timestamp_writes: None });
        self.dispatch_particles(&mut pass, &self.pipelines.density, &self.groups[self.current].density);
        drop(pass);
        self.fields_state = self.current;
        self.accelerations_valid = false;
        self.ctx.queue.submit([encoder.finish()]);
    }

    /// The ids of the particles in cell order and the cell starts, after binning the current
    /// state (for the binning tests).
    pub fn binning(&mut self) -> anyhow::Result<(Vec<u32>, Vec<u32>)> {
        self.refresh_fields();
        let n = self.fluid_count as u64;
        let cells = self.params.grid.cell_count() as u64;
        let data = read_buffers(&self.ctx, &[(&self.state[self.current].positions, n * 16), (&self.starts, (cells + 1) * 4)])?;
        Ok((ids_of(bytemuck::cast_slice(&data[0])), bytemuck::pod_collect_to_vec(&data[1])))
    }

    /// The buffers holding the current particle state (they alternate between two pairs as the
    /// solver steps: ask again after stepping). Particles are in cell order; the w component of
    /// each position holds the particle's original index as u32 bits. `densities` and
    /// `pressures` are in the same order after a snapshot.
    pub fn particle_buffers(&self) -> ParticleBuffers<'_> {
        let st = &self.state[self.current];
        ParticleBuffers {
            positions: &st.positions,
            velocities: &st.velocities,
            densities: &self.densities,
            pressures: &self.pressures,
            count: self.fluid_count,
        }
    }

    /// The status words, checked to count as many steps as the host did (for saved states).
    pub(super) fn counted_status(&self) -> anyhow::Result<[u32; STATUS_WORDS as usize]> {
        let status = self.read_status()?;
        anyhow::ensure!(status[0] as u64 == self.steps % (1 << 32), "the GPU counted {} steps, the host {}", status[0], self.steps);
        Ok(status)
    }

    fn read_status(&self) -> anyhow::Result<[u32; STATUS_WORDS as usize]> {
        let data = read_buffers(&self.ctx, &[(&self.status, STATUS_WORDS * 4)])?;
        let words: Vec<u32> = bytemuck::pod_collect_to_vec(&data[0]);
        Ok(words.try_into().expect("status has STATUS_WORDS words"))
    }

    /// Bytes of every buffer the solver allocated on the device (its [`MemoryPlan`]'s total).
    pub fn memory_bytes(&self) -> u64 {
        self.memory
    }

    /// Bytes of the buffers as created, summed from the buffers themselves (to check the plan).
    pub fn allocated_bytes(&self) -> u64 {
        let s = self;
        // With the fused step the accelerations exist only after `step_fields` asked for them.
        let planned_accelerations = s.accelerations.as_ref().filter(|_| !s.pipelines.fused).map(|a| &a.buffer);
        [&s.uniform, &s.starts, &s.densities, &s.pressures, &s.placeholder, &s.status, &s.wall_positions, &s.wall_starts]
            .into_iter()
            .chain(planned_accelerations)
            .map(|b| b.size())
            .chain(s.state.iter().flat_map(|st| [st.positions.size(), st.velocities.size()]))
            .sum::<u64>()
            + s.scan.bytes()
    }
}

/// The GPU buffers of the particle state, for rendering or post-processing on the GPU.
#[derive(Clone, Copy, Debug)]
pub struct ParticleBuffers<'a> {
    /// `array<vec4<f32>>`: x, y, z, and in w the original index of the particle in each slot
    /// (u32 bits).
    pub positions: &'a wgpu::Buffer,
    /// `array<vec4<f32>>`: vx, vy, vz, 0.
    pub velocities: &'a wgpu::Buffer,
    /// `array<f32>`.
    pub densities: &'a wgpu::Buffer,
    /// `array<f32>`.
    pub pressures: &'a wgpu::Buffer,
    /// Number of fluid particles (elements of each array).
    pub count: u32,
}

/// Copies `buffers` (their first `bytes` each) to mappable staging buffers and reads them back
/// (waits for the GPU).
pub fn read_buffers(ctx: &GpuContext, buffers: &[(&wgpu::Buffer, u64)]) -> anyhow::Result<Vec<Vec<u8>>> {
    let ranges: Vec<(&wgpu::Buffer, u64, u64)> = buffers.iter().map(|&(buffer, bytes)| (buffer, 0, bytes)).collect();
    read_ranges(ctx, &ranges)
}

/// Copies byte ranges `(buffer, offset, bytes)` to mappable staging buffers and reads them back
/// (waits for the GPU). Copies are made in whole 4-byte words, as wgpu requires.
pub fn read_ranges(ctx: &GpuContext, ranges: &[(&wgpu::Buffer, u64, u64)]) -> anyhow::Result<Vec<Vec<u8>>> {
    let device = &ctx.device;
    let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("readback") });
    let staging: Vec<wgpu::Buffer> = ranges
        .iter()
        .map(|&(src, offset, bytes)| {
            let size = bytes.max(4).next_multiple_of(4);
            let dst = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("staging"),
                size,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            encoder.copy_buffer_to_buffer(src, offset, &dst, 0, size);
            dst
        })
        .collect();
    ctx.queue.submit([encoder.finish()]);
    let (tx, rx) = std::sync::mpsc::channel();
    for (i, s) in staging.iter().enumerate() {
        let tx = tx.clone();
        s.slice(..).map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send((i, r));
        });
    }
    device.poll(wgpu::PollType::Wait { submission_index: None, timeout: None })?;
    for _ in 0..staging.len() {
        let (i, r) = rx.recv()?;
        r.map_err(|e| anyhow::anyhow!("mapping readback buffer {i} failed: {e}"))?;
    }
    let out = staging
        .iter()
        .zip(ranges)
        .map(|(s, &(_, _, bytes))| s.slice(..).get_mapped_range().expect("mapped above")[..bytes as usize].to_vec())
        .collect();
    for s in &staging {
        s.unmap();
    }
    Ok(out)
}

/// The health counters in the status words (wgsl/integrate.wgsl).
pub(super) fn health_of(s: &[u32]) -> Health {
    Health {
        non_finite: s[1] as u64,
        escaped: s[2] as u64,
        first_bad_step: (s[3] != NO_BAD_STEP).then_some(s[3] as u64),
        max_density: f32::from_bits(s[4]) as f64,
    }
}

fn unpermute<T: Copy + Default>(ids: &[u32], values: impl Iterator<Item = T>) -> Vec<T> {
    let mut out = vec![T::default(); ids.len()];
    for (slot, v) in values.enumerate() {
        out[ids[slot] as usize] = v;
    }
    out
}

fn widen(v: &[f32; 4]) -> [f64; 3] {
    [v[0] as f64, v[1] as f64, v[2] as f64]
}

impl Backend for GpuSolver {
    fn kind(&self) -> &'static str {
        "gpu"
    }
    fn adapter(&self) -> String {
        self.ctx.describe()
    }
    fn params(&self) -> &Params {
        &self.params
    }
    fn fluid_count(&self) -> usize {
        self.fluid_count as usize
    }
    fn wall_count(&self) -> usize {
        self.wall_count as usize
    }
    fn step(&mut self, n: u64) -> anyhow::Result<()> {
        self.advance(n);
        Ok(())
    }
    fn steps_done(&self) -> u64 {
        self.steps
    }
    fn time(&self) -> f64 {
        if self.params.adaptive.is_none() {
            return self.steps as f64 * self.params.dt;
        }
        // A few bytes: the compensated sum of the steps' dt (wgsl/integrate.wgsl choose_dt).
        match read_buffers(&self.ctx, &[(&self.status, STATUS_WORDS * 4)]) {
            Ok(data) => {
                let w: Vec<u32> = bytemuck::pod_collect_to_vec(&data[0]);
                f32::from_bits(w[8]) as f64 - f32::from_bits(w[9]) as f64
            }
            Err(e) => {
                log::error!("reading the simulated time failed: {e:#}");
                f64::NAN
            }
        }
    }
    fn dt_stats(&mut self) -> anyhow::Result<DtStats> {
        let Some(_) = self.params.adaptive else {
            return Ok(DtStats::fixed(self.params.dt));
        };
        let s = self.read_status()?;
        let f = |i: usize| f32::from_bits(s[i]) as f64;
        let time = f(8) - f(9);
        Ok(if self.steps == 0 {
            DtStats::default()
        } else {
            DtStats { min: f(10), max: f(11), mean: time / self.steps as f64, last: f(7) }
        })
    }
    fn memory_bytes(&self) -> Option<u64> {
        Some(self.memory)
    }
    fn health(&mut self) -> anyhow::Result<Health> {
        Ok(health_of(&self.read_status()?))
    }
    fn snapshot(&mut self) -> anyhow::Result<Snapshot> {
        self.refresh_fields();
        let n = self.fluid_count as u64;
        let st = &self.state[self.current];
        let data = read_buffers(&self.ctx, &[(&st.positions, n * 16), (&st.velocities, n * 16), (&self.densities, n * 4), (&self.pressures, n * 4)])?;
        let pos: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&data[0]);
        let ids = ids_of(&pos);
        let vel: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&data[1]);
        let rho: Vec<f32> = bytemuck::pod_collect_to_vec(&data[2]);
        let p: Vec<f32> = bytemuck::pod_collect_to_vec(&data[3]);
        Ok(Snapshot {
            step: self.steps,
            time: self.time(),
            positions: unpermute(&ids, pos.iter().map(widen)),
            velocities: unpermute(&ids, vel.iter().map(widen)),
            densities: unpermute(&ids, rho.iter().map(|&v| v as f64)),
            pressures: unpermute(&ids, p.iter().map(|&v| v as f64)),
        })
    }
    fn write_snapshot_streamed(&mut self, files: &[(crate::export::SnapshotFormat, std::path::PathBuf)]) -> Option<anyhow::Result<StreamedSnapshot>> {
        Some(self.write_snapshot_in_pieces(files, STREAM_CHUNK))
    }
    fn write_state_streamed(&mut self, w: &mut dyn std::io::Write) -> Option<anyhow::Result<()>> {
        Some(self.write_state_in_pieces(w, STREAM_CHUNK))
    }
    fn gpu_particles(&self) -> Option<(GpuContext, crate::render::ParticleBuffers)> {
        let st = &self.state[self.current];
        Some((
            self.ctx.clone(),
            crate::render::ParticleBuffers {
                positions: st.positions.clone(),
                velocities: st.velocities.clone(),
                densities: self.densities.clone(),
                pressures: self.pressures.clone(),
                count: self.fluid_count,
            },
        ))
    }
    fn save_state(&mut self) -> anyhow::Result<BackendState> {
        // One description of the saved state: the encoding the checkpoints stream, decoded.
        let mut bytes = Vec::new();
        self.write_state_in_pieces(&mut bytes, STREAM_CHUNK)?;
        postcard::from_bytes(&bytes).map_err(|e| anyhow::anyhow!("cannot decode the GPU state: {e}"))
    }
    fn restore_state(&mut self, state: &BackendState) -> anyhow::Result<()> {
        state.check_fits("gpu", self.fluid_count as usize)?;
        upload_state(&self.ctx, &self.state[0], &state.positions, &state.velocities, |i| state.ids[i]);
        let q = &self.ctx.queue;
        anyhow::ensure!(
            state.gpu_status.len() == STATUS_WORDS as usize,
            "the state holds {} status words; this solver has {STATUS_WORDS}",
            state.gpu_status.len()
        );
        let status = &state.gpu_status;
        q.write_buffer(&self.status, 0, bytemuck::cast_slice(status));
        q.submit([]);
        self.current = 0;
        self.fields_state = 0;
        self.accelerations_valid = false;
        self.steps = state.step;
        Ok(())
    }
    fn step_fields(&mut self) -> anyhow::Result<StepFields> {
        let n = self.fluid_count as u64;
        self.ensure_accelerations();
        let acc = &self.accelerations.as_ref().expect("ensured").buffer;
        let data = read_buffers(&self.ctx, &[
            (&self.densities, n * 4),
            (&self.pressures, n * 4),
            (acc, n * 16),
            (&self.state[self.fields_state].positions, n * 16),
        ])?;
        let ids = ids_of(bytemuck::cast_slice(&data[3]));
        let rho: Vec<f32> = bytemuck::pod_collect_to_vec(&data[0]);
        let p: Vec<f32> = bytemuck::pod_collect_to_vec(&data[1]);
        let acc: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&data[2]);
        Ok(StepFields {
            densities: unpermute(&ids, rho.iter().map(|&v| v as f64)),
            pressures: unpermute(&ids, p.iter().map(|&v| v as f64)),
            accelerations: unpermute(&ids, acc.iter().map(widen)),
        })
    }
}
