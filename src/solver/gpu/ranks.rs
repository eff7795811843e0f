//! The GPU step of one rank across ranks (docs/scale-out.md): the host runs the exchange
//! (src/solver/cpu/exchange.rs, shared with the CPU path), then the rank's particles (own and
//! ghosts) go up, the ordinary GPU step runs once on them, and the cell-sorted result comes
//! back for the next exchange. The buffers are made for a capacity above the held count and
//! the stages bound to `fluid_count`, so a changing count costs no new pipelines unless it
//! outgrows the capacity.

use super::buffers::{ids_of, storage, vec4s, WallCellIndex, GHOST_BIT, WALL_CELL_BLOCK};
use super::device::GpuContext;
use super::readback::read_buffers;
use super::{GpuOptions, GpuSolver};
use crate::model::initial::InitialState;
use crate::model::params::Params;
use crate::model::kernels::sort_by_cell;
use crate::model::real::V3;
use crate::solver::communicator::Communicator;
use crate::solver::cpu::exchange::{Carried, Held};
use crate::solver::cpu::rank_device::{DeviceStages, DfsphHeld, HeldArrays, ResidentBand, ResidentSolves, ResidentStep};
use crate::solver::cpu::resident_exchange::SlabFaces;
use super::resident::{received_w, PlaceArrays, ResidentExchange};
use super::dfsph::RankSolves;
use super::params::status;
use std::sync::Arc;

/// Bytes of the resident exchange's control and health words.
const WORDS_BYTES: u64 = super::resident::words::COUNT as u64 * 4;

/// Room made above the held count when the buffers are (re)made: migration and moving bounds
/// change the count a little from step to step.
const CAPACITY_MARGIN: f64 = 1.25;

/// The device stages of a rank on the GPU.
pub struct GpuRankStages {
    ctx: GpuContext,
    params: Params,
    options: GpuOptions,
    /// The walls near the rank's slab, in the initial state's form.
    walls: InitialState,
    /// Made on the first step, with room for `capacity` particles.
    solver: Option<GpuSolver>,
    capacity: usize,
    /// Why this adapter, for the summary.
    why: String,
    /// The ranks, for the adaptive step's maxima.
    comm: Arc<dyn Communicator>,
    /// The resident exchange's stages and arrays (src/solver/gpu/resident.rs), made on first
    /// use for the current solver.
    resident: Option<ResidentExchange>,
    /// Whether the device holds the state its last step left (a resident step may start from
    /// it).
    keeps_step: bool,
    /// Bytes of particles that crossed between the host and the device (both ways), so far.
    bus_bytes: u64,
    /// Band and received particles the resident exchange makes room for: at first an eighth of
    /// the held particles or a quarter more than the ghosts of the last full step (the band
    /// the neighbours take and the particles they send are each about that many), whichever
    /// is more; more once a step needed more.
    list_room: u64,
    /// DFSPH: each place's particle id (a position's w holds its place in the upload, where the
    /// warm starts live too), for the solver's capacity; uploaded with the particles, written
    /// again by each resident step's merge.
    place_ids: Option<wgpu::Buffer>,
}

impl GpuRankStages {
    /// The stages on `ctx` for the scene's `params`, for a rank of `comm` (the walls come
    /// with [`DeviceStages::set_walls`]). `why`: how the adapter was chosen.
    pub fn new(ctx: GpuContext, params: &Params, options: GpuOptions, why: String, comm: Arc<dyn Communicator>) -> Self {
        GpuRankStages { ctx, params: params.clone(), options, walls: InitialState::default(), solver: None, capacity: 0, why, comm, resident: None, keeps_step: false, bus_bytes: 0, list_room: 0, place_ids: None }
    }

