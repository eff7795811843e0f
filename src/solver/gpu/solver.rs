//! The GPU solver: structure-of-arrays storage buffers, the pipelines of every stage and their
//! bind groups, built once per scene, and the [`Backend`] the layers above drive. The order in
//! which a step dispatches the stages is recorded in one place, `schedule.rs`; nothing is read
//! back, waited for or created while steps are recorded.

use super::buffers::{ids_of, storage, storage_init, unpermute, vec4s, widen, NeighbourLists, ParticleBuffers, StateLayout, StateStore, STREAM_CHUNK};
use super::device::{GpuContext, GpuError};
use super::memory::{MemoryPlan, StepArrays};
use super::pipelines::{array_places, sized, Pipelines, StepShape, WcsphStages, IN_PLACE};
use super::params::{status, GpuParams};
use super::prefix_sum::Scan;
use super::probes::{DfsphSums, GpuProbes};
use super::readback::{read_buffers, visit_array, visit_pairs, visit_rows, Element, RowArrays};
use super::shaders::{stage_with_aliases, Alias, ArrayLengths, Stage};
use super::dfsph::{solve_threads, DfsphBuffers, DfsphGpu, DfsphStages, GhostVelocities, RankSolves, SharedBuffers};
use super::workgroups::{GpuOptions, SolverLoop};
use crate::model::initial::InitialState;
use crate::model::params::Params;
use crate::model::probes::ProbeSample;
use crate::model::state::{BackendState, DtStats, Health, Snapshot, StepFields};
use crate::solver::backend::{Backend, SnapshotRow, StateArray, StatePiece};
use wgpu::util::DeviceExt;

/// Steps per command buffer: enough to amortise submission, few enough to check health often.
pub const STEPS_PER_SUBMIT: u64 = 32;

/// Bind groups of one phase of the state (see [`StateStore`]): reading its buffers, and writing
/// those of the phase after it where a stage writes another state.
pub(super) struct ParityBindGroups {
    pub bin_count: wgpu::BindGroup,
    pub bin_scatter: wgpu::BindGroup,
    /// The reorder's destinations, then its gathering of the positions and of the velocities.
    pub reorder_rank: wgpu::BindGroup,
    pub reorder: [wgpu::BindGroup; 2],
    /// The weakly compressible step's (`None` with DFSPH).
    pub wcsph: Option<WcsphBindGroups>,
}

/// The weakly compressible step's bind groups of one parity.
pub(super) struct WcsphBindGroups {
    pub density: wgpu::BindGroup,
    /// With a neighbour skin and lists: the density over the lists of the last rebuild.
    pub density_listed: Option<wgpu::BindGroup>,
    /// With the Adami wall pressure: the wall stage's.
    pub wall_pressure: Option<wgpu::BindGroup>,
    /// With surface tension: the normals stage's.
    pub surface_normals: Option<wgpu::BindGroup>,
    /// The forces into the state's spare buffer (the state in place; the fused step makes its
    /// forces' groups on request, see `GpuSolver::accelerations`).
    pub forces: Option<wgpu::BindGroup>,
    /// The integration (after `forces`, adaptive dt) or the fused forces and integration.
    pub advance: wgpu::BindGroup,
}

/// How full the neighbour lists are (see [`GpuSolver::neighbour_list_usage`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ListUsage {
    /// The slots of each list.
    pub slots: u32,
    /// The most slots one list that fit used.
    pub longest: u32,
    /// The particles whose lists overflowed.
    pub full: u64,
}

/// The fused step's accelerations array, made on request, with the forces' bind groups of each
/// parity.
pub(super) struct Accelerations {
    pub buffer: wgpu::Buffer,
    pub groups: [wgpu::BindGroup; 2],
}

