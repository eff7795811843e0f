//! How a scene's step is shaped on the GPU before any buffer exists: the arrays it keeps and
//! their lengths, whether the forces and the integration are fused, whether the neighbour
//! stages walk subgroup tiles and keep lists, the memory plan, and the pipelines of the weakly
//! compressible step. [`GpuSolver`](super::solver::GpuSolver) builds its buffers and bind groups
//! on what this decides.

use super::buffers::{StateLayout, WallCellIndex};
use super::device::{GpuContext, GpuError, TILE_LANES};
use super::memory::{MemoryPlan, StepArrays};
use super::params::GpuParams;
use super::shaders::{constants, stage_with_aliases, storage_bindings, Alias, ArrayLengths, Stage};
use super::workgroups::GpuOptions;
use crate::model::initial::InitialState;
use crate::model::kernels::sort_by_cell;
use crate::model::params::Params;
use crate::model::real::V3;
use crate::model::scene::BoundaryPressure;

/// The integration with the state in place: it writes each particle's new state into the slot
/// it read it from.
pub(super) const IN_PLACE: &[(&str, Alias)] = &[("positions_out", Alias::Same("positions")), ("velocities_out", Alias::Same("velocities"))];

/// Where the arrays the stages declare live when they have no buffer of their own
/// (docs/performance.md, "GPU memory layout"): the binning's cell keys, ranks and unordered slots
/// in lanes of `bins`, a buffer free while the binning runs (the spare, or the other state's
/// velocities); a summed density, and the binning's destinations before it, in the w of the
/// velocities; the weakly compressible step's pressure computed from the density where it is
/// read; the wall cell starts from the index of the cells that hold walls.
pub(super) fn array_places(arrays: &StepArrays) -> Vec<(&'static str, Alias)> {
    let bins = |lane| Alias::Lane { target: "bins", ty: "vec4<u32>", lane };
    let mut places = vec![("keys", bins(0)), ("ranks", bins(1)), ("unordered", bins(2))];
    if !arrays.densities {
        let w = Alias::Lane { target: "velocities", ty: "vec4<f32>", lane: 3 };
        places.extend([("densities", w), ("dest", w)]);
    }
    if !arrays.pressures {
        places.push(("pressures", Alias::Derived { expr: "eos_pressure(densities_at(i))", arrays: &[] }));
    }
    // The wall cell starts from the index of the cells that hold walls (`WallCellIndex`): the
    // start of the first such cell from cell i on (blocks of 32 cells: `i >> 5u`, `i & 31u`).
    const _: () = assert!(super::buffers::WALL_CELL_BLOCK == 32);
    let wall_starts = "wall_cell_firsts_at(wall_cell_blocks_at(i >> 5u).y + countOneBits(wall_cell_blocks_at(i >> 5u).x & ((1u << (i & 31u)) - 1u)))";
    places.push(("wall_starts", Alias::Derived { expr: wall_starts, arrays: &[("wall_cell_blocks", "vec2<u32>"), ("wall_cell_firsts", "u32")] }));
    places
}

pub(super) struct Pipelines {
    pub bin_count: Stage,
    pub bin_scatter: Stage,
    pub reorder_rank: Stage,
    pub reorder: Stage,
    /// The weakly compressible step's stages (`None` with DFSPH, whose are in `GpuSolver::dfsph`).
    pub wcsph: Option<WcsphStages>,
    pub finish_step: Stage,
    /// Forces and integration in one pass (fixed dt only; see `GpuOptions`): no accelerations
    /// array.
    pub fused: bool,
    /// The neighbour stages walk a subgroup's stencils together (see [`subgroup_tiles`]).
    pub subgroup_tiles: bool,
}