    /// A solver with buffers for `capacity` particles (placeholders at the domain's lower
    /// corner, never bound past the held count) and room for [`CAPACITY_MARGIN`] times the
    /// walls near the slab, which are loaded into it: when the slab's bounds move, other walls
    /// replace them in the same buffers ([`GpuSolver::load_walls`]) and no pipeline is made
    /// again unless they outgrow that room.
    fn make_solver(&self, capacity: usize) -> anyhow::Result<GpuSolver> {
        let corner = self.params.domain_min;
        let mut initial = self.walls.clone();
        // The room: the walls repeated (overwritten by the load below before any step), where
        // other walls can be loaded later (no force probe on the device: their masks follow the
        // walls made with).
        let reloadable = self.params.probes.force_count() == 0 && !initial.wall_positions.is_empty();
        let room = if reloadable { ((initial.wall_positions.len() as f64) * CAPACITY_MARGIN).ceil() as usize } else { 0 };
        repeat_to(&mut initial.wall_positions, room);
        repeat_to(&mut initial.wall_masses, room);
        repeat_to(&mut initial.wall_boundaries, room);
        initial.fluid_positions = vec![corner; capacity];
        initial.fluid_velocities = vec![[0.0; 3]; capacity];
        if self.params.continuity_density {
            initial.fluid_densities = vec![self.params.rest_density; capacity];
        }
        let mut solver = GpuSolver::build(self.ctx.clone(), &self.params, &initial, self.options, Some(self.comm.clone()))?;
        anyhow::ensure!(!reloadable || solver.load_walls(&self.walls), "the walls near the slab do not fit the buffers made for them");
        Ok(solver)
    }
}

impl DeviceStages<f32> for GpuRankStages {
    fn describe(&self) -> String {
        format!("{} ({})", self.ctx.describe(), self.why)
    }

    fn set_walls(&mut self, walls: &InitialState) {
        self.keep_walls(walls);
        // Loaded where they fit; otherwise made again, with these walls, at the next step.
        if !self.solver.as_mut().is_some_and(|solver| solver.load_walls(walls)) {
            self.solver = None;
            self.resident = None;
            self.keeps_step = false;
        }
    }

    fn run_step(&mut self, step: u64, held: HeldArrays<'_, f32>) -> anyhow::Result<f64> {
        self.run(step, held, true)
    }

    fn run_fields(&mut self, step: u64, held: HeldArrays<'_, f32>) -> anyhow::Result<()> {
        self.run(step, held, false).map(|_| ())
    }

    fn resident_band(&mut self, faces: &SlabFaces) -> anyhow::Result<Option<ResidentBand<f32>>> {
        if !self.make_resident()? {
            return Ok(None);
        }
        let (Some(solver), Some(resident)) = (self.solver.as_ref(), self.resident.as_ref()) else { return Ok(None) };
        let band = resident.band(solver, faces);
        // The control words written, and what the reads took.
        self.bus_bytes += WORDS_BYTES + resident.band_bytes_read();
        let band = match band? {
            Ok(band) => band,
            Err(size) => {
                // This step takes the full path; the next has room for this band and a quarter more.
                self.grow_lists(size);
                return Ok(None);
            }
        };
        // In slot order, which is the one-process order (the state is in the cell order of its
        // binning).
        let mut by_slot: Vec<(u32, usize)> = (0..band.entries.len()).map(|k| (band.slot(k), k)).collect();
        by_slot.sort_unstable();
        let (continuity, dfsph) = (self.params.continuity_density, resident.carries_places());
        let mut particles = Held::default();
        particles.reserve(by_slot.len(), Carried { density: continuity, warm: dfsph });
        for &(_, k) in &by_slot {
            let [p, v, key] = band.entries[k];
            particles.x.push(V3([p[0], p[1], p[2]]));
            particles.v.push(V3([v[0], v[1], v[2]]));
            particles.id.push(p[3].to_bits() & !GHOST_BIT);
            if continuity {
                particles.rho.push(v[3]);
            }
            if dfsph {
                // The constant-density warm start in the velocity's w, the divergence one beside
                // the key.
                particles.warm.push([v[3], key[3]]);
            }
            particles.order.push(band.key(k));
        }
        let mut dropped = band.dropped;
        dropped.sort_unstable();
        Ok(Some(ResidentBand { dropped, slots: by_slot.iter().map(|&(slot, _)| slot).collect(), particles }))
    }

