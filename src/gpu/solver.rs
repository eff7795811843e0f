//! The GPU solver: structure-of-arrays storage buffers, the pipelines of every stage, and the
//! dispatch order of a step. The step loop only records dispatches; nothing is read back, waited
//! for or created inside it.

use super::device::GpuContext;
use super::memory::MemoryPlan;
use super::pipelines::{bind_group, constants, dispatch_size, stage, Stage, Use, WORKGROUP_SIZE};
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

/// Particle state that is reordered every step (ping-pong pair).
struct StateBuffers {
    positions: wgpu::Buffer,
    velocities: wgpu::Buffer,
    ids: wgpu::Buffer,
}

/// Bind groups of one parity: reading state `c`, writing state `1 - c`.
struct ParityBindGroups {
    bin_count: wgpu::BindGroup,
    reorder: wgpu::BindGroup,
    density: wgpu::BindGroup,
    forces: wgpu::BindGroup,
    integrate: wgpu::BindGroup,
}

struct Pipelines {
    bin_count: Stage,
    bin_scatter: Stage,
    reorder: Stage,
    density: Stage,
    forces: Stage,
    integrate: Stage,
    finish_step: Stage,
    /// Adaptive dt only: the reduction of |v|max and |a|max, and the choice of dt.
    adaptive: Option<(Stage, Stage)>,
}

/// Steps per command buffer: enough to amortise submission, few enough to check health often.
pub const STEPS_PER_SUBMIT: u64 = 32;

/// The status buffer: health counters, and the adaptive step's maxima, dt and time (see
/// wgsl/integrate.wgsl).
const STATUS_WORDS: u64 = 12;
pub(super) const STATUS_BYTES: u64 = STATUS_WORDS * 4;
const NO_BAD_STEP: u32 = u32::MAX;

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
    /// Which of `state` orders the accelerations of the last step.
    accel_state: usize,
    _keys: wgpu::Buffer,
    _ranks: wgpu::Buffer,
    _unordered: wgpu::Buffer,
    /// Cell counts, scanned in place into cell starts (cells + 1 values).
    starts: wgpu::Buffer,
    densities: wgpu::Buffer,
    pressures: wgpu::Buffer,
    accelerations: wgpu::Buffer,
    status: wgpu::Buffer,
    _wall_positions: wgpu::Buffer,
    _wall_starts: wgpu::Buffer,
    scan: Scan,
    pipelines: Pipelines,
    groups: [ParityBindGroups; 2],
    scatter_group: wgpu::BindGroup,
    finish_group: wgpu::BindGroup,
    steps: u64,
    dispatch: (u32, u32),
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

fn b(buf: &wgpu::Buffer) -> wgpu::BindingResource<'_> {
    buf.as_entire_binding()
}

fn vec4s(points: &[[f64; 3]], w: impl Fn(usize) -> f32) -> Vec<[f32; 4]> {
    points.iter().enumerate().map(|(i, p)| [p[0] as f32, p[1] as f32, p[2] as f32, w(i)]).collect()
}