pub struct GpuSolver {
    pub(super) ctx: GpuContext,
    pub(super) params: Params,
    pub(super) fluid_count: u32,
    pub(super) wall_count: u32,
    pub(super) uniform: wgpu::Buffer,
    /// Viscosity currently in the uniform block.
    pub(super) uniform_viscosity: f64,
    /// The particle state's buffers and their roles in each phase.
    pub(super) store: StateStore,
    /// The phase of `store` that holds the current particles.
    pub(super) current: usize,
    /// The phase the densities and pressures (and accelerations, when valid) belong to: the
    /// state the last step or refresh evaluated them on (in place, the state the step then
    /// advanced, in the same slots).
    pub(super) fields_state: usize,
    /// Whether `accelerations` holds the accelerations of `fields_state`.
    pub(super) accelerations_valid: bool,
    /// Cell counts, scanned in place into cell starts (cells + 1 values).
    pub(super) starts: wgpu::Buffer,
    /// With the continuity equation and DFSPH (a summed density lives in the w of the
    /// velocities); also the reorder's destinations (u32), dead once the state is reordered.
    pub(super) densities: Option<wgpu::Buffer>,
    /// DFSPH only (the weakly compressible step's pressure is its density's, through the
    /// equation of state).
    pub(super) pressures: Option<wgpu::Buffer>,
    /// The fused step's, created on the first `step_fields` (in place the accelerations live in
    /// the state's spare buffer).
    pub(super) accelerations: Option<Accelerations>,
    /// Bound where a fused stage declares the accelerations it does not use.
    pub(super) placeholder: wgpu::Buffer,
    pub(super) status: wgpu::Buffer,
    pub(super) wall_positions: wgpu::Buffer,
    /// The wall cell index (`WallCellIndex`): per block of cells a mask and a count, and the
    /// starts of the cells that hold walls, with room for more across ranks.
    pub(super) wall_cell_blocks: wgpu::Buffer,
    pub(super) wall_cell_firsts: wgpu::Buffer,
    /// With the Adami wall pressure: each sorted wall particle's pressure and density
    /// (`vec2<f32>`).
    pub(super) wall_fields: Option<wgpu::Buffer>,
    /// With surface tension: each fluid particle's normal (surface_normals.wgsl).
    pub(super) normals: Option<wgpu::Buffer>,
    /// The neighbour lists, where the step keeps them.
    pub(super) neighbour_lists: Option<NeighbourLists>,
    /// The neighbour skin, where the options ask for one.
    pub(super) skin: Option<super::skin::NeighbourSkin>,
    /// The original index of each sorted wall particle.
    pub(super) wall_order: Vec<u32>,
    pub(super) scan: Scan,
    pub(super) pipelines: Pipelines,
    /// Per phase of `store`.
    pub(super) groups: Vec<ParityBindGroups>,
    pub(super) finish_group: wgpu::BindGroup,
    /// DFSPH's stages, arrays and bind groups, when the scene uses it.
    pub(super) dfsph: Option<DfsphGpu>,
    /// How a DFSPH solve's loop ends.
    pub(super) solver_loop: SolverLoop,
    /// DFSPH with [`SolverLoop::Adaptive`]: the iterations each solve (0: divergence, 1:
    /// constant density) recorded past its warm start in the last step that read them back.
    pub(super) last_iterations: std::cell::Cell<[u32; 2]>,
    /// DFSPH: the bind groups of `step_accelerations` of each phase, made on request.
    pub(super) step_accelerations_groups: Option<Vec<wgpu::BindGroup>>,
    pub(super) steps: u64,
    /// The adapter's `max_compute_workgroups_per_dimension`.
    pub(super) max_groups_per_dim: u32,
    /// Steps per command buffer.
    pub(super) steps_per_submit: u64,
    /// The probe stage, in a scene with probes.
    pub(super) probes: Option<GpuProbes>,
    /// Across ranks (src/solver/gpu/ranks.rs): the ranks, with which the adaptive step takes the
    /// largest speed and acceleration of every rank's own particles before choosing dt.
    pub(super) ranks: Option<std::sync::Arc<dyn crate::solver::communicator::Communicator>>,
    /// Why the last step's collective failed (across ranks), until the rank reads it.
    pub(super) rank_error: std::cell::RefCell<Option<String>>,
    /// DFSPH across ranks: the ghosts and iterations of the solves under way (set by the rank
    /// for each step or refresh).
    pub(super) rank_solves: std::cell::RefCell<Option<RankSolves>>,
    /// DFSPH across ranks: the gather and scatter of the ghosts' velocities, made on first use.
    pub(super) ghost_velocities: std::cell::OnceCell<GhostVelocities>,
    /// DFSPH across ranks: where the ghost link's cells lie in the binning, made on first use.
    pub(super) ghost_link_cells: std::cell::OnceCell<super::dfsph::GhostLinkCells>,
    /// Bytes of every buffer the solver allocated.
    memory: u64,
    /// The buffers the solver planned and allocated (the probes' besides, in `memory`).
    plan: MemoryPlan,
    /// The arrays the step keeps, and the specialisation constants of its stages (for stages
    /// made later).
    arrays: StepArrays,
    constants: Vec<(&'static str, f64)>,
    /// The density and pressure arrays handed to the renderer where the step keeps none of its
    /// own, made on first request.
    output_fields: std::cell::OnceCell<OutputFields>,
}

/// Arrays of every particle's density and pressure written from where the step keeps them
/// (wgsl/sim/fields.wgsl), with the stage's bind group per phase of the state.
pub(super) struct OutputFields {
    pub stage: Stage,
    densities: wgpu::Buffer,
    pressures: wgpu::Buffer,
    pub groups: Vec<wgpu::BindGroup>,
}

impl GpuSolver {
    /// Uploads a scene's particles and builds every pipeline and bind group. Programs build a
    /// solver through [`crate::solver::open`], which checks the memory plan first.
    pub(crate) fn with_options(ctx: GpuContext, params: &Params, initial: &InitialState, options: GpuOptions) -> anyhow::Result<Self> {
        Self::build(ctx, params, initial, options, None)
    }

    /// [`GpuSolver::with_options`] for one rank's part of a simulation across `ranks`
    /// (positions mark ghosts, see [`GpuSolver::load_held`]), or alone with `None`.
    pub(super) fn build(ctx: GpuContext, params: &Params, initial: &InitialState, options: GpuOptions, ranks: Option<std::sync::Arc<dyn crate::solver::communicator::Communicator>>) -> anyhow::Result<Self> {
        // With a neighbour skin the grid's cells are h (1 + skin) wide (wgsl/sim/neighbour_skin.wgsl).
        let widened;
        let params = match options.neighbour_skin {
            Some(skin) => {
                if let Some(why) = super::skin::refusal(params, skin, ranks.is_some()) {
                    return Err(GpuError::NoNeighbourSkin(why).into());
                }
                widened = Params { grid: params.grid.widened(1.0 + skin), ..params.clone() };
                &widened
            }
            None => params,
        };
        let shape = StepShape::new(&ctx, params, initial, &options, ranks.is_some())?;
        let k = shape.constants(params, &options, ranks.is_some());
        let pipelines = Pipelines::new(&ctx, params, &shape, &options, &k)?;
        let StepShape { fluid: n, walls: w, cells, viscosity, gpu_params, has_walls, adami, surface_tension, dfsph, wall_order, wall_index, fused, list_capacity, counts, arrays, plan, aliases, .. } = shape;
        let layout = arrays.layout;
        let ws = options.workgroup_sizes;
        let len = |name: &str| counts.len(name);
        let stage = |name: &str, entry: &str, lens: ArrayLengths, constants: &[(&str, f64)]| stage_with_aliases(&ctx, name, entry, lens, constants, &aliases);
        // DFSPH's accelerations exist with adaptive dt only; elsewhere its stages bind a
        // placeholder (until `step_fields` asks for them).
        let dfsph_len = |name: &str| if name == "accelerations" && params.adaptive.is_none() { 0 } else { counts.len(name) };
        // In place DFSPH's integration writes the positions it reads.
        let dfsph_places: Vec<(&str, Alias)> = aliases.iter().copied().chain((layout == StateLayout::InPlace).then_some(IN_PLACE[0])).collect();
        let dfsph_stages = if dfsph { Some(DfsphStages::new(&ctx, params, &k, &ws, &dfsph_len, &dfsph_places, pipelines.subgroup_tiles)?) } else { None };

        let device = &ctx.device;
        let uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("params"),
            contents: &gpu_params.bytes(),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        });