    fn run_resident_step(&mut self, step: u64, dropped: &[u32], received: &Held<f32>, ghosts: &[bool], solves: Option<ResidentSolves<'_>>) -> anyhow::Result<Option<ResidentStep>> {
        let (Some(solver), Some(resident)) = (self.solver.as_mut(), self.resident.as_ref()) else { return Ok(None) };
        if !self.keeps_step {
            return Ok(None);
        }
        // With DFSPH the velocity's w carries the constant-density warm start (DFSPH sums its
        // density: the w holds no carried density) and the divergence one goes beside it.
        let positions: Vec<[f32; 4]> = (0..received.len()).map(|k| {
            let x = received.x[k].0;
            [x[0], x[1], x[2], received_w(received.id[k], ghosts[k])]
        }).collect();
        let velocities: Vec<[f32; 4]> = (0..received.len()).map(|k| {
            let v = received.v[k].0;
            let w = received.warm.get(k).map_or(received.rho.get(k).copied().unwrap_or(0.0), |warm| warm[0]);
            [v[0], v[1], v[2], w]
        }).collect();
        let warm_divergence: Vec<f32> = received.warm.iter().map(|w| w[1]).collect();
        if !resident.merge(solver, dropped, &positions, &velocities, &received.order, &warm_divergence) {
            if received.len() as u64 > resident.list_capacity() {
                self.grow_lists(received.len() as u64);
            }
            return Ok(None);
        }
        // The control words, the dropped slots and the received particles; after the step the
        // health's words (written and read) and the status words up to dt.
        self.bus_bytes += 3 * WORDS_BYTES + 4 * dropped.len() as u64 + 48 * received.len() as u64 + (status::DT as u64 + 1) * 4;
        self.keeps_step = false;
        solver.steps = step;
        solver.accelerations_valid = false;
        if let Some(s) = &solves {
            // The solves across ranks, their link made from the step's binning on the slab's faces.
            *solver.rank_solves.borrow_mut() = Some(RankSolves::new(Some(s.link.clone()), Some(s.faces.clone()), *s.stats, s.particles, false));
        }
        solver.advance(1);
        if let (Some(s), Some(done)) = (solves, solver.rank_solves.borrow_mut().take()) {
            done.hand_back(s.stats, Some(s.link), &mut self.bus_bytes)?;
        }
        if let Some(e) = solver.rank_error.borrow_mut().take() {
            anyhow::bail!("the adaptive step's maxima across ranks: {e}");
        }
        let (health, words) = resident.own_health(solver, status::DT as u64 + 1)?;
        self.keeps_step = true;
        Ok(Some(ResidentStep { dt: self.step_dt(&words), health }))
    }

    fn own_layer_counts(&mut self, axis: usize) -> anyhow::Result<Option<Vec<u32>>> {
        if !self.make_resident()? {
            return Ok(None);
        }
        let (Some(solver), Some(resident)) = (self.solver.as_ref(), self.resident.as_ref()) else { return Ok(None) };
        let counts = resident.layer_counts(solver, axis)?;
        // The control words written, and the counts read.
        self.bus_bytes += WORDS_BYTES + 4 * counts.len() as u64;
        Ok(Some(counts))
    }

    fn replace_walls(&mut self, walls: &InitialState) -> bool {
        if !self.solver.as_mut().is_some_and(|solver| solver.load_walls(walls)) {
            return false;
        }
        self.keep_walls(walls);
        true
    }

    fn take_probe_rows(&mut self) -> anyhow::Result<Vec<(u64, Vec<f64>)>> {
        let Some(solver) = self.solver.as_mut() else { return Ok(Vec::new()) };
        let samples = crate::solver::backend::Backend::take_probe_samples(solver)?;
        // Each row: its head (step, the time's three words, dt) and its values, in words.
        self.bus_bytes += samples.iter().map(|s| 4 * (5 + s.values.len() as u64)).sum::<u64>();
        Ok(samples.into_iter().map(|s| (s.step, s.values)).collect())
    }

    fn read_held(&mut self, mut held: HeldArrays<'_, f32>) -> anyhow::Result<()> {
        anyhow::ensure!(self.keeps_step, "the device keeps no step's particles");
        // The host's ids are no longer in the order of the upload: with DFSPH they come from the
        // device's places.
        let dfsph = held.dfsph.take();
        self.read_back(held, dfsph, true).map(|_| ())
    }

    fn bus_bytes(&self) -> u64 {
        self.bus_bytes
    }
}