/// Whether the density (summation or continuity), the two-pass forces and DFSPH's solve
/// iterations walk the stencils of a subgroup together (wgsl/shared/tiles.wgsl): by default where
/// the device has subgroups of exactly [`TILE_LANES`] invocations, the density and forces
/// workgroups (DFSPH's solves run at the forces' size) are whole subgroups, and the stencil is
/// walked as runs; asked for where it cannot, an error that says why.
fn subgroup_tiles(ctx: &GpuContext, options: &GpuOptions) -> Result<bool, GpuError> {
    let ws = options.workgroup_sizes;
    let why = ctx.subgroup_tiles_unavailable().or_else(|| {
        [("density", ws.density), ("forces", ws.forces)]
            .iter()
            .find(|(_, size)| size % TILE_LANES != 0)
            .map(|(stage, size)| format!("the {stage} stage's workgroups of {size} are not whole subgroups of {TILE_LANES}"))
    });
    match (options.subgroup_tiles, why) {
        (Some(false), _) => Ok(false),
        (None, why) => Ok(why.is_none() && !options.single_cells),
        (Some(true), None) => Ok(true),
        (Some(true), Some(why)) => Err(GpuError::NoSubgroupTiles { adapter: ctx.info.name.clone(), backend: format!("{:?}", ctx.info.backend), why }),
    }
}

/// The capacity of each fluid particle's neighbour list where the step keeps lists
/// (wgsl/shared/neighbour_lists.wgsl), else `None`: where `walks_tiles` (subgroup tiles, the
/// weakly compressible forces in a pass of their own, one device) and the options do not turn
/// them off. The capacity is 0.75 times the neighbours a particle has at rest density, 4/3 pi h^3 rho0 / m
/// (fluid and walls together, the walls' spacing being the fluid's), in whole rows of eight, or
/// the options'. A slot holds a chunk of up to eight neighbours: measured on the dam break and
/// the resting block, the longest list used 0.37-0.52 times that many slots (17, 34 and 42
/// with supports of 2, 2.5 and 3 spacings), so this leaves room for compression; a longer list
/// overflows, and its subgroup walks the tiles.
fn neighbour_lists(ctx: &GpuContext, params: &Params, walks_tiles: bool, options: &GpuOptions, fluid: u64, walls: u64) -> Option<u32> {
    let used = walks_tiles && options.neighbour_lists != Some(false);
    // With a skin the lists reach h (1 + skin).
    let reach = params.h * (1.0 + options.neighbour_skin.unwrap_or(0.0));
    let at_rest = 4.0 / 3.0 * std::f64::consts::PI * reach.powi(3) * params.rest_density / params.fluid_mass;
    // The counts are kept in 16 bits.
    let capacity = options.neighbour_list_capacity.unwrap_or(((0.75 * at_rest / 8.0).ceil() * 8.0).clamp(8.0, 4096.0) as u32).clamp(1, 0xffff);
    // Slots are indexed with 32 bits, and an entry holds a chunk's first fluid or wall
    // candidate in 24; the lists are one buffer, which a scene too big for it runs without.
    let slots = fluid.saturating_mul(capacity as u64);
    let fits = slots <= u32::MAX as u64 && fluid.max(walls) < 1 << 24 && slots * 4 <= ctx.device.limits().max_buffer_size;
    (used && fits).then_some(capacity)
}

/// The weakly compressible step's own stages.
pub(super) struct WcsphStages {
    pub density: Stage,
    /// With a neighbour skin and lists: the tiled density stage built with RECORD_LISTS false,
    /// which walks the lists of the last rebuild on the steps between rebuilds.
    pub density_listed: Option<Stage>,
    /// With `boundary_pressure = "adami"`: the wall particles' pressure (wall_pressure.wgsl),
    /// after the density stage, one invocation per wall particle.
    pub wall_pressure: Option<Stage>,
    /// With `surface_tension` above zero: each fluid particle's normal (surface_normals.wgsl),
    /// before the forces, one invocation per fluid particle.
    pub surface_normals: Option<Stage>,
    /// The forces alone: every step with adaptive dt; otherwise only when the accelerations are
    /// asked for (`step_fields`).
    pub forces: Stage,
    /// `integrate` (two passes) or `forces_and_integrate` (fused, see `Pipelines::fused`).
    pub advance: Stage,
    /// Adaptive dt only: the reduction of |v|max and |a|max, and the choice of dt.
    pub adaptive: Option<(Stage, Stage)>,
}