        let walls_sorted: Vec<[f64; 3]> = wall_order.iter().map(|&i| initial.wall_positions[i as usize]).collect();
        let wall_masses: Vec<f32> = wall_order.iter().map(|&i| initial.wall_masses[i as usize] as f32).collect();
        // The w of a wall position holds its mass.
        let wall_positions = storage_init(device, "wall positions", bytemuck::cast_slice(&vec4s(&walls_sorted, |i| wall_masses[i])));
        let wall_cell_blocks = storage_init(device, "wall cell blocks", bytemuck::cast_slice(&wall_index.blocks));
        let wall_cell_firsts = storage(device, "wall cell starts", counts.wall_cell_firsts * 4);
        if has_walls {
            ctx.queue.write_buffer(&wall_cell_firsts, 0, bytemuck::cast_slice(&wall_index.firsts));
        }
        // Before the first step (a snapshot at t = 0 evaluates them too): no pressure, rest density.
        let wall_fields = adami.then(|| {
            let rest: Vec<[f32; 2]> = vec![[0.0, params.rest_density as f32]; w as usize];
            storage_init(device, "wall fields", bytemuck::cast_slice(&rest))
        });
        let normals = surface_tension.then(|| storage(device, "surface normals", n * 16));

        let store = StateStore::new(device, layout, n, dfsph);
        // With continuity density the w of each velocity carries the particle's density.
        let carried = |i: usize| if params.continuity_density { initial.fluid_density(i, params.rest_density) as f32 } else { 0.0 };
        store.state(0).upload(&ctx, &initial.fluid_positions, &initial.fluid_velocities, |i| i as u32, &carried);
        let starts = storage(device, "cell starts", (cells + 1) * 4);
        let densities = arrays.densities.then(|| storage(device, "densities", n * 4));
        let pressures = arrays.pressures.then(|| storage(device, "pressures", n * 4));
        let placeholder = storage(device, "placeholder", 16);
        let accelerations = (dfsph && params.adaptive.is_some()).then(|| storage(device, "accelerations", n * 16));
        let status = storage_init(device, "status", bytemuck::cast_slice(&status::initial()));
        // Every list marked full until a density stage records it: a pass that walked lists
        // before then would walk the tiles instead.
        let lists = list_capacity.map(|capacity| NeighbourLists {
            capacity,
            slots: storage(device, "neighbour lists", counts.list_slots * 4),
            counts: storage_init(device, "neighbour counts", bytemuck::cast_slice(&vec![NeighbourLists::FULL; n as usize])),
        });
        let scan = Scan::new(&ctx, &uniform, &starts, cells + 1)?;