impl GpuRankStages {
    /// Uploads `held`, runs one step (`advance`) or only the binning and density stage, and
    /// reads the cell-sorted result back into `held`. Returns the step's dt (the GPU's choice
    /// with adaptive dt).
    fn run(&mut self, step: u64, mut held: HeldArrays<'_, f32>, advance: bool) -> anyhow::Result<f64> {
        let n = held.positions.len();
        let mut dfsph = held.dfsph.take();
        self.keeps_step = false;
        if self.solver.is_none() || n > self.capacity {
            let capacity = ((n.max(1) as f64) * CAPACITY_MARGIN).ceil() as usize;
            let solver = self.make_solver(capacity)?;
            self.place_ids = solver.dfsph.is_some().then(|| storage(&self.ctx.device, "place ids", solver.store.capacity() * 4));
            self.solver = Some(solver);
            self.resident = None;
            self.capacity = capacity;
        }
        let solver = self.solver.as_mut().expect("made above");
        let wide = |v: &V3<f32>| [v.0[0] as f64, v.0[1] as f64, v.0[2] as f64];
        let positions: Vec<[f64; 3]> = held.positions.iter().map(wide).collect();
        let velocities: Vec<[f64; 3]> = held.velocities.iter().map(wide).collect();
        // DFSPH finds each particle's warm starts by its place in the upload; the weakly
        // compressible step keeps its id, which a resident step's merge carries along.
        let ids = if dfsph.is_some() { None } else { Some(held.ids.as_slice()) };
        solver.load_held(&positions, &velocities, held.carried_densities, held.ghosts, ids, step);
        self.bus_bytes += 32 * n as u64;
        let ghosts = held.ghosts.iter().filter(|&&g| g).count() as u64;
        self.list_room = self.list_room.max(ghosts + ghosts / 4);
        if let Some(d) = &dfsph {
            solver.load_dfsph_held(d);
            self.bus_bytes += 8 * n as u64;
        }
        if let (Some(ids), true) = (&self.place_ids, advance) {
            // Each place's id, for the resident steps that may follow this one.
            self.ctx.queue.write_buffer(ids, 0, bytemuck::cast_slice(held.ids.as_slice()));
            self.bus_bytes += 4 * n as u64;
        }
        if advance {
            solver.advance(1);
        } else {
            solver.refresh_fields();
        }
        let solves = solver.rank_solves.borrow_mut().take();
        if let (Some(d), Some(solves)) = (dfsph.as_mut(), solves) {
            let prediction_start = solves.hand_back(d.stats, d.link.as_deref_mut(), &mut self.bus_bytes)?;
            if let (Some(out), Some(v)) = (d.prediction_start.as_deref_mut(), prediction_start) {
                *out = v.iter().map(|v| V3([v[0], v[1], v[2]])).collect();
            }
        }
        if let Some(e) = solver.rank_error.borrow_mut().take() {
            anyhow::bail!("the adaptive step's maxima across ranks: {e}");
        }
        let dt = self.read_back(held, dfsph, false)?;
        self.keeps_step = advance;
        Ok(dt)
    }