impl GpuSolver {
    /// Uploads a scene's particles and builds every pipeline and bind group.
    pub fn new(ctx: GpuContext, params: &Params, initial: &InitialState) -> anyhow::Result<Self> {
        let n = initial.fluid_positions.len() as u64;
        let cells = params.grid.cell_count() as u64;
        let viscosity = params.viscosity_at_step(0);
        let gpu_params = GpuParams::new(params, n as u32, initial.wall_positions.len() as u32, viscosity);
        // Every buffer is checked against the device's limits before the first is created.
        let plan = MemoryPlan::new(n, Some(initial.wall_positions.len() as u64), cells, gpu_params.bytes().len() as u64);
        plan.check(&ctx)?;
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
        // Without walls the shaders never read the wall arrays (WALLS = false): no per-cell array.
        let has_walls = !initial.wall_positions.is_empty();
        let wall_starts = if has_walls { wall_starts } else { Vec::new() };
        let wall_starts_buf = storage_init(device, "wall cell starts", bytemuck::cast_slice(&wall_starts));

        let positions = vec4s(&initial.fluid_positions, |_| 0.0);
        let velocities = vec4s(&initial.fluid_velocities, |_| 0.0);
        let ids: Vec<u32> = (0..n as u32).collect();
        let state0 = StateBuffers {
            positions: storage_init(device, "positions 0", bytemuck::cast_slice(&positions)),
            velocities: storage_init(device, "velocities 0", bytemuck::cast_slice(&velocities)),
            ids: storage_init(device, "ids 0", bytemuck::cast_slice(&ids)),
        };
        let state1 = StateBuffers {
            positions: storage(device, "positions 1", n * 16, wgpu::BufferUsages::empty()),
            velocities: storage(device, "velocities 1", n * 16, wgpu::BufferUsages::empty()),
            ids: storage(device, "ids 1", n * 4, wgpu::BufferUsages::empty()),
        };
        let keys = storage(device, "cell keys", n * 4, wgpu::BufferUsages::empty());
        let ranks = storage(device, "ranks in cell", n * 4, wgpu::BufferUsages::empty());
        let unordered = storage(device, "unordered cell slots", n * 4, wgpu::BufferUsages::empty());
        let starts = storage(device, "cell starts", (cells + 1) * 4, wgpu::BufferUsages::empty());
        let densities = storage(device, "densities", n * 4, wgpu::BufferUsages::empty());
        let pressures = storage(device, "pressures", n * 4, wgpu::BufferUsages::empty());
        let accelerations = storage(device, "accelerations", n * 16, wgpu::BufferUsages::empty());
        let mut status_init = [0u32; STATUS_WORDS as usize];
        status_init[3] = NO_BAD_STEP;
        status_init[10] = f32::INFINITY.to_bits();
        let status = storage_init(device, "status", bytemuck::cast_slice(&status_init));
        let scan = Scan::new(device, &uniform, &starts, cells + 1);

        let mut k = constants(params);
        k.push(("WALLS", if has_walls { 1.0 } else { 0.0 }));
        use Use::*;
        let integrate_uses = [Uniform, ReadWrite, ReadWrite, Read, ReadWrite];
        let pipelines = Pipelines {
            bin_count: stage(device, "bin_count", "main", &[Uniform, Read, ReadWrite, ReadWrite, ReadWrite], &k),
            bin_scatter: stage(device, "bin_scatter", "main", &[Uniform, Read, Read, Read, ReadWrite], &k),
            reorder: stage(
                device,
                "reorder",
                "main",
                &[Uniform, Read, Read, Read, Read, Read, Read, ReadWrite, ReadWrite, ReadWrite],
                &k,
            ),
            density: stage(device, "density", "main", &[Uniform, Read, Read, Read, Read, ReadWrite, ReadWrite, ReadWrite], &k),
            forces: stage(device, "forces", "main", &[Uniform, Read, Read, Read, Read, Read, Read, Read, ReadWrite], &k),
            integrate: stage(device, "integrate", "main", &integrate_uses, &k),
            finish_step: stage(device, "integrate", "finish_step", &integrate_uses, &k),
            adaptive: params.adaptive.map(|_| {
                (stage(device, "integrate", "reduce_maxima", &integrate_uses, &k), stage(device, "integrate", "choose_dt", &integrate_uses, &k))
            }),
        };
        let state = [state0, state1];
        let u = uniform.as_entire_binding();
        let make_parity = |c: usize| {
            let (src, dst) = (&state[c], &state[1 - c]);
            ParityBindGroups {
                bin_count: bind_group(device, "bin_count", &pipelines.bin_count.layout, &[u.clone(), b(&src.positions), b(&keys), b(&ranks), b(&starts)]),
                reorder: bind_group(
                    device,
                    "reorder",
                    &pipelines.reorder.layout,
                    &[
                        u.clone(),
                        b(&keys),
                        b(&starts),
                        b(&unordered),
                        b(&src.positions),
                        b(&src.velocities),
                        b(&src.ids),
                        b(&dst.positions),
                        b(&dst.velocities),
                        b(&dst.ids),
                    ],
                ),
                density: bind_group(
                    device,
                    "density",
                    &pipelines.density.layout,
                    &[u.clone(), b(&dst.positions), b(&starts), b(&wall_positions), b(&wall_starts_buf), b(&densities), b(&pressures), b(&status)],
                ),
                forces: bind_group(
                    device,
                    "forces",
                    &pipelines.forces.layout,
                    &[
                        u.clone(),
                        b(&dst.positions),
                        b(&dst.velocities),
                        b(&densities),
                        b(&pressures),
                        b(&starts),
                        b(&wall_positions),
                        b(&wall_starts_buf),
                        b(&accelerations),
                    ],
                ),
                integrate: bind_group(
                    device,
                    "integrate",
                    &pipelines.integrate.layout,
                    &[u.clone(), b(&dst.positions), b(&dst.velocities), b(&accelerations), b(&status)],
                ),
            }
        };
        let groups = [make_parity(0), make_parity(1)];
        let scatter_group =
            bind_group(device, "bin_scatter", &pipelines.bin_scatter.layout, &[u.clone(), b(&keys), b(&ranks), b(&starts), b(&unordered)]);
        let finish_group = bind_group(
            device,
            "finish_step",
            &pipelines.finish_step.layout,
            &[u.clone(), b(&state[0].positions), b(&state[0].velocities), b(&accelerations), b(&status)],
        );
        let dispatch = dispatch_size(n, WORKGROUP_SIZE, device.limits().max_compute_workgroups_per_dimension);
        let memory = plan.total();
        Ok(GpuSolver {
            params: params.clone(),
            fluid_count: n as u32,
            wall_count: initial.wall_positions.len() as u32,
            uniform,
            uniform_viscosity: viscosity,
            state,
            current: 0,
            accel_state: 0,
            _keys: keys,
            _ranks: ranks,
            _unordered: unordered,
            starts,
            densities,
            pressures,
            accelerations,
            status,
            _wall_positions: wall_positions,
            _wall_starts: wall_starts_buf,
            scan,
            pipelines,
            groups,
            scatter_group,
            finish_group,
            steps: 0,
            dispatch,
            memory,
            ctx,
        })
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
        pass.dispatch_workgroups(self.dispatch.0, self.dispatch.1, 1);
    }