/// The element count of each array the stages declare, by name: every particle array holds
/// the fluid particles, the cell starts (and the counts scanned into them) one value per cell
/// and one more, the walls theirs. `status` is bound whole.
pub(super) struct ArrayCounts {
    pub(super) fluid: u64,
    pub(super) cells_plus_one: u64,
    pub(super) walls: u64,
    /// The wall cell index's blocks and starts (see `WallCellIndex`), 0 without walls.
    pub(super) wall_cell_blocks: u64,
    pub(super) wall_cell_firsts: u64,
    /// The wall particles with the Adami wall pressure, else 0 (the array is then not bound).
    pub(super) wall_fields: u64,
    /// The neighbour lists' slots (fluid particles times the capacity), else 0.
    pub(super) list_slots: u64,
    /// The fluid particles with surface tension, else 0 (the normals are then not bound).
    pub(super) normals: u64,
}

impl ArrayCounts {
    pub(super) fn len(&self, name: &str) -> u64 {
        match name {
            "starts" | "counts" => self.cells_plus_one,
            "wall_positions" => self.walls,
            "wall_cell_blocks" => self.wall_cell_blocks,
            "wall_cell_firsts" => self.wall_cell_firsts,
            "wall_fields" => self.wall_fields,
            "normals" => self.normals,
            "neighbours" => self.list_slots,
            "neighbour_counts" => if self.list_slots > 0 { self.fluid } else { 0 },
            "status" | "solve_dispatch" => 0,
            _ => self.fluid,
        }
    }
    /// [`ArrayCounts::len`] for a stage that does not bind `accelerations` (the fused step
    /// keeps them in registers, as does the one-thread finish_step).
    pub(super) fn len_without_accelerations(&self, name: &str) -> u64 {
        if name == "accelerations" { 0 } else { self.len(name) }
    }
}