    /// Reads the device's state back into `held` in cell order (positions, velocities, ids, the
    /// carried densities, the densities and pressures, the cell starts; with DFSPH the warm
    /// starts); returns the last step's dt. With DFSPH each slot's id is found by its place:
    /// in `held`'s ids where they are the upload's, else (`places_on_device`) in the device's.
    fn read_back(&mut self, held: HeldArrays<'_, f32>, dfsph: Option<DfsphHeld<'_, f32>>, places_on_device: bool) -> anyhow::Result<f64> {
        let solver = self.solver.as_ref().expect("made by a step");
        let n = solver.fluid_count as usize;
        let cells = self.params.grid.cell_count() as u64;
        let st = solver.store.state(solver.current);
        let bytes = n as u64;
        let data = read_buffers(&self.ctx, &[
            (&st.positions, bytes * 16),
            (&st.velocities, bytes * 16),
            (&solver.starts, (cells + 1) * 4),
            (&solver.status, (status::DT as u64 + 1) * 4),
        ])?;
        self.bus_bytes += 32 * bytes + (cells + 1) * 4 + (status::DT as u64 + 1) * 4;
        let pos: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&data[0]);
        let vel: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&data[1]);
        // The w of a position is the particle's id (DFSPH: its place in the upload), with the
        // ghost bit.
        let slots = ids_of(&pos).into_iter().map(|w| w & !GHOST_BIT);
        *held.ids = match (&dfsph, &self.place_ids) {
            (Some(_), Some(ids)) if places_on_device => {
                // Uploaded with the step's particles, or written by a resident step's merge.
                let by_place: Vec<u32> = bytemuck::pod_collect_to_vec(&read_buffers(&self.ctx, &[(ids, bytes * 4)])?[0]);
                self.bus_bytes += 4 * bytes;
                slots.map(|place| by_place[place as usize]).collect()
            }
            (Some(_), _) => {
                let uploaded = std::mem::take(held.ids);
                slots.map(|slot| uploaded[slot as usize]).collect()
            }
            (None, _) => slots.collect(),
        };
        *held.positions = pos.iter().map(|p| V3([p[0], p[1], p[2]])).collect();
        *held.velocities = vel.iter().map(|v| V3([v[0], v[1], v[2]])).collect();
        if self.params.continuity_density {
            *held.carried_densities = vel.iter().map(|v| v[3]).collect();
        }
        if let (Some(d), Some(gpu)) = (dfsph, &solver.dfsph) {
            // The warm starts by place in the upload, where the step left them; each slot's key
            // is its particle's place.
            let b = &gpu.buffers;
            let data = read_buffers(&self.ctx, &[(&b.warm_pressure, n as u64 * 4), (&b.warm_divergence, n as u64 * 4)])?;
            *d.warm_pressure = bytemuck::pod_collect_to_vec(&data[0]);
            *d.warm_divergence = bytemuck::pod_collect_to_vec(&data[1]);
            *d.warm_keys = ids_of(&pos).iter().map(|&slot| slot & !GHOST_BIT).collect();
            self.bus_bytes += 8 * bytes;
        }
        (*held.densities, *held.pressures) = solver.read_fields(solver.current)?;
        // Where the step keeps no densities, they come from the w of the velocities, read again.
        self.bus_bytes += bytes * if solver.densities.is_some() { 4 } else { 16 } + bytes * 4 * solver.pressures.is_some() as u64;
        *held.starts = bytemuck::pod_collect_to_vec(&data[2]);
        let words: Vec<u32> = bytemuck::pod_collect_to_vec(&data[3]);
        Ok(self.step_dt(&words))
    }

    /// The walls a solver made again is made with.
    fn keep_walls(&mut self, walls: &InitialState) {
        self.walls = InitialState {
            wall_positions: walls.wall_positions.clone(),
            wall_masses: walls.wall_masses.clone(),
            wall_boundaries: walls.wall_boundaries.clone(),
            ..InitialState::default()
        };
    }

    /// The resident exchange's stages, made where the device keeps the last step's particles
    /// and the rank takes resident steps; false where it does not.
    fn make_resident(&mut self) -> anyhow::Result<bool> {
        if !self.keeps_step || self.options.full_exchange {
            return Ok(false);
        }
        let solver = self.solver.as_ref().expect("kept by a step");
        if self.resident.is_none() {
            let room = self.list_room.max(solver.fluid_count as u64 / 8);
            let places = match (&self.place_ids, &solver.dfsph) {
                (Some(ids), Some(d)) => Some(PlaceArrays { ids, warm_pressure: &d.buffers.warm_pressure, warm_divergence: &d.buffers.warm_divergence }),
                _ => None,
            };
            self.resident = Some(ResidentExchange::new(solver, room, places)?);
        }
        Ok(true)
    }

    /// Room for `needed` band or received particles and a quarter more, from the next step on.
    fn grow_lists(&mut self, needed: u64) {
        self.list_room = self.list_room.max(needed + needed / 4);
        self.resident = None;
    }

    /// The last step's dt: the GPU's choice (in the status words) with adaptive dt.
    fn step_dt(&self, words: &[u32]) -> f64 {
        match self.params.adaptive {
            Some(_) => f32::from_bits(words[status::DT]) as f64,
            None => self.params.dt,
        }
    }
}