        let u = &uniform;
        let p = &pipelines;
        // The buffer of every array name in phase `c` (writing the phase after it where a
        // stage writes another state); `array_places` says which arrays live in others. The
        // binning's `bins` are a buffer dead while it runs and read before the reorder's last
        // gather writes it: the other state's velocities, or in place the spare, where the
        // accelerations then live. The reorder's destinations go to the densities' array where
        // there is one (it is written again only after the reorder).
        let buffers = |c: usize| {
            let (src, dst) = (store.state(c), store.state(store.after_binning(c)));
            let spare = (layout == StateLayout::InPlace).then(|| store.spare(c));
            let acc = spare.clone().or_else(|| accelerations.clone()).unwrap_or_else(|| placeholder.clone());
            let bins = spare.unwrap_or_else(|| dst.velocities.clone());
            let (starts, densities, pressures, status, wall_positions, wall_cell_blocks, wall_cell_firsts, wall_fields, normals, lists) =
                (&starts, &densities, &pressures, &status, &wall_positions, &wall_cell_blocks, &wall_cell_firsts, &wall_fields, &normals, &lists);
            move |name: &str| -> wgpu::Buffer {
                match name {
                    "positions" => src.positions.clone(),
                    "velocities" => src.velocities.clone(),
                    "positions_out" => dst.positions.clone(),
                    "velocities_out" => dst.velocities.clone(),
                    "bins" => bins.clone(),
                    "pressures" => pressures.clone().expect("a pressures array (DFSPH)"),
                    "densities" | "dest" => densities.clone().expect("a densities array"),
                    "starts" | "counts" => starts.clone(),
                    "wall_positions" => wall_positions.clone(),
                    "wall_cell_blocks" => wall_cell_blocks.clone(),
                    "wall_cell_firsts" => wall_cell_firsts.clone(),
                    "wall_fields" => wall_fields.clone().expect("bound only with the Adami wall pressure"),
                    "normals" => normals.clone().expect("bound only with surface tension"),
                    "neighbours" => lists.as_ref().expect("bound only with neighbour lists").slots.clone(),
                    "neighbour_counts" => lists.as_ref().expect("bound only with neighbour lists").counts.clone(),
                    "status" => status.clone(),
                    "accelerations" => acc.clone(),
                    other => panic!("no buffer holds the array '{other}'"),
                }
            }
        };
        // The fused stage and the one-thread finish_step declare accelerations they never use.
        let without_accelerations = |c: usize| {
            let b = buffers(c);
            let placeholder = &placeholder;
            move |name: &str| if name == "accelerations" { placeholder.clone() } else { b(name) }
        };
        // The reorder's two dispatches: positions, then velocities, each from phase `c` into
        // the phase after it (in place: the positions into the spare, then the velocities into
        // the positions' buffer, which the first has finished reading).
        let gather = |c: usize, k: usize| {
            let b = buffers(c);
            let (from, to) = (store.state(c), store.state(store.after_binning(c)));
            let (input, output) = if k == 0 { (from.positions, to.positions) } else { (from.velocities, to.velocities) };
            p.reorder.bind_group(device, "reorder", u, &move |name: &str| match name {
                "gathered_in" => input.clone(),
                "gathered_out" => output.clone(),
                other => b(other),
            })
        };
        let make_parity = |c: usize| {
            let b = buffers(c);
            ParityBindGroups {
                bin_count: p.bin_count.bind_group(device, "bin_count", u, &b),
                bin_scatter: p.bin_scatter.bind_group(device, "bin_scatter", u, &b),
                reorder_rank: p.reorder_rank.bind_group(device, "reorder_rank", u, &b),
                reorder: [gather(c, 0), gather(c, 1)],
                wcsph: p.wcsph.as_ref().map(|w| WcsphBindGroups {
                    density: w.density.bind_group(device, "density", u, &b),
                    density_listed: w.density_listed.as_ref().map(|stage| stage.bind_group(device, "density_listed", u, &b)),
                    wall_pressure: w.wall_pressure.as_ref().map(|stage| stage.bind_group(device, "wall_pressure", u, &b)),
                    surface_normals: w.surface_normals.as_ref().map(|stage| stage.bind_group(device, "surface_normals", u, &b)),
                    forces: (layout == StateLayout::InPlace).then(|| w.forces.bind_group(device, "forces", u, &b)),
                    advance: if fused {
                        w.advance.bind_group(device, "forces_and_integrate", u, &without_accelerations(c))
                    } else {
                        w.advance.bind_group(device, "integrate", u, &b)
                    },
                }),
            }
        };
        let groups: Vec<ParityBindGroups> = (0..store.phases()).map(make_parity).collect();
        // The skin's check, after each step, on the phase the step leaves its state in.
        let skin = match options.neighbour_skin {
            Some(fraction) => {
                let mut c = sized(&k, ws.integrate);
                c.push(("SKIN", crate::solver::cpu::neighbour_skin::checked_skin(fraction)));
                let check = stage("neighbour_skin", "check_skin", &|name: &str| if name == "skin_left" { 0 } else { len(name) }, &c)?;
                let phases: Vec<_> = (0..store.phases()).map(buffers).collect();
                Some(super::skin::NeighbourSkin::new(device, u, fraction, params.h, n, check, &phases))
            }
            None => None,
        };
        let finish_group = p.finish_step.bind_group(device, "finish_step", u, &without_accelerations(0));
        let max_groups_per_dim = device.limits().max_compute_workgroups_per_dimension;
        let dfsph = dfsph_stages.map(|stages| {
            let shared = SharedBuffers {
                store: &store,
                starts: &starts,
                densities: densities.as_ref().expect("DFSPH keeps a densities array"),
                pressures: pressures.as_ref().expect("DFSPH keeps a pressures array"),
                status: &status,
                wall_positions: &wall_positions,
                wall_cell_blocks: &wall_cell_blocks,
                wall_cell_firsts: &wall_cell_firsts,
                accelerations: accelerations.as_ref().unwrap_or(&placeholder),
                lists: lists.as_ref(),
                normals: normals.as_ref(),
            };
            let buffers = DfsphBuffers::new(&ctx, n, solve_threads(&ws), max_groups_per_dim);
            DfsphGpu::new(&ctx, params.dfsph.as_ref().expect("DFSPH"), stages, buffers, &shared, &uniform)
        });
        let probes = if params.probes.is_empty() {
            None
        } else {
            let masks = params.probes.wall_masks(&initial.wall_positions, &initial.wall_boundaries);
            let sorted_masks: Vec<u32> = if params.probes.force_count() > 0 { wall_order.iter().map(|&i| masks[i as usize]).collect() } else { Vec::new() };
            let phases: Vec<_> = (0..store.phases()).map(buffers).collect();
            let phases: Vec<&dyn Fn(&str) -> wgpu::Buffer> = phases.iter().map(|b| b as &dyn Fn(&str) -> wgpu::Buffer).collect();
            let sums = dfsph.as_ref().map(|d| DfsphSums { pressure_sum: &d.buffers.pressure_sum, divergence_sum: &d.buffers.divergence_sum });
            Some(GpuProbes::new(&ctx, params, n, &sorted_masks, &k, &len, u, &phases, &aliases, sums)?)
        };
        let memory = plan.total() + probes.as_ref().map_or(0, |p| p.bytes());
        let mut solver = GpuSolver {
            params: params.clone(),
            fluid_count: n as u32,
            wall_count: w as u32,
            uniform,
            uniform_viscosity: viscosity,
            store,
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
            wall_cell_blocks,
            wall_cell_firsts,
            wall_fields,
            normals,
            neighbour_lists: lists,
            skin,
            wall_order,
            scan,
            groups,
            pipelines,
            finish_group,
            dfsph,
            solver_loop: options.solver_loop,
            last_iterations: std::cell::Cell::new([0; 2]),
            step_accelerations_groups: None,
            steps: 0,
            max_groups_per_dim,
            steps_per_submit: if options.steps_per_submit == 0 { STEPS_PER_SUBMIT } else { options.steps_per_submit },
            memory,
            plan,
            probes,
            ranks,
            rank_error: std::cell::RefCell::new(None),
            rank_solves: std::cell::RefCell::new(None),
            ghost_velocities: std::cell::OnceCell::new(),
            ghost_link_cells: std::cell::OnceCell::new(),
            arrays,
            constants: k,
            output_fields: std::cell::OnceCell::new(),
            ctx,
        };
        if let Some(d) = &mut solver.dfsph {
            d.accelerations = accelerations;
        }
        solver.ctx.check_device()?;
        Ok(solver)
    }

    /// The fused step's forces' bind groups of both parities, writing into `buffer`.
    fn forces_groups(&self, buffer: wgpu::Buffer) -> Accelerations {
        let device = &self.ctx.device;
        let group = |c: usize| {
            let st = self.store.state(c);
            self.wcsph_stages().forces.bind_group(device, "forces", &self.uniform, &|name: &str| {
                match name {
                    "positions" => &st.positions,
                    "velocities" => &st.velocities,
                    "densities" => self.densities.as_ref().expect("a densities array"),
                    "pressures" => self.pressures.as_ref().expect("a pressures array"),
                    "starts" => &self.starts,
                    "wall_positions" => &self.wall_positions,
                    "wall_cell_blocks" => &self.wall_cell_blocks,
                    "wall_cell_firsts" => &self.wall_cell_firsts,
                    "wall_fields" => self.wall_fields.as_ref().expect("bound only with the Adami wall pressure"),
                    "normals" => self.normals.as_ref().expect("bound only with surface tension"),
                    "accelerations" => &buffer,
                    other => panic!("no buffer holds the array '{other}'"),
                }
                .clone()
            })
        };
        let groups = [group(0), group(1)];
        Accelerations { buffer, groups }
    }

    /// Makes the accelerations array hold the accelerations of `fields_state`: after a refresh
    /// (in place) or a fused step, which keeps them in registers, they are evaluated again here
    /// (same inputs, same shader code: the same values), the fused step's into an array created
    /// on first use.
    fn ensure_accelerations(&mut self) {
        if self.accelerations_valid {
            return;
        }
        if self.dfsph.is_some() {
            self.record_step_accelerations();
            self.accelerations_valid = true;
            return;
        }
        if self.store.layout == StateLayout::PingPong && self.accelerations.is_none() {
            let buffer = storage(&self.ctx.device, "accelerations", self.fluid_count as u64 * 16);
            self.accelerations = Some(self.forces_groups(buffer));
        }
        self.record_accelerations();
        self.accelerations_valid = true;
    }

    /// The accelerations array `step_fields` reads.
    fn accelerations_buffer(&self) -> wgpu::Buffer {
        match &self.dfsph {
            Some(d) => d.accelerations.clone().expect("made by ensure_accelerations"),
            None if self.store.layout == StateLayout::InPlace => self.store.spare(self.fields_state),
            None => self.accelerations.as_ref().expect("made by ensure_accelerations").buffer.clone(),
        }
    }

    /// DFSPH's arrays in original particle order (for the stage tests): `velocities` are the
    /// current state's, or with `predicted` the other buffer's, where the prediction writes.
    pub fn dfsph_fields(&self, predicted: bool) -> anyhow::Result<crate::model::state::DfsphFields> {
        let d = self.dfsph.as_ref().ok_or_else(|| anyhow::anyhow!("not a DFSPH scene"))?;
        let n = self.fluid_count as u64;
        let b = &d.buffers;
        let c = self.current;
        let velocities = &if predicted { self.store.next(c) } else { self.store.state(c) }.velocities;
        let data = read_buffers(&self.ctx, &[
            (&self.store.state(c).positions, n * 16),
            (self.densities.as_ref().expect("DFSPH keeps a densities array"), n * 4),
            (self.pressures.as_ref().expect("DFSPH keeps a pressures array"), n * 4),
            (&b.factors, n * 4),
            (&b.wall_gradients, n * 16),
            (&b.stiffness, n * 4),
            (&b.pressure_sum, n * 4),
            (&b.divergence_sum, n * 4),
            (velocities, n * 16),
        ])?;
        let ids = ids_of(bytemuck::cast_slice(&data[0]));
        let scalars = |k: usize| unpermute(&ids, bytemuck::pod_collect_to_vec::<u8, f32>(&data[k]).iter().map(|&v| v as f64));
        let vectors = |k: usize| unpermute(&ids, bytemuck::pod_collect_to_vec::<u8, [f32; 4]>(&data[k]).iter().map(widen));
        Ok(crate::model::state::DfsphFields {
            densities: scalars(1),
            pressures: scalars(2),
            factors: scalars(3),
            wall_gradients: vectors(4),
            stiffness: scalars(5),
            pressure_sum: scalars(6),
            divergence_sum: scalars(7),
            velocities: vectors(8),
        })
    }

    /// The weakly compressible step's stages (the solver of a WCSPH scene has them).
    pub(super) fn wcsph_stages(&self) -> &WcsphStages {
        self.pipelines.wcsph.as_ref().expect("a weakly compressible scene")
    }

    /// Whether the scene runs DFSPH.
    pub fn is_dfsph(&self) -> bool {
        self.dfsph.is_some()
    }

    /// Reads the probe rows recorded so far back into the host's samples.
    fn read_probe_rows(&mut self) -> anyhow::Result<()> {
        match &mut self.probes {
            Some(p) => p.read_rows(&self.ctx, &self.params),
            None => Ok(()),
        }
    }

    /// Each wall particle's [pressure, density] of the last density stage, in the walls'
    /// original order (`boundary_pressure = "adami"`; empty otherwise).
    pub fn wall_fields(&self) -> anyhow::Result<Vec<[f64; 2]>> {
        let Some(buffer) = &self.wall_fields else {
            return Ok(Vec::new());
        };
        let data = read_buffers(&self.ctx, &[(buffer, self.wall_count as u64 * 8)])?;
        let sorted: Vec<[f32; 2]> = bytemuck::pod_collect_to_vec(&data[0]);
        let mut out = vec![[0.0; 2]; sorted.len()];
        for (slot, f) in sorted.iter().enumerate() {
            out[self.wall_order[slot] as usize] = [f[0] as f64, f[1] as f64];
        }
        Ok(out)
    }

    /// Whether forces and integration run as one pass.
    pub fn fused(&self) -> bool {
        self.pipelines.fused
    }

    /// Whether the density (summation or continuity), the two-pass forces and DFSPH's solve
    /// iterations walk a subgroup's stencils together.
    pub fn subgroup_tiles(&self) -> bool {
        self.pipelines.subgroup_tiles
    }

    /// The slots of each fluid particle's neighbour list where the tiled forces or DFSPH's
    /// solves walk lists (see [`GpuOptions::neighbour_lists`]), else `None`.
    pub fn neighbour_list_capacity(&self) -> Option<u32> {
        self.neighbour_lists.as_ref().map(|l| l.capacity)
    }

    /// With a neighbour skin (see [`GpuOptions::neighbour_skin`]): the skin, a fraction of h,
    /// and the steps that rebuilt the grid and the lists so far; else `None`.
    pub fn neighbour_skin(&self) -> Option<(f64, u64)> {
        self.skin.as_ref().map(|s| (s.fraction, s.rebuilds.get()))
    }

    /// How full the lists the last step recorded were: the most slots one particle's list
    /// used, and the particles whose lists overflowed (their subgroups walked the tiles);
    /// `None` without lists.
    pub fn neighbour_list_usage(&self) -> anyhow::Result<Option<ListUsage>> {
        let Some(lists) = &self.neighbour_lists else {
            return Ok(None);
        };
        let data = read_buffers(&self.ctx, &[(&lists.counts, self.fluid_count as u64 * 4)])?;
        let words: Vec<u32> = bytemuck::pod_collect_to_vec(&data[0]);
        let full = words.iter().filter(|&&c| c == NeighbourLists::FULL).count() as u64;
        let longest = words.iter().filter_map(|&c| NeighbourLists::used(c)).max().unwrap_or(0);
        Ok(Some(ListUsage { slots: lists.capacity, longest, full }))
    }
    /// Blocks until the GPU has finished everything submitted (for timing).
    pub fn wait(&self) -> anyhow::Result<()> {
        self.ctx.device.poll(wgpu::PollType::Wait { submission_index: None, timeout: None })?;
        Ok(())
    }

    pub fn context(&self) -> &GpuContext {
        &self.ctx
    }

    pub(super) fn set_viscosity(&mut self, nu: f64) {
        if nu != self.uniform_viscosity {
            let p = GpuParams::new(&self.params, self.fluid_count, self.wall_count, nu);
            self.ctx.queue.write_buffer(&self.uniform, 0, &p.bytes());
            self.uniform_viscosity = nu;
        }
    }

    /// The ids of the particles in cell order and the cell starts, after binning the current
    /// state (for the binning tests).
    pub fn binning(&mut self) -> anyhow::Result<(Vec<u32>, Vec<u32>)> {
        self.refresh_fields();
        let n = self.fluid_count as u64;
        let cells = self.params.grid.cell_count() as u64;
        let data = read_buffers(&self.ctx, &[(&self.store.state(self.current).positions, n * 16), (&self.starts, (cells + 1) * 4)])?;
        Ok((ids_of(bytemuck::cast_slice(&data[0])), bytemuck::pod_collect_to_vec(&data[1])))
    }

    /// The buffers holding the current particle state (they change roles as the solver steps:
    /// ask again after stepping). Particles are in cell order; the w component of
    /// each position holds the particle's original index as u32 bits. `densities` and
    /// `pressures` are in the same order after a snapshot.
    ///
    /// Where the step keeps no density or pressure array of its own (the weakly compressible
    /// step sums density into the w of the velocities and computes pressure from it), both are
    /// written into arrays made on the first call (8 bytes per fluid particle) and refreshed on
    /// every call.
    pub fn particle_buffers(&self) -> anyhow::Result<ParticleBuffers> {
        let st = self.store.state(self.current);
        let (densities, pressures) = match (&self.densities, &self.pressures) {
            (Some(d), Some(p)) => (d.clone(), p.clone()),
            _ => {
                let out = match self.output_fields.get() {
                    Some(out) => out,
                    None => {
                        let made = self.make_output_fields()?;
                        self.output_fields.get_or_init(|| made)
                    }
                };
                self.record_output_fields(&out.stage, &out.groups[self.current]);
                (out.densities.clone(), out.pressures.clone())
            }
        };
        Ok(ParticleBuffers {
            context: self.ctx.clone(),
            positions: st.positions.clone(),
            velocities: st.velocities.clone(),
            densities,
            pressures,
            count: self.fluid_count,
        })
    }

    /// The output fields' arrays, stage and bind groups (see [`GpuSolver::particle_buffers`]).
    fn make_output_fields(&self) -> anyhow::Result<OutputFields> {
        let n = self.store.capacity();
        let places = array_places(&self.arrays);
        let stage = stage_with_aliases(&self.ctx, "fields", "output_fields", &|_: &str| n, &self.constants_sized(super::shaders::WORKGROUP_SIZE), &places)?;
        let device = &self.ctx.device;
        let densities = storage(device, "output densities", n * 4);
        let pressures = storage(device, "output pressures", n * 4);
        let groups = (0..self.store.phases())
            .map(|c| {
                let st = self.store.state(c);
                stage.bind_group(device, "output_fields", &self.uniform, &|name: &str| match name {
                    "velocities" => st.velocities.clone(),
                    "densities" => self.densities.clone().expect("a densities array"),
                    "pressures" => self.pressures.clone().expect("a pressures array"),
                    "density_out" => densities.clone(),
                    "pressure_out" => pressures.clone(),
                    other => panic!("no buffer holds the array '{other}'"),
                })
            })
            .collect();
        Ok(OutputFields { stage, densities, pressures, groups })
    }

    /// The stages' specialisation constants with `size` threads per workgroup.
    pub(super) fn constants_sized(&self, size: u32) -> Vec<(&'static str, f64)> {
        super::pipelines::sized(&self.constants, size)
    }

    /// The pressure the stages compute from a density (the equation of state in f32, as
    /// `eos_pressure` in wgsl/shared/common.wgsl).
    pub(super) fn pressure_of(&self, rho: f32) -> f32 {
        let p = &self.params;
        crate::model::kernels::pressure::<f32>(rho, p.rest_density as f32, p.stiffness as f32, p.eos, p.clamp_negative_pressure)
    }

    /// The densities and pressures of every particle of phase `c`'s state in slot order, read
    /// where they live: their arrays, or the w of the velocities and the equation of state
    /// (`array_places`).
    pub(super) fn read_fields(&self, c: usize) -> anyhow::Result<(Vec<f32>, Vec<f32>)> {
        let n = self.fluid_count as u64;
        let velocities = self.store.state(c).velocities;
        let density_source = match &self.densities {
            Some(d) => (d, n * 4),
            None => (&velocities, n * 16),
        };
        let mut sources = vec![density_source];
        sources.extend(self.pressures.as_ref().map(|p| (p, n * 4)));
        let data = read_buffers(&self.ctx, &sources)?;
        let rho: Vec<f32> = match &self.densities {
            Some(_) => bytemuck::pod_collect_to_vec(&data[0]),
            None => bytemuck::pod_collect_to_vec::<u8, [f32; 4]>(&data[0]).iter().map(|v| v[3]).collect(),
        };
        let p = match &self.pressures {
            Some(_) => bytemuck::pod_collect_to_vec(&data[1]),
            None => rho.iter().map(|&r| self.pressure_of(r)).collect(),
        };
        Ok((rho, p))
    }

    /// The status words, checked to count as many steps as the host did (for saved states).
    fn counted_status(&self) -> anyhow::Result<[u32; status::WORDS]> {
        let words = self.read_status()?;
        anyhow::ensure!(words[status::STEPS] as u64 == self.steps % (1 << 32), "the GPU counted {} steps, the host {}", words[status::STEPS], self.steps);
        Ok(words)
    }

    /// The dt of every step without adaptive dt (the host then knows the time of a step).
    fn fixed_dt(&self) -> Option<f64> {
        self.params.adaptive.is_none().then_some(self.params.dt)
    }

    pub(super) fn read_status(&self) -> anyhow::Result<[u32; status::WORDS]> {
        let data = read_buffers(&self.ctx, &[(&self.status, status::BYTES)])?;
        let words: Vec<u32> = bytemuck::pod_collect_to_vec(&data[0]);
        Ok(words.try_into().expect("the status buffer has status::WORDS words"))
    }

    /// Bytes of every buffer the solver allocated on the device (its [`MemoryPlan`]'s total).
    pub fn memory_bytes(&self) -> u64 {
        self.memory
    }

    /// Every buffer of the memory plan the solver was made with.
    pub fn memory_plan(&self) -> &MemoryPlan {
        &self.plan
    }

    /// Bytes of the buffers as created, summed from the buffers themselves (to check the plan).
    pub fn allocated_bytes(&self) -> u64 {
        let s = self;
        // With the fused step (and DFSPH with a fixed dt) the accelerations exist only after
        // `step_fields` asked for them; in place they live in the state's spare buffer.
        let planned_accelerations = s.dfsph.as_ref().and_then(|d| d.accelerations.as_ref().filter(|_| s.params.adaptive.is_some()));
        [&s.uniform, &s.starts, &s.placeholder, &s.status, &s.wall_positions, &s.wall_cell_blocks, &s.wall_cell_firsts]
            .into_iter()
            .chain(s.densities.as_ref())
            .chain(s.pressures.as_ref())
            .chain(planned_accelerations)
            .chain(s.wall_fields.as_ref())
            .chain(s.normals.as_ref())
            .chain(s.neighbour_lists.iter().flat_map(|l| [&l.slots, &l.counts]))
            .chain(s.skin.iter().flat_map(|k| [&k.rebuild_positions, &k.left]))
            .map(|b| b.size())
            .sum::<u64>()
            + s.store.bytes()
            + s.scan.bytes()
            + s.dfsph.as_ref().map_or(0, |d| d.buffers.bytes())
            + s.probes.as_ref().map_or(0, |p| p.bytes())
            + s.output_fields.get().map_or(0, |o| o.densities.size() + o.pressures.size())
            + s.ghost_velocities.get().map_or(0, |g| g.bytes())
            + s.ghost_link_cells.get().map_or(0, |g| g.bytes())
    }

    /// The snapshot rows of the current state (after a refresh) in pieces of `chunk` slots: the
    /// streamed snapshot with an explicit piece size (the tests use small ones).
    pub fn visit_rows_in_pieces(&mut self, chunk: u64, visit: &mut dyn FnMut(u64, &[SnapshotRow]) -> anyhow::Result<()>) -> anyhow::Result<()> {
        self.refresh_fields();
        let st = self.store.state(self.current);
        let pressure = |rho: f32| self.pressure_of(rho);
        let arrays = RowArrays {
            positions: &st.positions,
            velocities: &st.velocities,
            densities: self.densities.as_ref(),
            pressures: self.pressures.as_ref(),
            pressure_of: &pressure,
            count: self.fluid_count as u64,
        };
        visit_rows(&self.ctx, &arrays, chunk, visit)
    }

    /// One array of the saved state in pieces of `chunk` particles (the tests use small ones).
    pub fn visit_state_in_pieces(&mut self, array: StateArray, chunk: u64, visit: &mut dyn FnMut(StatePiece) -> anyhow::Result<()>) -> anyhow::Result<()> {
        let st = self.store.state(self.current);
        let n = self.fluid_count as u64;
        match array {
            StateArray::Positions => visit_array(&self.ctx, &st.positions, n, Element::Vector, chunk, visit),
            StateArray::Velocities => visit_array(&self.ctx, &st.velocities, n, Element::Vector, chunk, visit),
            StateArray::Ids => visit_array(&self.ctx, &st.positions, n, Element::IdInW, chunk, visit),
            StateArray::WarmStart => match &self.dfsph {
                Some(d) => visit_pairs(&self.ctx, &d.buffers.warm_pressure, &d.buffers.warm_divergence, n, chunk, visit),
                None => Ok(()),
            },
            StateArray::Densities if !self.params.continuity_density => Ok(()),
            StateArray::Densities => visit_array(&self.ctx, &st.velocities, n, Element::ScalarInW, chunk, visit),
        }
    }
}

