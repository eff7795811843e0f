//! DFSPH on the GPU: the pipelines of its stages (wgsl/sim/dfsph_*.wgsl), its arrays and the
//! bind groups of both parities of the state pair. The order in which a step records them is in
//! `schedule.rs`, with the weakly compressible step's.
//!
//! A step reads state `c` (after the binning) and leaves the new state in `1 - c`: the
//! divergence solve changes the velocities of `c` in place, the prediction writes v* into the
//! velocities of `1 - c`, the constant-density solve changes those in place, and the integration
//! writes the new positions next to them. The warm-start stiffnesses are kept by particle id.

use super::buffers::{storage, StateStore};
use super::device::{GpuContext, GpuError};
use super::shaders::{dispatch_size, stage_with_aliases, Alias, ArrayLengths, Stage};
use super::workgroups::WorkgroupSizes;
use crate::model::params::Params;
use crate::model::scene::DfsphSettings;
use crate::model::state::IterationStats;
use crate::solver::cpu::exchange::GhostLink;

/// DFSPH across ranks (src/solver/gpu/dfsph_ranks.rs): the solves' loops run from the host, which
/// gives the ghosts their owners' velocities after every velocity change and adds the error
/// sums of the ranks before each check (docs/scale-out.md).
pub struct RankSolves {
    /// The ghosts in the solves: in the upload's order until the binning, in the device's
    /// after it. `None` for the fields alone.
    pub link: Option<GhostLink>,
    /// The rank's slab, whose face layers' cells the link lists after the device's binning
    /// (src/solver/cpu/ghost_link.rs).
    pub faces: Option<crate::solver::cpu::resident_exchange::SlabFaces>,
    /// The solves' iterations so far (each solve adds its own).
    pub stats: IterationStats,
    /// The fluid particles of the whole simulation.
    pub particles: usize,
    /// The first failed read or message, for the rank's failure.
    pub failure: Option<String>,
    /// Whether the step reads back the velocities the prediction starts from (a step that
    /// samples the force probes on the host), and those velocities once read.
    pub wants_prediction_start: bool,
    pub prediction_start: Option<Vec<[f32; 4]>>,
    /// Bytes the solves' loops moved between host and device (reads and writes) this step.
    pub bus_bytes: u64,
}

impl RankSolves {
    /// The solves of a step about to run: with `link` and the slab `faces` it lists, the
    /// iterations so far, the particles of the whole simulation, and whether the velocities the
    /// prediction starts from are to be read back.
    pub fn new(link: Option<GhostLink>, faces: Option<crate::solver::cpu::resident_exchange::SlabFaces>, stats: IterationStats, particles: usize, wants_prediction_start: bool) -> Self {
        RankSolves { link, faces, stats, particles, failure: None, wants_prediction_start, prediction_start: None, bus_bytes: 0 }
    }

    /// After the step: its iterations into `stats`, its link (in the device's order) into
    /// `link`, its bytes added to `bus_bytes`; the velocities the prediction started from where
    /// they were read back, or the first failure of the solves.
    pub fn hand_back(self, stats: &mut IterationStats, link: Option<&mut GhostLink>, bus_bytes: &mut u64) -> anyhow::Result<Option<Vec<[f32; 4]>>> {
        *bus_bytes += self.bus_bytes;
        *stats = self.stats;
        if let (Some(link), Some(moved)) = (link, self.link) {
            *link = moved;
        }
        if let Some(e) = self.failure {
            anyhow::bail!("DFSPH's solves across ranks: {e}");
        }
        Ok(self.prediction_start)
    }
}

/// DFSPH across ranks: the stage that gathers the velocities a rank sends to its neighbours
/// and scatters those it receives onto its ghosts (wgsl/sim/ghost_velocities.wgsl), with its
/// slots and values, made on the first solve across ranks for the solver's capacity.
pub struct GhostVelocities {
    pub gather: Stage,
    pub scatter: Stage,
    /// The counts of slots to gather and to scatter, then those slots.
    pub slots: wgpu::Buffer,
    pub values: wgpu::Buffer,
    /// Per phase of the state read, on its own velocities (0) and on the predicted ones (1):
    /// the bind groups of the gather and of the scatter.
    pub groups: Vec<[[wgpu::BindGroup; 2]; 2]>,
}