impl GpuSolver {
    /// Replaces the wall particles by `walls` (a rank's walls near its slab) in the buffers
    /// made for the walls, sorted by cell as [`GpuSolver::build`] sorts them, without making
    /// any pipeline again. False, and nothing changed, where they do not fit: more walls than
    /// the buffers hold, a solver made without walls (its stages skip them), or force probes on
    /// the device (their masks follow the walls).
    pub(super) fn load_walls(&mut self, walls: &InitialState) -> bool {
        let w = walls.wall_positions.len();
        let cells = self.params.grid.cell_count() as u64;
        let made_with_walls = self.wall_cell_blocks.size() >= (cells + 1).div_ceil(WALL_CELL_BLOCK as u64) * 8;
        if w as u64 > self.wall_positions.size() / 16 || !made_with_walls || self.params.probes.force_count() > 0 {
            return false;
        }
        let grid = self.params.grid.cast::<f32>();
        let wall_f32: Vec<V3<f32>> = walls.wall_positions.iter().map(|&p| V3::from64(p)).collect();
        let (order, starts) = sort_by_cell(&grid, &wall_f32);
        let index = WallCellIndex::new(&starts);
        if index.firsts.len() as u64 > self.wall_cell_firsts.size() / 4 {
            return false;
        }
        let sorted: Vec<[f64; 3]> = order.iter().map(|&i| walls.wall_positions[i as usize]).collect();
        let positions = vec4s(&sorted, |k| walls.wall_masses[order[k] as usize] as f32);
        let queue = &self.ctx.queue;
        queue.write_buffer(&self.wall_positions, 0, bytemuck::cast_slice(&positions));
        queue.write_buffer(&self.wall_cell_blocks, 0, bytemuck::cast_slice(&index.blocks));
        queue.write_buffer(&self.wall_cell_firsts, 0, bytemuck::cast_slice(&index.firsts));
        if let Some(fields) = &self.wall_fields {
            // As at the start: no pressure, rest density (each step evaluates them first).
            let rest: Vec<[f32; 2]> = vec![[0.0, self.params.rest_density as f32]; w];
            queue.write_buffer(fields, 0, bytemuck::cast_slice(&rest));
        }
        self.wall_order = order;
        self.wall_count = w as u32;
        // Every stage reads the wall count from the uniform block.
        let p = super::params::GpuParams::new(&self.params, self.fluid_count, self.wall_count, self.uniform_viscosity);
        queue.write_buffer(&self.uniform, 0, &p.bytes());
        true
    }

    /// DFSPH across ranks, after [`GpuSolver::load_held`]: the held particles' warm starts in the
    /// order of the upload (the shaders find them by that place), the last step's dt (adaptive
    /// dt: the divergence solve and the output pressure read it from the status words, which a
    /// solver made again does not hold), and for a step the solves' ghosts and iterations.
    pub(super) fn load_dfsph_held(&mut self, held: &DfsphHeld<'_, f32>) {
        let Some(gpu) = &self.dfsph else { return };
        let n = self.fluid_count as usize;
        let key = |k: usize| held.warm_keys.get(k).map_or(k, |&key| key as usize);
        let (pressure, divergence): (Vec<f32>, Vec<f32>) = (0..n).map(|k| (held.warm_pressure[key(k)], held.warm_divergence[key(k)])).unzip();
        let queue = &self.ctx.queue;
        queue.write_buffer(&gpu.buffers.warm_pressure, 0, bytemuck::cast_slice(&pressure));
        queue.write_buffer(&gpu.buffers.warm_divergence, 0, bytemuck::cast_slice(&divergence));
        if self.params.adaptive.is_some() {
            queue.write_buffer(&self.status, status::DT as u64 * 4, bytemuck::bytes_of(&(held.last_dt as f32)));
        }
        *self.rank_solves.borrow_mut() = Some(RankSolves::new(held.link.as_deref().cloned(), held.faces.clone(), *held.stats, held.particles, held.prediction_start.is_some()));
    }

    /// Puts `positions`, `velocities` (and with continuity density `carried` densities) in the
    /// buffers as the current state of step `step`, each particle's w its id (`ids`; without
    /// them its index) with [`GHOST_BIT`] where `ghosts` says so, and binds the stages to that
    /// many particles (at most the buffers' capacity).
    pub(super) fn load_held(&mut self, positions: &[[f64; 3]], velocities: &[[f64; 3]], carried: &[f32], ghosts: &[bool], ids: Option<&[u32]>, step: u64) {
        self.set_held_count(positions.len() as u32);
        let carried_of = |i: usize| carried.get(i).copied().unwrap_or(0.0);
        let id_of = |i: usize| ids.map_or(i as u32, |ids| ids[i]) | if ghosts.get(i).copied().unwrap_or(false) { GHOST_BIT } else { 0 };
        self.store.state(0).upload(&self.ctx, positions, velocities, id_of, &carried_of);
        self.current = 0;
        self.fields_state = 0;
        self.accelerations_valid = false;
        self.steps = step;
    }
}

/// `v` repeated from its start until it holds `len` elements (as it is when empty or longer).
fn repeat_to<T: Clone>(v: &mut Vec<T>, len: usize) {
    let extra: Vec<T> = v.iter().cycle().take(len.saturating_sub(v.len())).cloned().collect();
    v.extend(extra);
}