    /// Records the binning (count, scan, scatter, reorder) of the current state into the other
    /// buffer of the pair, and flips `current`.
    fn record_bin(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.clear_buffer(&self.starts, 0, None);
        let g = &self.groups[self.current];
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("binning"), timestamp_writes: None });
        self.dispatch_particles(&mut pass, &self.pipelines.bin_count, &g.bin_count);
        self.scan.record(&mut pass);
        self.dispatch_particles(&mut pass, &self.pipelines.bin_scatter, &self.scatter_group);
        self.dispatch_particles(&mut pass, &self.pipelines.reorder, &g.reorder);
        drop(pass);
    }

    /// Records one full step. The neighbour grid is rebuilt every `rebuild_every` steps; in
    /// between, the stages work on the current buffers in place with the cells of the last
    /// rebuild (the bind groups of the other parity write to them).
    fn record_step(&mut self, encoder: &mut wgpu::CommandEncoder) {
        let rebuild = self.steps % self.params.rebuild_every.max(1) as u64 == 0;
        let parity = if rebuild { self.current } else { 1 - self.current };
        if rebuild {
            self.record_bin(encoder);
        }
        encoder.clear_buffer(&self.status, 4, Some(8));
        let g = &self.groups[parity];
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("step"), timestamp_writes: None });
        self.dispatch_particles(&mut pass, &self.pipelines.density, &g.density);
        self.dispatch_particles(&mut pass, &self.pipelines.forces, &g.forces);
        self.record_integration(&mut pass, g);
        drop(pass);
        self.current = 1 - parity;
        self.accel_state = self.current;
    }

    /// The integration with its bookkeeping: the adaptive step's reduction and choice of dt,
    /// the integration itself and the per-step status update.
    fn record_integration(&self, pass: &mut wgpu::ComputePass, g: &ParityBindGroups) {
        if let Some((reduce, choose)) = &self.pipelines.adaptive {
            self.dispatch_particles(pass, reduce, &g.integrate);
            pass.set_pipeline(&choose.pipeline);
            pass.set_bind_group(0, &g.integrate, &[]);
            pass.dispatch_workgroups(1, 1, 1);
        }
        self.dispatch_particles(pass, &self.pipelines.integrate, &g.integrate);
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

    /// Advances `n` steps, `STEPS_PER_SUBMIT` per command buffer; a viscosity change from the
    /// schedule starts a new command buffer after a uniform write.
    pub fn advance(&mut self, n: u64) {
        let mut left = n;
        // Without a schedule the viscosity never changes: no per-step look-up.
        let scheduled = self.params.viscosity.len() > 1;
        while left > 0 {
            let nu = self.params.viscosity_at_step(self.steps);
            self.set_viscosity(nu);
            let mut encoder = self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("steps") });
            let mut batch = 0;
            while batch < left.min(STEPS_PER_SUBMIT) {
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
        let parity = self.current;
        self.record_bin(&mut encoder);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("density"), timestamp_writes: None });
        self.dispatch_particles(&mut pass, &self.pipelines.density, &self.groups[parity].density);
        drop(pass);
        self.current = 1 - parity;
        self.ctx.queue.submit([encoder.finish()]);
    }

    /// The ids of the particles in cell order and the cell starts, after binning the current
    /// state (for the binning tests).
    pub fn binning(&mut self) -> anyhow::Result<(Vec<u32>, Vec<u32>)> {
        self.refresh_fields();
        let n = self.fluid_count as u64;
        let cells = self.params.grid.cell_count() as u64;
        let data = read_buffers(&self.ctx, &[(&self.state[self.current].ids, n * 4), (&self.starts, (cells + 1) * 4)])?;
        Ok((bytemuck::pod_collect_to_vec(&data[0]), bytemuck::pod_collect_to_vec(&data[1])))
    }

    /// The buffers holding the current particle state (they alternate between two pairs as the
    /// solver steps: ask again after stepping). Particles are in cell order; `ids` maps each
    /// slot to the particle's original index. `densities` and `pressures` are in the same order
    /// after a snapshot.
    pub fn particle_buffers(&self) -> ParticleBuffers<'_> {
        let st = &self.state[self.current];
        ParticleBuffers {
            positions: &st.positions,
            velocities: &st.velocities,
            ids: &st.ids,
            densities: &self.densities,
            pressures: &self.pressures,
            count: self.fluid_count,
        }
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
        [&s.uniform, &s._keys, &s._ranks, &s._unordered, &s.starts, &s.densities, &s.pressures, &s.accelerations, &s.status, &s._wall_positions, &s._wall_starts]
            .iter()
            .map(|b| b.size())
            .chain(s.state.iter().flat_map(|st| [st.positions.size(), st.velocities.size(), st.ids.size()]))
            .sum::<u64>()
            + s.scan.bytes()
    }
}