impl GhostVelocities {
    /// For `n` held particles at most (a particle of a thin slab may go to both neighbours).
    pub fn new(ctx: &GpuContext, n: u64, constants: &[(&'static str, f64)], store: &StateStore, uniform: &wgpu::Buffer) -> Result<Self, GpuError> {
        let (slot_count, value_count) = (3 * n + 2, 2 * n);
        let lens = move |name: &str| match name {
            "ghost_slots" => slot_count,
            "ghost_values" => value_count,
            _ => n,
        };
        let stage = |entry: &str| stage_with_aliases(ctx, "ghost_velocities", entry, &lens, constants, &[]);
        let (gather, scatter) = (stage("gather_ghost_velocities")?, stage("scatter_ghost_velocities")?);
        let slots = storage(&ctx.device, "ghost slots", slot_count * 4);
        let values = storage(&ctx.device, "ghost values", value_count * 16);
        let group = |stage: &Stage, velocities: &wgpu::Buffer| {
            stage.bind_group(&ctx.device, "ghost velocities", uniform, &|name: &str| match name {
                "velocities" => velocities.clone(),
                "ghost_slots" => slots.clone(),
                "ghost_values" => values.clone(),
                other => panic!("no buffer holds the array '{other}'"),
            })
        };
        let groups = (0..store.phases())
            .map(|c| [store.state(c).velocities, store.next(c).velocities].map(|v| [group(&gather, &v), group(&scatter, &v)]))
            .collect();
        Ok(GhostVelocities { gather, scatter, slots, values, groups })
    }

    pub fn bytes(&self) -> u64 {
        self.slots.size() + self.values.size()
    }
}

/// DFSPH across ranks: the stage that reads where the ghost link's cells lie in the cell starts
/// (wgsl/sim/ghost_link.wgsl), with room for `capacity` cells: the most the link lists for the
/// grid (every cell of four times the ghost layers), made on the first solve across ranks.
pub struct GhostLinkCells {
    pub stage: Stage,
    /// The count of cells, then the cells.
    pub cells: wgpu::Buffer,
    /// Each cell's first slot and end.
    pub bounds: wgpu::Buffer,
    pub group: wgpu::BindGroup,
    pub capacity: u64,
    /// The slab whose link's cells `cells` holds, and those cells by list: written again only
    /// when the slab's bounds move.
    pub listed: std::cell::RefCell<Option<(crate::solver::cpu::resident_exchange::SlabFaces, [Vec<u32>; 4])>>,
}

impl GhostLinkCells {
    /// With room for `capacity` cells, reading the cell starts `starts` of `cells` cells.
    pub fn new(ctx: &GpuContext, capacity: u64, cells: u64, constants: &[(&'static str, f64)], starts: &wgpu::Buffer, uniform: &wgpu::Buffer) -> Result<Self, GpuError> {
        let lens = move |name: &str| match name {
            "starts" => cells + 1,
            "link_cells" => capacity + 1,
            _ => 2 * capacity,
        };
        let stage = stage_with_aliases(ctx, "ghost_link", "link_cell_bounds", &lens, constants, &[])?;
        let list = storage(&ctx.device, "ghost link cells", (capacity + 1) * 4);
        let bounds = storage(&ctx.device, "ghost link cell bounds", 2 * capacity * 4);
        let group = stage.bind_group(&ctx.device, "ghost link", uniform, &|name: &str| match name {
            "starts" => starts.clone(),
            "link_cells" => list.clone(),
            "link_bounds" => bounds.clone(),
            other => panic!("no buffer holds the array '{other}'"),
        });
        Ok(GhostLinkCells { stage, cells: list, bounds, group, capacity, listed: Default::default() })
    }

    pub fn bytes(&self) -> u64 {
        self.cells.size() + self.bounds.size()
    }

    /// Writes the cells of a link's `lists` (joined, after their count) for the stage to read;
    /// returns the bytes written.
    pub fn write_cells(&self, queue: &wgpu::Queue, lists: &[Vec<u32>]) -> anyhow::Result<u64> {
        let cells = lists.iter().map(Vec::len).sum::<usize>();
        anyhow::ensure!(cells as u64 <= self.capacity, "the ghost link lists {cells} cells, its arrays hold {}", self.capacity);
        let words: Vec<u32> = std::iter::once(cells as u32).chain(lists.iter().flatten().copied()).collect();
        queue.write_buffer(&self.cells, 0, bytemuck::cast_slice(&words));
        Ok(4 * words.len() as u64)
    }
}

/// The pipelines of DFSPH's stages.
pub(super) struct DfsphStages {
    pub factors: Stage,
    pub divergence_warm_start: Stage,
    pub divergence_rate: Stage,
    pub divergence_apply: Stage,
    /// Fixed dt: viscosity, gravity and v* in one pass.
    pub predict: Stage,
    /// Adaptive dt: the accelerations with the maxima, the choice of dt, then v*.
    pub adaptive: Option<[Stage; 3]>,
    pub pressure_warm_start: Stage,
    pub predict_density: Stage,
    pub pressure_apply: Stage,
    /// `begin_solve` and `check_convergence` of the divergence solve (0) and the
    /// constant-density solve (1).
    pub begin: [Stage; 2],
    pub check: [Stage; 2],
    pub integrate: Stage,
    pub step_accelerations: Stage,
    /// With surface tension: the normals of the factors' densities, before the prediction.
    pub surface_normals: Option<Stage>,
}

/// DFSPH's arrays.
pub(super) struct DfsphBuffers {
    pub factors: wgpu::Buffer,
    pub wall_gradients: wgpu::Buffer,
    pub stiffness: wgpu::Buffer,
    pub pressure_sum: wgpu::Buffer,
    pub divergence_sum: wgpu::Buffer,
    /// By particle id.
    pub warm_pressure: wgpu::Buffer,
    pub warm_divergence: wgpu::Buffer,
    /// The dispatch size of the next iteration's passes (words 0-2) and the full size (4-6).
    pub solve_dispatch: wgpu::Buffer,
}

/// The bind groups of one parity: reading state `c`, writing state `1 - c`.
pub(super) struct DfsphGroups {
    pub factors: wgpu::BindGroup,
    pub divergence_warm_start: wgpu::BindGroup,
    pub divergence_rate: wgpu::BindGroup,
    pub divergence_apply: wgpu::BindGroup,
    pub predict: wgpu::BindGroup,
    pub adaptive: Option<[wgpu::BindGroup; 3]>,
    pub pressure_warm_start: wgpu::BindGroup,
    pub predict_density: wgpu::BindGroup,
    pub pressure_apply: wgpu::BindGroup,
    pub integrate: wgpu::BindGroup,
    pub surface_normals: Option<wgpu::BindGroup>,
}

/// DFSPH on the GPU: its settings, pipelines, arrays and bind groups.
pub(super) struct DfsphGpu {
    pub settings: DfsphSettings,
    pub stages: DfsphStages,
    pub buffers: DfsphBuffers,
    /// Per phase of the state.
    pub groups: Vec<DfsphGroups>,
    /// The bind groups of `begin_solve` and `check_convergence` of the divergence solve (0) and
    /// the constant-density solve (1).
    pub control: [(wgpu::BindGroup, wgpu::BindGroup); 2],
    /// The accelerations: with adaptive dt from the start; with a fixed dt made when the step's
    /// fields are asked for.
    pub accelerations: Option<wgpu::Buffer>,
}

/// The shared buffers a DFSPH stage binds besides its own.
pub(super) struct SharedBuffers<'a> {
    /// The particle state, held as a ping-pong pair (the prediction writes the other state).
    pub store: &'a StateStore,
    pub starts: &'a wgpu::Buffer,
    pub densities: &'a wgpu::Buffer,
    pub pressures: &'a wgpu::Buffer,
    pub status: &'a wgpu::Buffer,
    pub wall_positions: &'a wgpu::Buffer,
    pub wall_cell_blocks: &'a wgpu::Buffer,
    pub wall_cell_firsts: &'a wgpu::Buffer,
    /// The accelerations (adaptive dt), or a placeholder.
    pub accelerations: &'a wgpu::Buffer,
    /// The neighbour lists and their counts, where the solves walk lists.
    pub lists: Option<&'a super::buffers::NeighbourLists>,
    /// The fluid's normals, with surface tension.
    pub normals: Option<&'a wgpu::Buffer>,
}

/// Threads per workgroup of the solves' passes, whose dispatch size the GPU's checks write.
pub(super) fn solve_threads(sizes: &WorkgroupSizes) -> u32 {
    sizes.forces
}

impl DfsphStages {
    /// Every DFSPH pipeline, with the scene's constants `k` and the workgroup sizes (density:
    /// the factors; forces: the prediction and the solves; integrate: the integration); with
    /// `tiles`, the factors and the solves' iterations walk a subgroup's stencils together
    /// (wgsl/sim/dfsph_factors_tiled.wgsl, wgsl/shared/dfsph_tiles.wgsl).
    pub fn new(ctx: &GpuContext, params: &Params, k: &[(&'static str, f64)], sizes: &WorkgroupSizes, lens: ArrayLengths, places: &[(&str, Alias)], tiles: bool) -> Result<Self, GpuError> {
        let settings = params.dfsph.as_ref().expect("a DFSPH scene");
        let sized = |size: u32| {
            let mut c = k.to_vec();
            c.push(("WORKGROUP_SIZE", size as f64));
            c
        };
        let solve = sized(solve_threads(sizes));
        let control = |which: u32, warm: bool| {
            let mut c = k.to_vec();
            c.push(("SOLVE", which as f64));
            c.push(("WARM_START", if warm { 1.0 } else { 0.0 }));
            c
        };
        let warm = settings.warm_start;
        let one = |entry: &str, consts: &[(&str, f64)]| stage_with_aliases(ctx, entry_file(entry), entry, lens, consts, places);
        // A solve iteration's pass: `entry`, or with tiles `tiled` in its file's _tiled twin.
        let iteration = |entry: &str, tiled: &str| {
            if tiles {
                stage_with_aliases(ctx, &format!("{}_tiled", entry_file(entry)), tiled, lens, &solve, places)
            } else {
                one(entry, &solve)
            }
        };
        Ok(DfsphStages {
            // With tiles the factors' walk is tiled too, and records the neighbour lists where
            // the step keeps them (NEIGHBOUR_LISTS).
            factors: if tiles {
                stage_with_aliases(ctx, "dfsph_factors_tiled", "factors_tiled", lens, &sized(sizes.density), places)?
            } else {
                one("density_and_factor", &sized(sizes.density))?
            },
            divergence_warm_start: one("divergence_warm_start", &solve)?,
            divergence_rate: iteration("divergence_rate", "rate_tiled")?,
            divergence_apply: iteration("divergence_apply", "apply_tiled")?,
            predict: one("predict_velocities", &solve)?,
            adaptive: match params.adaptive {
                Some(_) => Some([one("non_pressure_accelerations", &solve)?, one("choose_dt", k)?, one("predict_from_accelerations", &solve)?]),
                None => None,
            },
            pressure_warm_start: one("pressure_warm_start", &solve)?,
            predict_density: iteration("predict_density", "rate_tiled")?,
            pressure_apply: iteration("pressure_apply", "apply_tiled")?,
            begin: [one("begin_solve", &control(0, warm))?, one("begin_solve", &control(1, warm))?],
            check: [one("check_convergence", &control(0, warm))?, one("check_convergence", &control(1, warm))?],
            integrate: one("integrate", &sized(sizes.integrate))?,
            step_accelerations: one("step_accelerations", &sized(sizes.integrate))?,
            surface_normals: if params.surface_tension > 0.0 { Some(one("surface_normals", &solve)?) } else { None },
        })
    }
}

/// The stage file of an entry point.
fn entry_file(entry: &str) -> &'static str {
    match entry {
        "density_and_factor" => "dfsph_factors",
        "divergence_warm_start" | "divergence_rate" | "divergence_apply" => "dfsph_divergence",
        "predict_velocities" | "non_pressure_accelerations" | "choose_dt" | "predict_from_accelerations" => "dfsph_predict",
        "pressure_warm_start" | "predict_density" | "pressure_apply" => "dfsph_pressure",
        "begin_solve" | "check_convergence" => "dfsph_convergence",
        "integrate" | "step_accelerations" => "dfsph_integrate",
        "surface_normals" => "surface_normals",
        other => panic!("no DFSPH entry point {other}"),
    }
}

/// Bytes of DFSPH's own arrays for `n` fluid particles (the memory plan lists them).
pub fn buffer_bytes(n: u64) -> [(&'static str, u64); 8] {
    [
        ("dfsph factors", n * 4),
        ("dfsph wall gradients", n * 16),
        ("dfsph stiffness", n * 4),
        ("dfsph pressure stiffness sum", n * 4),
        ("dfsph divergence stiffness sum", n * 4),
        ("dfsph warm start (pressure)", n * 4),
        ("dfsph warm start (divergence)", n * 4),
        ("dfsph solve dispatch", 32),
    ]
}

impl DfsphBuffers {
    /// The arrays of `n` particles; the dispatch sizes of the solves' passes written in.
    pub fn new(ctx: &GpuContext, n: u64, threads: u32, max_groups_per_dim: u32) -> Self {
        let device = &ctx.device;
        let b = buffer_bytes(n);
        let (x, y) = dispatch_size(n, threads, max_groups_per_dim);
        let solve_dispatch = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(b[7].0),
            size: b[7].1,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::INDIRECT | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        ctx.queue.write_buffer(&solve_dispatch, 0, bytemuck::cast_slice(&[x, y, 1, 0, x, y, 1, 0u32]));
        DfsphBuffers {
            factors: storage(device, b[0].0, b[0].1),
            wall_gradients: storage(device, b[1].0, b[1].1),
            stiffness: storage(device, b[2].0, b[2].1),
            pressure_sum: storage(device, b[3].0, b[3].1),
            divergence_sum: storage(device, b[4].0, b[4].1),
            warm_pressure: storage(device, b[5].0, b[5].1),
            warm_divergence: storage(device, b[6].0, b[6].1),
            solve_dispatch,
        }
    }

    pub fn bytes(&self) -> u64 {
        [&self.factors, &self.wall_gradients, &self.stiffness, &self.pressure_sum, &self.divergence_sum, &self.warm_pressure, &self.warm_divergence, &self.solve_dispatch]
            .iter()
            .map(|b| b.size())
            .sum()
    }
}

/// The three passes of a solve, each with its bind group: the warm start, the error (rate) and
/// the velocity change (apply).
pub(super) struct SolvePasses<'a> {
    pub warm: (&'a Stage, &'a wgpu::BindGroup),
    pub rate: (&'a Stage, &'a wgpu::BindGroup),
    pub apply: (&'a Stage, &'a wgpu::BindGroup),
}

impl DfsphGpu {
    /// The passes of solve `solve` (0: divergence, 1: constant density) on the state pair read
    /// from `read`.
    pub(super) fn solve_passes(&self, solve: usize, read: usize) -> SolvePasses<'_> {
        let (g, st) = (&self.groups[read], &self.stages);
        match solve {
            0 => SolvePasses {
                warm: (&st.divergence_warm_start, &g.divergence_warm_start),
                rate: (&st.divergence_rate, &g.divergence_rate),
                apply: (&st.divergence_apply, &g.divergence_apply),
            },
            _ => SolvePasses {
                warm: (&st.pressure_warm_start, &g.pressure_warm_start),
                rate: (&st.predict_density, &g.predict_density),
                apply: (&st.pressure_apply, &g.pressure_apply),
            },
        }
    }
    pub fn new(ctx: &GpuContext, settings: &DfsphSettings, stages: DfsphStages, buffers: DfsphBuffers, shared: &SharedBuffers, uniform: &wgpu::Buffer) -> Self {
        let device = &ctx.device;
        let groups: Vec<DfsphGroups> = (0..shared.store.phases()).map(|c| {
            // `predicted`: the velocities a stage works on are the predicted ones.
            let lookup = |predicted: bool| {
                let (read, write) = (shared.store.state(c), shared.store.next(c));
                let (b, s) = (&buffers, shared);
                move |name: &str| -> wgpu::Buffer {
                    match name {
                        "positions" => read.positions.clone(),
                        // The velocities a stage works on: the state's own (the divergence
                        // solve, the prediction) or the predicted ones (the constant-density
                        // solve, the integration).
                        "velocities" => if predicted { write.velocities.clone() } else { read.velocities.clone() },
                        "velocities_out" => write.velocities.clone(),
                        "velocities_start" => read.velocities.clone(),
                        "positions_out" => write.positions.clone(),
                        "starts" => s.starts.clone(),
                        "densities" => s.densities.clone(),
                        "pressures" => s.pressures.clone(),
                        "status" => s.status.clone(),
                        "wall_positions" => s.wall_positions.clone(),
                        "wall_cell_blocks" => s.wall_cell_blocks.clone(),
                        "wall_cell_firsts" => s.wall_cell_firsts.clone(),
                        "accelerations" => s.accelerations.clone(),
                        "factors" => b.factors.clone(),
                        "wall_gradients" => b.wall_gradients.clone(),
                        "stiffness" => b.stiffness.clone(),
                        "pressure_sum" => b.pressure_sum.clone(),
                        "divergence_sum" => b.divergence_sum.clone(),
                        "warm_pressure" => b.warm_pressure.clone(),
                        "warm_divergence" => b.warm_divergence.clone(),
                        "neighbours" => s.lists.expect("bound only with neighbour lists").slots.clone(),
                        "neighbour_counts" => s.lists.expect("bound only with neighbour lists").counts.clone(),
                        "normals" => s.normals.expect("bound only with surface tension").clone(),
                        other => panic!("no DFSPH buffer holds the array '{other}'"),
                    }
                }
            };
            let own = lookup(false);
            let predicted = lookup(true);
            let st = &stages;
            DfsphGroups {
                factors: st.factors.bind_group(device, "density_and_factor", uniform, &own),
                divergence_warm_start: st.divergence_warm_start.bind_group(device, "divergence_warm_start", uniform, &own),
                divergence_rate: st.divergence_rate.bind_group(device, "divergence_rate", uniform, &own),
                divergence_apply: st.divergence_apply.bind_group(device, "divergence_apply", uniform, &own),
                predict: st.predict.bind_group(device, "predict_velocities", uniform, &own),
                adaptive: st.adaptive.as_ref().map(|[a, d, p]| {
                    [
                        a.bind_group(device, "non_pressure_accelerations", uniform, &own),
                        d.bind_group(device, "choose_dt", uniform, &own),
                        p.bind_group(device, "predict_from_accelerations", uniform, &own),
                    ]
                }),
                pressure_warm_start: st.pressure_warm_start.bind_group(device, "pressure_warm_start", uniform, &predicted),
                predict_density: st.predict_density.bind_group(device, "predict_density", uniform, &predicted),
                pressure_apply: st.pressure_apply.bind_group(device, "pressure_apply", uniform, &predicted),
                integrate: st.integrate.bind_group(device, "integrate", uniform, &predicted),
                surface_normals: st.surface_normals.as_ref().map(|stage| stage.bind_group(device, "surface_normals", uniform, &own)),
            }
        }).collect();
        let control_buffers = |name: &str| match name {
            "status" => shared.status.clone(),
            "solve_dispatch" => buffers.solve_dispatch.clone(),
            other => panic!("no buffer holds the array '{other}'"),
        };
        let control = [0, 1].map(|s| {
            (stages.begin[s].bind_group(device, "begin_solve", uniform, &control_buffers), stages.check[s].bind_group(device, "check_convergence", uniform, &control_buffers))
        });
        DfsphGpu { settings: settings.clone(), stages, buffers, groups, control, accelerations: None }
    }

    /// The bind groups of `step_accelerations` for the state pair read from `c` (made on
    /// request, with the accelerations array then in use).
    pub fn step_accelerations_group(&self, ctx: &GpuContext, shared: &SharedBuffers, uniform: &wgpu::Buffer, c: usize) -> wgpu::BindGroup {
        let (read, write) = (shared.store.state(c), shared.store.next(c));
        let b = &self.buffers;
        self.stages.step_accelerations.bind_group(&ctx.device, "step_accelerations", uniform, &|name: &str| {
            match name {
                "positions" => &read.positions,
                "velocities" => &write.velocities,
                "velocities_start" => &read.velocities,
                "positions_out" => &write.positions,
                "pressure_sum" => &b.pressure_sum,
                "divergence_sum" => &b.divergence_sum,
                "warm_pressure" => &b.warm_pressure,
                "warm_divergence" => &b.warm_divergence,
                "accelerations" => shared.accelerations,
                "status" => shared.status,
                other => panic!("no buffer holds the array '{other}'"),
            }
            .clone()
        })
    }

    /// Iterations recorded per solve with the indirect loop: up to the limit (the warm start
    /// counts as the first).
    pub fn recorded_iterations(&self, solve: usize) -> u32 {
        let max = if solve == 0 { self.settings.max_divergence_iterations } else { self.settings.max_iterations };
        max.saturating_sub(self.settings.warm_start as u32)
    }
}