/// What a scene's step keeps on the GPU and how its stages run, decided from the scene, the
/// options and the adapter before any buffer exists (every buffer is checked against the
/// device's limits, and the stages' bindings against the adapter's, first).
pub(super) struct StepShape {
    pub fluid: u64,
    pub walls: u64,
    pub cells: u64,
    /// The viscosity of the first step, and the uniform block with it.
    pub viscosity: f64,
    pub gpu_params: GpuParams,
    /// Without walls the shaders never read the wall arrays (WALLS = false): no per-cell array.
    pub has_walls: bool,
    /// The Adami wall pressure's stage runs (weakly compressible, with walls).
    pub adami: bool,
    pub surface_tension: bool,
    pub dfsph: bool,
    /// The original index of each wall particle in cell order, and the index of the cells that
    /// hold walls.
    pub wall_order: Vec<u32>,
    pub wall_index: WallCellIndex,
    pub tiles: bool,
    pub fused: bool,
    /// Each fluid particle's neighbour list slots, where the step keeps lists.
    pub list_capacity: Option<u32>,
    pub counts: ArrayCounts,
    pub arrays: StepArrays,
    pub plan: MemoryPlan,
    /// Where the arrays without a buffer of their own live ([`array_places`]), and the same
    /// with the integration writing the state in place where the layout is in place.
    pub aliases: Vec<(&'static str, Alias)>,
    pub in_place: Vec<(&'static str, Alias)>,
}

impl StepShape {
    /// The shape of the step of `params` (already widened by a neighbour skin) over `initial`'s
    /// particles, on one device or as a rank of several (`across_ranks`).
    pub fn new(ctx: &GpuContext, params: &Params, initial: &InitialState, options: &GpuOptions, across_ranks: bool) -> anyhow::Result<StepShape> {
        let n = initial.fluid_positions.len() as u64;
        let cells = params.grid.cell_count() as u64;
        let viscosity = params.viscosity_at_step(0);
        let gpu_params = GpuParams::new(params, n as u32, initial.wall_positions.len() as u32, viscosity);
        let w = initial.wall_positions.len() as u64;
        let has_walls = w > 0;
        let adami = params.boundary_pressure == BoundaryPressure::Adami && has_walls && params.dfsph.is_none();
        let surface_tension = params.surface_tension > 0.0;
        // Walls never move: sorted by cell once, on the host, with the same counting sort, and
        // their cell starts kept for the cells that hold walls. Across ranks the walls near a
        // slab change as it moves (`load_walls`): room for as many wall cells as wall particles.
        let grid = params.grid.cast::<f32>();
        let wall_f32: Vec<V3<f32>> = initial.wall_positions.iter().map(|&p| V3::from64(p)).collect();
        let (wall_order, wall_starts) = sort_by_cell(&grid, &wall_f32);
        let wall_index = if has_walls { WallCellIndex::new(&wall_starts) } else { WallCellIndex::default() };
        let wall_cell_room = if across_ranks { (w + 1).min(cells + 1) } else { wall_index.firsts.len() as u64 };
        options.workgroup_sizes.check(ctx)?;
        let tiles = subgroup_tiles(ctx, options)?;
        let mut counts = ArrayCounts {
            fluid: n,
            cells_plus_one: cells + 1,
            walls: w,
            wall_cell_blocks: wall_index.blocks.len() as u64,
            wall_cell_firsts: if has_walls { wall_cell_room } else { 0 },
            wall_fields: if adami { w } else { 0 },
            list_slots: 0,
            normals: if surface_tension { n } else { 0 },
        };
        // Forces and integration can be fused with fixed dt in the weakly compressible step,
        // unless the fused stage's bindings exceed the adapter's (arrays in many segments).
        let dfsph = params.dfsph.is_some();
        let most = ctx.device.limits().max_storage_buffers_per_shader_stage as u64;
        let cannot_fuse = if params.adaptive.is_some() {
            Some("the scene chooses dt adaptively (time.adaptive = true), from every particle's acceleration, before any particle is integrated".to_string())
        } else if dfsph {
            Some("the scene uses DFSPH (physics.solver = \"dfsph\"), whose step has no forces pass of its own".to_string())
        } else {
            let bindings = storage_bindings(ctx, "forces_integrate", &|name: &str| counts.len_without_accelerations(name));
            (bindings > most).then(|| format!("the fused stage would bind {bindings} storage arrays (the scene's arrays take several segments each), more than the adapter's {most}"))
        };
        // Asked for where it cannot run: refused (exit 2), not quietly run as two passes.
        if let (Some(true), Some(why)) = (options.fuse_forces_and_integration, &cannot_fuse) {
            return Err(GpuError::NoFusion(format!("--fused cannot be used: {why}; run without it (the forces and the integration then run as two passes)")).into());
        }
        // The two-pass step with its state in place is the default: 48 bytes of state per
        // particle instead of the fused step's 64 (docs/performance.md).
        let fused = cannot_fuse.is_none() && options.fuse_forces_and_integration.unwrap_or(false);
        let mut list_capacity = neighbour_lists(ctx, params, tiles && !fused && !across_ranks, options, n, w);
        counts.list_slots = n * list_capacity.unwrap_or(0) as u64;
        // The lists' bindings (one per segment) must fit the stages that declare them; a scene
        // whose arrays take too many segments runs without.
        let list_stages: &[&str] = match (dfsph, params.continuity_density) {
            (true, _) => &["dfsph_factors_tiled", "dfsph_divergence_tiled", "dfsph_pressure_tiled"],
            (false, true) => &["continuity_tiled", "forces_tiled"],
            (false, false) => &["density_tiled", "forces_tiled"],
        };
        if list_capacity.is_some() && list_stages.iter().any(|stage| storage_bindings(ctx, stage, &|name: &str| counts.len(name)) > most) {
            list_capacity = None;
            counts.list_slots = 0;
        }
        // The fused step writes a second state; DFSPH keeps accelerations with adaptive dt only
        // (fixed dt: in registers).
        let arrays = StepArrays::new(dfsph, params.continuity_density, params.adaptive.is_some(), fused);
        let uniform_bytes = gpu_params.bytes().len() as u64;
        let plan = MemoryPlan::new(n, Some(w), cells, uniform_bytes, arrays).with_wall_cell_starts(counts.wall_cell_firsts);
        let plan = if dfsph { plan.with_dfsph(n) } else { plan.with_wall_fields(counts.wall_fields) }.with_neighbour_lists(n, list_capacity.unwrap_or(0));
        let plan = plan.with_neighbour_skin(n, options.neighbour_skin.is_some()).with_surface_normals(n, surface_tension);
        plan.check(ctx)?;
        let aliases = array_places(&arrays);
        let in_place = aliases.iter().copied().chain(if arrays.layout == StateLayout::InPlace { IN_PLACE.to_vec() } else { Vec::new() }).collect();
        Ok(StepShape {
            fluid: n,
            walls: w,
            cells,
            viscosity,
            gpu_params,
            has_walls,
            adami,
            surface_tension,
            dfsph,
            wall_order,
            wall_index,
            tiles,
            fused,
            list_capacity,
            counts,
            arrays,
            plan,
            aliases,
            in_place,
        })
    }

    /// The specialisation constants every stage of this step is built with: the scene's, and
    /// what the shape decided.
    pub fn constants(&self, params: &Params, options: &GpuOptions, across_ranks: bool) -> Vec<(&'static str, f64)> {
        let flag = |on: bool| if on { 1.0 } else { 0.0 };
        let mut k = constants(params);
        k.push(("WALLS", flag(self.has_walls)));
        k.push(("STENCIL_RUNS", flag(!options.single_cells)));
        k.push(("GHOSTS", flag(across_ranks)));
        k.push(("NEIGHBOUR_LISTS", flag(self.list_capacity.is_some())));
        k.push(("LIST_CAPACITY", self.list_capacity.unwrap_or(0) as f64));
        if let Some(skin) = options.neighbour_skin {
            k.push(("LIST_RADIUS2", (1.0 + skin) * (1.0 + skin)));
        }
        k
    }

    /// A stage of file `name`, entry point `entry`, with the step's array places.
    pub fn stage(&self, ctx: &GpuContext, name: &str, entry: &str, lens: ArrayLengths, constants: &[(&str, f64)]) -> Result<Stage, GpuError> {
        stage_with_aliases(ctx, name, entry, lens, constants, &self.aliases)
    }

    /// [`StepShape::stage`] for a stage that writes the state it reads where the layout is in
    /// place.
    pub fn stage_in_place(&self, ctx: &GpuContext, name: &str, entry: &str, lens: ArrayLengths, constants: &[(&str, f64)]) -> Result<Stage, GpuError> {
        stage_with_aliases(ctx, name, entry, lens, constants, &self.in_place)
    }
}

/// The constants `k` of a stage with `size` threads per workgroup.
pub(super) fn sized(k: &[(&'static str, f64)], size: u32) -> Vec<(&'static str, f64)> {
    let mut c = k.to_vec();
    c.push(("WORKGROUP_SIZE", size as f64));
    c
}

impl Pipelines {
    /// The pipelines of the binning, the reorder, the weakly compressible step (not with DFSPH,
    /// whose are `DfsphStages`) and the step's bookkeeping. They come before any buffer: they
    /// check that the stages' bindings (one per segment of each array) fit the adapter.
    pub fn new(ctx: &GpuContext, params: &Params, shape: &StepShape, options: &GpuOptions, k: &[(&'static str, f64)]) -> anyhow::Result<Pipelines> {
        let ws = options.workgroup_sizes;
        let counts = &shape.counts;
        let len = |name: &str| counts.len(name);
        // The fused stage binds a placeholder for the accelerations it declares but never uses,
        // as does the one-thread finish_step.
        let without_accelerations = |name: &str| counts.len_without_accelerations(name);
        let stage = |name: &str, entry: &str, lens: ArrayLengths, constants: &[(&str, f64)]| shape.stage(ctx, name, entry, lens, constants);
        let stage_in_place = |name: &str, entry: &str, lens: ArrayLengths, constants: &[(&str, f64)]| shape.stage_in_place(ctx, name, entry, lens, constants);
        // A neighbour stage: stage file NAME's `entry`, or with subgroup tiles NAME_tiled's.
        let neighbour_stage = |name: &str, entry: &str, size: u32| {
            if shape.tiles {
                let tiled = format!("{name}_tiled");
                stage(&tiled, &tiled, &len, &sized(k, size))
            } else {
                stage(name, entry, &len, &sized(k, size))
            }
        };
        let bin_count = stage("bin_count", "bin_count", &len, &sized(k, ws.bin_count))?;
        let bin_scatter = stage("bin_scatter", "bin_scatter", &len, &sized(k, ws.bin_scatter))?;
        // The rank binds no state array, the gather no cell keys or slots (see reorder.wgsl).
        let reorder_rank = stage("reorder", "reorder_rank", &|name: &str| if name.starts_with("gathered") { 0 } else { len(name) }, &sized(k, ws.reorder))?;
        let reorder = stage_with_aliases(
            ctx,
            "reorder",
            "reorder",
            &|name: &str| if matches!(name, "keys" | "unordered") { 0 } else { len(name) },
            &sized(k, ws.reorder),
            &shape.aliases.iter().filter(|(name, _)| !matches!(*name, "keys" | "unordered")).copied().collect::<Vec<_>>(),
        )?;
        let wcsph = if shape.dfsph {
            None
        } else {
            let density_file = if params.continuity_density { "continuity" } else { "density" };
            Some(WcsphStages {
                // The density stage: summation, or with continuity density the carried density.
                density: neighbour_stage(density_file, if params.continuity_density { "continuity_density" } else { "density" }, ws.density)?,
                density_listed: match (options.neighbour_skin, shape.list_capacity) {
                    (Some(_), Some(_)) => {
                        let mut c = sized(k, ws.density);
                        c.push(("RECORD_LISTS", 0.0));
                        let tiled = format!("{density_file}_tiled");
                        Some(stage(&tiled, &tiled, &len, &c)?)
                    }
                    _ => None,
                },
                // One invocation per wall particle, at the density stage's workgroup size.
                wall_pressure: if shape.adami { Some(stage("wall_pressure", "wall_pressure", &len, &sized(k, ws.density))?) } else { None },
                // One invocation per fluid particle, at the forces' workgroup size; with tiles
                // a subgroup's stencils walked together.
                surface_normals: if shape.surface_tension { Some(neighbour_stage("surface_normals", "surface_normals", ws.forces)?) } else { None },
                forces: neighbour_stage("forces", "forces", ws.forces)?,
                advance: if shape.fused {
                    stage("forces_integrate", "forces_and_integrate", &without_accelerations, &sized(k, ws.forces))?
                } else if shape.tiles {
                    // Its largest speed over a subgroup, without the workgroup's barriers.
                    stage_in_place("integrate_tiled", "integrate_tiled", &len, &sized(k, ws.integrate))?
                } else {
                    stage_in_place("integrate", "integrate", &len, &sized(k, ws.integrate))?
                },
                adaptive: match params.adaptive {
                    Some(_) => Some((
                        stage_in_place("integrate", "reduce_maxima", &len, &sized(k, ws.integrate))?,
                        stage_in_place("integrate", "choose_dt", &len, k)?,
                    )),
                    None => None,
                },
            })
        };
        Ok(Pipelines {
            bin_count,
            bin_scatter,
            reorder_rank,
            reorder,
            wcsph,
            // One thread on the status words.
            finish_step: stage_in_place("integrate", "finish_step", &without_accelerations, k)?,
            fused: shape.fused,
            subgroup_tiles: shape.tiles,
        })
    }
}
