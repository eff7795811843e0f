//! The GPU memory of the solver, planned before anything is allocated.
//!
//! [`MemoryPlan`] lists every buffer the GPU solver creates with its size in bytes. The
//! solver checks the plan against the device's limits before it creates a buffer, and reports
//! the plan's total as its memory (`Backend::memory_bytes`), so the check and the figure cannot
//! disagree. wgpu reports no free-memory figure for an adapter, so only the per-buffer limits
//! (`max_buffer_size`, `max_storage_buffer_binding_size`) are checked; an allocation beyond the
//! device's memory still fails inside the driver.

use super::buffers::{StateLayout, WALL_CELL_BLOCK};
use super::device::GpuContext;
use super::params::{status, GpuParams};
use super::prefix_sum::Scan;
use crate::model::scene::{PressureSolver, Scene};

/// One buffer of the solver.
#[derive(Clone, Debug, PartialEq)]
pub struct PlannedBuffer {
    pub label: &'static str,
    pub bytes: u64,
    /// Bytes per fluid particle (0 for buffers that do not grow with the fluid).
    pub bytes_per_fluid_particle: u64,
    /// Bound whole as one storage binding (the others are the uniform block and the arrays bound
    /// in segments).
    pub single_binding: bool,
}

/// The particle arrays a step keeps besides the cell arrays and the walls (docs/performance.md,
/// "GPU memory layout").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StepArrays {
    /// How the positions and velocities are held.
    pub layout: StateLayout,
    /// A separate accelerations array (DFSPH with adaptive dt; in place the accelerations live
    /// in the state's spare buffer, and the fused step keeps them in registers).
    pub accelerations: bool,
    /// A densities array (with the continuity equation, whose velocities carry the density of
    /// the step before, and DFSPH); a summed density lives in the w of the velocities.
    pub densities: bool,
    /// A pressures array (DFSPH, whose pressure is no function of the density); elsewhere the
    /// equation of state gives it where it is read.
    pub pressures: bool,
}

impl StepArrays {
    /// The arrays of a step: DFSPH (in place) or the weakly compressible step (fused, or in
    /// place), with
    /// the continuity equation or summed density, with adaptive or fixed dt.
    pub fn new(dfsph: bool, continuity_density: bool, adaptive: bool, fused: bool) -> StepArrays {
        StepArrays {
            layout: if fused && !dfsph { StateLayout::PingPong } else { StateLayout::InPlace },
            accelerations: dfsph && adaptive,
            densities: dfsph || continuity_density,
            pressures: dfsph,
        }
    }
}

/// Every buffer the solver allocates for a scene.
#[derive(Clone, Debug, PartialEq)]
pub struct MemoryPlan {
    pub fluid: u64,
    /// `None` before the walls are generated (a check from the scene's sizes alone).
    pub walls: Option<u64>,
    pub cells: u64,
    pub buffers: Vec<PlannedBuffer>,
}

/// The scene does not fit the adapter.
#[derive(Debug, thiserror::Error)]
#[error(
    "adapter '{adapter}' ({backend}): {particles} fluid particles{walls} and {cells} grid cells need {at_least}{total} bytes ({total_mib} MiB) of GPU memory; \
     the buffer '{buffer}' needs {need} bytes but the adapter's {limit} is {have} bytes{fit}"
)]
pub struct GpuMemoryError {
    pub adapter: String,
    pub backend: String,
    pub particles: u64,
    walls: String,
    at_least: &'static str,
    pub cells: u64,
    pub total: u64,
    total_mib: u64,
    pub buffer: String,
    pub need: u64,
    pub limit: &'static str,
    pub have: u64,
    fit: String,
}

/// What `storage`/`storage_init` in the solver allocate: never less than 16 bytes.
fn padded(bytes: u64) -> u64 {
    bytes.max(16)
}