impl Backend for GpuSolver {
    fn kind(&self) -> &'static str {
        "gpu"
    }
    fn adapter(&self) -> String {
        self.ctx.describe()
    }
    fn driver(&self) -> String {
        self.ctx.driver()
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
        if self.probes.is_none() {
            self.advance(n);
            return Ok(());
        }
        // In runs of steps whose samples fit the row buffer, read back in between.
        let mut left = n;
        while left > 0 {
            let probes = self.probes.as_ref().expect("checked above");
            let mut room = super::probes::ROW_CAPACITY - probes.pending.len() as u64;
            let mut run = 0;
            while run < left {
                if self.params.probes.samples_step(self.steps + run, self.params.dt, self.params.adaptive.is_some()) {
                    if room == 0 {
                        break;
                    }
                    room -= 1;
                }
                run += 1;
            }
            if run == 0 {
                self.read_probe_rows()?;
                continue;
            }
            self.advance(run);
            left -= run;
        }
        Ok(())
    }
    fn steps_done(&self) -> u64 {
        self.steps
    }
    fn time(&self) -> f64 {
        if self.params.adaptive.is_none() {
            return self.steps as f64 * self.params.dt;
        }
        // A few bytes: the exact sum of the steps' dt (wgsl/shared/adaptive_dt.wgsl add_to_time).
        match self.read_status() {
            Ok(w) => status::time(&w).seconds(),
            Err(e) => {
                log::error!("reading the simulated time failed: {e:#}");
                f64::NAN
            }
        }
    }
    fn dt_stats(&mut self) -> anyhow::Result<DtStats> {
        // No step taken, no step to report (as on the CPU path).
        if self.steps == 0 {
            return Ok(DtStats::default());
        }
        let Some(_) = self.params.adaptive else {
            return Ok(DtStats::fixed(self.params.dt));
        };
        let s = self.read_status()?;
        let f = |i: usize| status::float(&s, i);
        let time = status::time(&s).seconds();
        Ok(DtStats { min: f(status::DT_MIN), max: f(status::DT_MAX), mean: time / self.steps as f64, last: f(status::DT) })
    }
    fn memory_bytes(&self) -> Option<u64> {
        Some(self.memory)
    }
    fn health(&mut self) -> anyhow::Result<Health> {
        let words = self.read_status()?;
        Ok(Health { iterations: self.dfsph.is_some().then(|| status::iterations(&words)), ..status::health(&words, self.fixed_dt()) })
    }
    fn snapshot(&mut self) -> anyhow::Result<Snapshot> {
        self.refresh_fields();
        let n = self.fluid_count as u64;
        let st = self.store.state(self.current);
        let data = read_buffers(&self.ctx, &[(&st.positions, n * 16), (&st.velocities, n * 16)])?;
        let pos: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&data[0]);
        let ids = ids_of(&pos);
        let vel: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&data[1]);
        let (rho, p) = self.read_fields(self.current)?;
        Ok(Snapshot {
            step: self.steps,
            time: self.time(),
            positions: unpermute(&ids, pos.iter().map(widen)),
            velocities: unpermute(&ids, vel.iter().map(widen)),
            densities: unpermute(&ids, rho.iter().map(|&v| v as f64)),
            pressures: unpermute(&ids, p.iter().map(|&v| v as f64)),
        })
    }
    fn streams_snapshots(&self) -> bool {
        true
    }
    fn visit_snapshot_rows(&mut self, visit: &mut dyn FnMut(u64, &[SnapshotRow]) -> anyhow::Result<()>) -> anyhow::Result<()> {
        self.visit_rows_in_pieces(STREAM_CHUNK, visit)
    }
    fn gpu_particles(&self) -> Option<ParticleBuffers> {
        match self.particle_buffers() {
            Ok(p) => Some(p),
            Err(e) => {
                // The caller then draws from a snapshot uploaded from the host.
                log::warn!("the GPU's density and pressure arrays for drawing could not be made: {e:#}");
                None
            }
        }
    }
    fn save_state(&mut self) -> anyhow::Result<BackendState> {
        let mut state = self.save_state_header()?;
        for (array, chunk) in [(StateArray::Positions, 0), (StateArray::Velocities, 0), (StateArray::Ids, 0), (StateArray::WarmStart, 0), (StateArray::Densities, 0)] {
            self.visit_state_in_pieces(array, chunk, &mut |piece| {
                match (array, piece) {
                    (StateArray::Positions, StatePiece::Vectors(v)) => state.positions.extend_from_slice(v),
                    (StateArray::Velocities, StatePiece::Vectors(v)) => state.velocities.extend_from_slice(v),
                    (StateArray::Ids, StatePiece::Ids(v)) => state.ids.extend_from_slice(v),
                    (StateArray::WarmStart, StatePiece::Pairs(v)) => state.warm_start.extend_from_slice(v),
                    (StateArray::Densities, StatePiece::Scalars(v)) => state.densities.extend_from_slice(v),
                    _ => unreachable!("each array hands out its own kind of piece"),
                }
                Ok(())
            })?;
        }
        Ok(state)
    }
    fn save_state_header(&mut self) -> anyhow::Result<BackendState> {
        // A run resumed from this state rebuilds its neighbours at its first step: so does this.
        self.rebuild_next_step();
        let words = self.counted_status()?;
        let h = status::health(&words, self.fixed_dt());
        // The time, dt range and iterations as the CPU path keeps them, for GPU ranks resuming
        // this state (one GPU restores the status words whole).
        let f = |i: usize| status::float(&words, i);
        let (time, dt_min_max_last) = match self.params.adaptive {
            None => (self.steps as f64 * self.params.dt, [self.params.dt; 3]),
            Some(_) if self.steps == 0 => (0.0, [0.0; 3]),
            Some(_) => (status::time(&words).seconds(), [f(status::DT_MIN), f(status::DT_MAX), f(status::DT)]),
        };
        Ok(BackendState {
            kind: "gpu".into(),
            step: self.steps,
            positions: Vec::new(),
            velocities: Vec::new(),
            ids: Vec::new(),
            non_finite: h.non_finite,
            escaped: h.escaped,
            first_bad_step: h.first_bad_step,
            max_density: h.max_density,
            max_speed: h.max_speed,
            bad_step: h.bad_step,
            // One GPU keeps its time and dt range in the status words, restored whole.
            time,
            dt_min_max_last,
            gpu_status: words.to_vec(),
            warm_start: Vec::new(),
            iterations: if self.dfsph.is_some() { status::iterations(&words) } else { Default::default() },
            densities: Vec::new(),
        })
    }
    fn visit_state_array(&mut self, array: StateArray, chunk: u64, visit: &mut dyn FnMut(StatePiece) -> anyhow::Result<()>) -> anyhow::Result<()> {
        self.visit_state_in_pieces(array, chunk, visit)
    }
    fn take_probe_samples(&mut self) -> anyhow::Result<Vec<ProbeSample>> {
        self.read_probe_rows()?;
        Ok(self.probes.as_mut().map(|p| std::mem::take(&mut p.samples)).unwrap_or_default())
    }
    fn restore_state(&mut self, state: &BackendState) -> anyhow::Result<()> {
        state.check_fits("gpu", self.fluid_count as usize)?;
        if let Some(p) = &mut self.probes {
            p.reset(&self.ctx);
        }
        // GPU ranks save no status words: made from the state's header.
        let words = match state.gpu_status.len() {
            0 => status::from_header(state).to_vec(),
            _ => state.gpu_status.clone(),
        };
        anyhow::ensure!(words.len() == status::WORDS, "the state holds {} status words; this solver has {}", words.len(), status::WORDS);
        let continuity = self.params.continuity_density;
        anyhow::ensure!(
            state.densities.len() == if continuity { state.positions.len() } else { 0 },
            "the state holds {} carried densities; the scene's density method needs {}",
            state.densities.len(),
            if continuity { state.positions.len() } else { 0 }
        );
        let carried = |i: usize| if continuity { state.densities[i] as f32 } else { 0.0 };
        self.store.state(0).upload(&self.ctx, &state.positions, &state.velocities, |i| state.ids[i], &carried);
        if let Some(d) = &self.dfsph {
            let n = self.fluid_count as usize;
            anyhow::ensure!(state.warm_start.len() == n, "the state holds {} warm-start stiffnesses for DFSPH; the scene has {n} particles", state.warm_start.len());
            let (p, v): (Vec<f32>, Vec<f32>) = state.warm_start.iter().map(|w| (w[0] as f32, w[1] as f32)).unzip();
            self.ctx.queue.write_buffer(&d.buffers.warm_pressure, 0, bytemuck::cast_slice(&p));
            self.ctx.queue.write_buffer(&d.buffers.warm_divergence, 0, bytemuck::cast_slice(&v));
        }
        let q = &self.ctx.queue;
        q.write_buffer(&self.status, 0, bytemuck::cast_slice(&words));
        q.submit([]);
        self.current = 0;
        self.fields_state = 0;
        self.accelerations_valid = false;
        self.steps = state.step;
        self.rebuild_next_step();
        Ok(())
    }
    fn step_fields(&mut self) -> anyhow::Result<StepFields> {
        let n = self.fluid_count as u64;
        self.ensure_accelerations();
        let acc = self.accelerations_buffer();
        let data = read_buffers(&self.ctx, &[(&acc, n * 16), (&self.store.state(self.fields_state).positions, n * 16)])?;
        let ids = ids_of(bytemuck::cast_slice(&data[1]));
        let (rho, p) = self.read_fields(self.fields_state)?;
        let acc: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&data[0]);
        Ok(StepFields {
            densities: unpermute(&ids, rho.iter().map(|&v| v as f64)),
            pressures: unpermute(&ids, p.iter().map(|&v| v as f64)),
            accelerations: unpermute(&ids, acc.iter().map(widen)),
        })
    }
}