/// The GPU buffers of the particle state, for rendering or post-processing on the GPU.
#[derive(Clone, Copy, Debug)]
pub struct ParticleBuffers<'a> {
    /// `array<vec4<f32>>`: x, y, z, 0.
    pub positions: &'a wgpu::Buffer,
    /// `array<vec4<f32>>`: vx, vy, vz, 0.
    pub velocities: &'a wgpu::Buffer,
    /// `array<u32>`: the original index of the particle in each slot.
    pub ids: &'a wgpu::Buffer,
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
        let s = self.read_status()?;
        Ok(Health {
            non_finite: s[1] as u64,
            escaped: s[2] as u64,
            first_bad_step: (s[3] != NO_BAD_STEP).then_some(s[3] as u64),
            max_density: f32::from_bits(s[4]) as f64,
        })
    }
    fn snapshot(&mut self) -> anyhow::Result<Snapshot> {
        self.refresh_fields();
        let n = self.fluid_count as u64;
        let st = &self.state[self.current];
        let data = read_buffers(&self.ctx, &[
            (&st.positions, n * 16),
            (&st.velocities, n * 16),
            (&st.ids, n * 4),
            (&self.densities, n * 4),
            (&self.pressures, n * 4),
        ])?;
        let ids: Vec<u32> = bytemuck::pod_collect_to_vec(&data[2]);
        let pos: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&data[0]);
        let vel: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&data[1]);
        let rho: Vec<f32> = bytemuck::pod_collect_to_vec(&data[3]);
        let p: Vec<f32> = bytemuck::pod_collect_to_vec(&data[4]);
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
        let n = self.fluid_count as u64;
        let st = &self.state[self.current];
        let data = read_buffers(&self.ctx, &[(&st.positions, n * 16), (&st.velocities, n * 16), (&st.ids, n * 4)])?;
        let pos: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&data[0]);
        let vel: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&data[1]);
        let status = self.read_status()?;
        anyhow::ensure!(status[0] as u64 == self.steps % (1 << 32), "the GPU counted {} steps, the host {}", status[0], self.steps);
        Ok(BackendState {
            kind: "gpu".into(),
            step: self.steps,
            positions: pos.iter().map(widen).collect(),
            velocities: vel.iter().map(widen).collect(),
            ids: bytemuck::pod_collect_to_vec(&data[2]),
            non_finite: status[1] as u64,
            escaped: status[2] as u64,
            first_bad_step: (status[3] != NO_BAD_STEP).then_some(status[3] as u64),
            max_density: f32::from_bits(status[4]) as f64,
            time: 0.0,
            dt_min_max_last: [0.0; 3],
            gpu_status: status.to_vec(),
        })
    }
    fn restore_state(&mut self, state: &BackendState) -> anyhow::Result<()> {
        state.check_fits("gpu", self.fluid_count as usize)?;
        // The w components are 0, as the integration writes them.
        let pos = vec4s(&state.positions, |_| 0.0);
        let vel = vec4s(&state.velocities, |_| 0.0);
        let st = &self.state[0];
        let q = &self.ctx.queue;
        q.write_buffer(&st.positions, 0, bytemuck::cast_slice(&pos));
        q.write_buffer(&st.velocities, 0, bytemuck::cast_slice(&vel));
        q.write_buffer(&st.ids, 0, bytemuck::cast_slice(&state.ids));
        anyhow::ensure!(
            state.gpu_status.len() == STATUS_WORDS as usize,
            "the state holds {} status words; this solver has {STATUS_WORDS}",
            state.gpu_status.len()
        );
        let status = &state.gpu_status;
        q.write_buffer(&self.status, 0, bytemuck::cast_slice(status));
        q.submit([]);
        self.current = 0;
        self.accel_state = 0;
        self.steps = state.step;
        Ok(())
    }
    fn step_fields(&mut self) -> anyhow::Result<StepFields> {
        let n = self.fluid_count as u64;
        let data = read_buffers(&self.ctx, &[
            (&self.densities, n * 4),
            (&self.pressures, n * 4),
            (&self.accelerations, n * 16),
            (&self.state[self.accel_state].ids, n * 4),
        ])?;
        let ids: Vec<u32> = bytemuck::pod_collect_to_vec(&data[3]);
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