impl MemoryPlan {
    /// The buffers of a solver with `fluid` particles, `walls` wall particles and `cells` grid
    /// cells; `uniform_bytes` is the size of the parameter block; `arrays`: the particle arrays
    /// the step keeps.
    pub fn new(fluid: u64, walls: Option<u64>, cells: u64, uniform_bytes: u64, arrays: StepArrays) -> MemoryPlan {
        let w = walls.unwrap_or(0);
        let per_fluid = |label, per: u64| PlannedBuffer { label, bytes: padded(fluid * per), bytes_per_fluid_particle: per, single_binding: false };
        let fixed = |label, bytes| PlannedBuffer { label, bytes, bytes_per_fluid_particle: 0, single_binding: false };
        let mut buffers = vec![
            PlannedBuffer { label: "params", bytes: uniform_bytes, bytes_per_fluid_particle: 0, single_binding: false },
            fixed("wall positions", padded(w * 16)),
            // Without walls the shaders never read the wall cell index; its starts are planned
            // once the walls are known (`with_wall_cell_starts`).
            fixed("wall cell blocks", padded(if w > 0 { (cells + 1).div_ceil(WALL_CELL_BLOCK as u64) * 8 } else { 0 })),
        ];
        // The particles' ids ride in the w of the positions.
        let state: &[&'static str] = match arrays.layout {
            StateLayout::PingPong => &["positions 0", "velocities 0", "positions 1", "velocities 1"],
            StateLayout::InPlace => &["particle state 0", "particle state 1", "particle state 2"],
        };
        buffers.extend(state.iter().map(|&label| per_fluid(label, 16)));
        buffers.extend([
            fixed("cell starts", padded((cells + 1) * 4)),
            fixed("placeholder", 16),
            PlannedBuffer { label: "status", bytes: padded(status::BYTES), bytes_per_fluid_particle: 0, single_binding: true },
        ]);
        if arrays.densities {
            buffers.push(per_fluid("densities", 4));
        }
        if arrays.pressures {
            buffers.push(per_fluid("pressures", 4));
        }
        if arrays.accelerations {
            buffers.push(per_fluid("accelerations", 16));
        }
        buffers.extend(Scan::sum_buffer_bytes(cells + 1).into_iter().map(|bytes| fixed("scan block sums", bytes)));
        MemoryPlan { fluid, walls, cells, buffers }
    }

    /// The plan with the wall cell index's starts: `entries` values (the cells that hold walls
    /// and one more, or more room; see [`super::buffers::WallCellIndex`]; 0 without walls).
    pub fn with_wall_cell_starts(mut self, entries: u64) -> MemoryPlan {
        self.buffers.push(PlannedBuffer { label: "wall cell starts", bytes: padded(entries * 4), bytes_per_fluid_particle: 0, single_binding: false });
        self
    }

    /// The plan with the Adami wall pressure's array (a pressure and a density per wall
    /// particle) for `walls` wall particles; nothing for 0.
    pub fn with_wall_fields(mut self, walls: u64) -> MemoryPlan {
        if walls > 0 {
            self.buffers.push(PlannedBuffer { label: "wall fields", bytes: padded(walls * 8), bytes_per_fluid_particle: 0, single_binding: false });
        }
        self
    }

    /// The plan with surface tension's normals (a vec4 per fluid particle); nothing without.
    pub fn with_surface_normals(mut self, fluid: u64, used: bool) -> MemoryPlan {
        if used {
            self.buffers.push(PlannedBuffer { label: "surface normals", bytes: padded(fluid * 16), bytes_per_fluid_particle: 16, single_binding: false });
        }
        self
    }

    /// The plan with the neighbour lists (`capacity` slots and a count per fluid particle;
    /// nothing for a capacity of 0).
    pub fn with_neighbour_lists(mut self, fluid: u64, capacity: u32) -> MemoryPlan {
        if capacity > 0 {
            let per = capacity as u64 * 4;
            self.buffers.push(PlannedBuffer { label: "neighbour lists", bytes: padded(fluid * per), bytes_per_fluid_particle: per, single_binding: false });
            self.buffers.push(PlannedBuffer { label: "neighbour counts", bytes: padded(fluid * 4), bytes_per_fluid_particle: 4, single_binding: false });
        }
        self
    }

    /// The plan with a neighbour skin's arrays (each fluid particle's position at the last
    /// rebuild, and the check's word); nothing without one.
    pub fn with_neighbour_skin(mut self, fluid: u64, skin: bool) -> MemoryPlan {
        if skin {
            self.buffers.push(PlannedBuffer { label: "rebuild positions", bytes: padded(fluid * 16), bytes_per_fluid_particle: 16, single_binding: false });
            self.buffers.push(PlannedBuffer { label: "skin check", bytes: super::skin::CHECK_BYTES, bytes_per_fluid_particle: 0, single_binding: true });
        }
        self
    }

    /// The plan with DFSPH's own arrays added (for `fluid` particles).
    pub fn with_dfsph(mut self, fluid: u64) -> MemoryPlan {
        for (label, bytes) in super::dfsph::buffer_bytes(fluid) {
            let per = if bytes == 32 { 0 } else { bytes / fluid.max(1) };
            // The dispatch sizes are bound whole; every other array in segments.
            self.buffers.push(PlannedBuffer { label, bytes: padded(bytes), bytes_per_fluid_particle: per, single_binding: per == 0 });
        }
        self
    }

    /// The plan of a scene from its lattice sizes, before any particle is created on the host:
    /// a lower bound (walls not counted, as they are known only once generated; the weakly
    /// compressible step's state in place, its smallest). The solver checks its exact plan
    /// again before it allocates.
    pub fn for_scene(scene: &Scene) -> MemoryPlan {
        let uniform = GpuParams::default().bytes().len() as u64;
        let (n, cells) = (scene.fluid_particle_count(), scene.grid().cell_count() as u64);
        let dfsph = scene.physics.solver == PressureSolver::Dfsph;
        let continuity = scene.physics.density == crate::model::scene::DensityMethod::Continuity;
        let arrays = StepArrays::new(dfsph, continuity, scene.time.adaptive, false);
        let plan = MemoryPlan::new(n, None, cells, uniform, arrays);
        if dfsph {
            plan.with_dfsph(n)
        } else {
            plan
        }
    }

    /// Bytes of all buffers.
    pub fn total(&self) -> u64 {
        self.buffers.iter().map(|b| b.bytes).sum()
    }

    /// Fails, naming the adapter, the particle count, the total bytes and the limit, when a
    /// buffer exceeds `max_buffer_size` or a buffer bound whole `max_storage_buffer_binding_size`.
    pub fn check(&self, ctx: &GpuContext) -> Result<(), GpuMemoryError> {
        let l = ctx.device.limits();
        let binding = l.max_storage_buffer_binding_size as u64;
        for b in &self.buffers {
            let over = if b.bytes > l.max_buffer_size {
                Some(("max_buffer_size", l.max_buffer_size))
            } else if b.single_binding && b.bytes > binding {
                Some(("max_storage_buffer_binding_size", binding))
            } else {
                None
            };
            let Some((limit, have)) = over else { continue };
            let total = self.total();
            return Err(GpuMemoryError {
                adapter: ctx.info.name.clone(),
                backend: format!("{:?}", ctx.info.backend),
                particles: self.fluid,
                walls: match self.walls {
                    Some(w) => format!(", {w} wall particles"),
                    None => " (walls not yet counted)".into(),
                },
                at_least: if self.walls.is_some() { "" } else { "at least " },
                cells: self.cells,
                total,
                total_mib: total >> 20,
                buffer: b.label.into(),
                need: b.bytes,
                limit,
                have,
                fit: if b.bytes_per_fluid_particle > 0 {
                    format!(" (at most {} fluid particles fit; choose a smaller --particles)", have / b.bytes_per_fluid_particle)
                } else {
                    " (use a coarser grid: a larger smoothing length or a smaller domain)".into()
                },
            });
        }
        Ok(())
    }
}
