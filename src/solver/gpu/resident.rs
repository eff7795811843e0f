//! A rank's step on the GPU with its interior left on the device (docs/scale-out.md, "The GPU
//! across ranks"): after a step the device keeps the held particles, and the next exchange
//! reads back only the band the exchange touches (the particles that left the slab and those in
//! the layers next to a face), uploads only what the neighbours sent (migrants and ghosts), and
//! merges the two on the device in the one-process order (wgsl/sim/resident_exchange.wgsl, whose
//! CPU twin is src/solver/cpu/resident_exchange.rs). The full readback and upload
//! (src/solver/gpu/ranks.rs) remain for the steps that need the particles on the host.

use super::buffers::{storage, GHOST_BIT};
use super::readback::read_ranges;
use super::schedule::{PlainRecorder, Recorder};
use super::shaders::{stage_with_aliases, Stage, WORKGROUP_SIZE};
use super::GpuSolver;
use crate::solver::cpu::resident_exchange::{OwnHealth, SlabFaces};

/// The words of `exchange_words` (`EXCHANGE_*` in wgsl/sim/resident_exchange.wgsl).
pub mod words {
    pub const AXIS: usize = 0;
    pub const SLAB_START: usize = 1;
    pub const SLAB_END: usize = 2;
    pub const HALO: usize = 3;
    pub const NEIGHBOURS: usize = 4;
    pub const DROPPED: usize = 5;
    pub const BAND: usize = 6;
    pub const INSERTS: usize = 7;
    pub const HELD: usize = 8;
    pub const NON_FINITE: usize = 9;
    pub const ESCAPED: usize = 10;
    pub const MAX_SPEED2: usize = 11;
    pub const MAX_DENSITY: usize = 12;
    pub const PLACES: usize = 13;
    /// Words in the buffer.
    pub const COUNT: usize = 16;
}

/// The band a step's exchange reads back: the dropped slots (unsorted), and the band's
/// entries as the device wrote them (unsorted), three vectors each: the position and the
/// velocity (w included), then the slot, the place in the one-process order (cell, and place
/// in the cell of the last binning) and, with DFSPH, the divergence solve's warm start (the
/// position's w holds the id, the velocity's w the constant-density warm start).
pub struct DeviceBand {
    pub dropped: Vec<u32>,
    pub entries: Vec<[[f32; 4]; 3]>,
}

impl DeviceBand {
    /// The slot of entry `k`.
    pub fn slot(&self, k: usize) -> u32 {
        self.entries[k][2][0].to_bits()
    }
    /// The place of entry `k` in the one-process order.
    pub fn key(&self, k: usize) -> u64 {
        let key = self.entries[k][2].map(f32::to_bits);
        (key[1] as u64) << 32 | key[2] as u64
    }
}

/// DFSPH across ranks: the arrays indexed by each particle's place in the upload (the w of its
/// position), which the merge writes again at the particles' new slots.
pub struct PlaceArrays<'a> {
    pub ids: &'a wgpu::Buffer,
    pub warm_pressure: &'a wgpu::Buffer,
    pub warm_divergence: &'a wgpu::Buffer,
}

/// The stages and arrays of the resident exchange, made for a solver's capacity, with room for
/// `list_capacity` band and received particles each (a step whose band or received particles
/// outgrow it takes the full path, and the rank makes the room larger).
pub struct ResidentExchange {
    select_band: Stage,
    place_inserts: Stage,
    merge_kept: Stage,
    own_health: Stage,
    count_layers: Stage,
    /// Per phase of the state: the bind groups of the five entry points, in that order.
    groups: Vec<[wgpu::BindGroup; 5]>,
    words: wgpu::Buffer,
    /// `count_layers`' counts, room for the layers along any axis.
    layer_counts: wgpu::Buffer,
    dropped: wgpu::Buffer,
    band: wgpu::Buffer,
    inserts: wgpu::Buffer,
    merged_positions: wgpu::Buffer,
    merged_velocities: wgpu::Buffer,
    /// DFSPH: the merged ids and warm starts, and where they go.
    places: Option<(wgpu::Buffer, [wgpu::Buffer; 3])>,
    /// Held particles the arrays hold (the solver's capacity).
    capacity: u64,
    /// Band and received particles each.
    list_capacity: u64,
    /// The last band's dropped slots and particles (how much the next read takes at once).
    last_sizes: std::cell::Cell<(u64, u64)>,
    /// Bytes the last band's reads took.
    bytes_read: std::cell::Cell<u64>,
}

impl ResidentExchange {
    /// The stages for `solver`'s capacity, with room for `list_capacity` band and received
    /// particles; with DFSPH the arrays its positions' places index (`places`).
    pub fn new(solver: &GpuSolver, list_capacity: u64, place_arrays: Option<PlaceArrays<'_>>) -> anyhow::Result<Self> {
        let ctx = &solver.ctx;
        let capacity = solver.store.capacity();
        let list_capacity = list_capacity.clamp(64, capacity.max(64));
        let cells = solver.params.grid.cell_count() as u64 + 1;
        // Room for the layers along any axis.
        let layers = solver.params.grid.dims.into_iter().max().unwrap_or(1) as u64;
        let with_densities = solver.densities.is_some();
        let with_places = place_arrays.is_some();
        let lens = move |name: &str| match name {
            "starts" => cells,
            "exchange_words" => words::COUNT as u64,
            "layer_counts" => layers,
            "band" | "inserts" => 3 * list_capacity,
            "insert_places" => list_capacity,
            "densities" if !with_densities => 0,
            "place_ids" | "warm_pressure" | "warm_divergence" if !with_places => 0,
            "merged_places" => if with_places { 3 * capacity } else { 0 },
            _ => capacity,
        };
        // Ghosts are marked in the w of their positions (always so across ranks, where this
        // runs; one GPU's stage tests mark some themselves).
        let mut constants: Vec<(&'static str, f64)> = solver.constants_sized(WORKGROUP_SIZE).into_iter().filter(|c| c.0 != "GHOSTS").collect();
        constants.push(("GHOSTS", 1.0));
        constants.push(("DFSPH_PLACES", with_places as u32 as f64));
        constants.push(("DENSITY_ARRAY", with_densities as u32 as f64));
        let stage = |entry: &str| stage_with_aliases(ctx, "resident_exchange", entry, &lens, &constants, &[]);
        let [select_band, place_inserts, merge_kept, own_health, count_layers] = ["select_band", "place_inserts", "merge_kept", "own_health", "count_layers"].map(stage);
        let (select_band, place_inserts, merge_kept, own_health, count_layers) = (select_band?, place_inserts?, merge_kept?, own_health?, count_layers?);
        let device = &ctx.device;
        let words = storage(device, "exchange words", words::COUNT as u64 * 4);
        let layer_counts = storage(device, "layer counts", layers * 4);
        let dropped = storage(device, "dropped slots", capacity * 4);
        let band = storage(device, "band", 3 * list_capacity * 16);
        let inserts = storage(device, "received particles", 3 * list_capacity * 16);
        let places = storage(device, "received particles' places", list_capacity * 4);
        let merged_positions = storage(device, "merged positions", capacity * 16);
        let merged_velocities = storage(device, "merged velocities", capacity * 16);
        let place_arrays = place_arrays.map(|p| (storage(device, "merged places", 3 * capacity * 4), [p.warm_pressure.clone(), p.warm_divergence.clone(), p.ids.clone()]));
        let groups = (0..solver.store.phases())
            .map(|c| {
                let state = solver.store.state(c);
                let buffers = |name: &str| match name {
                    "positions" => state.positions.clone(),
                    "velocities" => state.velocities.clone(),
                    "densities" => solver.densities.clone().expect("bound only where the step keeps densities"),
                    "starts" => solver.starts.clone(),
                    "exchange_words" => words.clone(),
                    "layer_counts" => layer_counts.clone(),
                    "dropped" => dropped.clone(),
                    "band" => band.clone(),
                    "inserts" => inserts.clone(),
                    "insert_places" => places.clone(),
                    "merged_positions" => merged_positions.clone(),
                    "merged_velocities" => merged_velocities.clone(),
                    "merged_places" | "warm_pressure" | "warm_divergence" | "place_ids" => {
                        let (merged, [pressure, divergence, ids]) = place_arrays.as_ref().expect("bound only with DFSPH");
                        match name {
                            "merged_places" => merged.clone(),
                            "warm_pressure" => pressure.clone(),
                            "warm_divergence" => divergence.clone(),
                            _ => ids.clone(),
                        }
                    }
                    other => panic!("no buffer holds the array '{other}'"),
                };
                [&select_band, &place_inserts, &merge_kept, &own_health, &count_layers].map(|s| s.bind_group(device, "resident exchange", &solver.uniform, &buffers))
            })
            .collect();
        Ok(ResidentExchange { select_band, place_inserts, merge_kept, own_health, count_layers, groups, words, layer_counts, dropped, band, inserts, merged_positions, merged_velocities, places: place_arrays, capacity, list_capacity, last_sizes: Default::default(), bytes_read: Default::default() })
    }

    /// Band and received particles the arrays have room for.
    pub fn list_capacity(&self) -> u64 {
        self.list_capacity
    }

    /// Bytes the last band's reads took (the counts, and the lists as far as they were read).
    pub fn band_bytes_read(&self) -> u64 {
        self.bytes_read.get()
    }

    /// Whether the band carries DFSPH's places and warm starts.
    pub fn carries_places(&self) -> bool {
        self.places.is_some()
    }

    /// Lists the dropped slots and reads back the band of the state the last step left
    /// (`faces`: the rank's slab), or `Err` with the band's size where it outgrows its array.
    pub fn band(&self, solver: &GpuSolver, faces: &SlabFaces) -> anyhow::Result<Result<DeviceBand, u64>> {
        let ctx = &solver.ctx;
        let mut control = [0u32; words::COUNT];
        control[words::AXIS] = faces.axis as u32;
        control[words::SLAB_START] = faces.slab.start;
        control[words::SLAB_END] = faces.slab.end;
        control[words::HALO] = faces.halo;
        control[words::NEIGHBOURS] = faces.lower as u32 | (faces.upper as u32) << 1;
        ctx.queue.write_buffer(&self.words, 0, bytemuck::cast_slice(&control));
        let mut rec = PlainRecorder::new(&ctx.device, "band");
        solver.dispatch_particles(&mut rec, &self.select_band, &self.groups[solver.current][0]);
        ctx.queue.submit([rec.finish()]);
        // The counts and, in the same wait, as much of the lists as the last step's sizes and a
        // quarter more; the rest, where they grew past that, in a second wait.
        let (last_dropped, last_band) = self.last_sizes.get();
        let guess = |last: u64, room: u64| (last + last / 4 + 64).min(room);
        let (guess_dropped, guess_band) = (guess(last_dropped, self.capacity), guess(last_band, self.list_capacity));
        let mut data = read_ranges(ctx, &[(&self.words, 0, words::COUNT as u64 * 4), (&self.dropped, 0, guess_dropped * 4), (&self.band, 0, guess_band * 48)])?;
        let counts: Vec<u32> = bytemuck::pod_collect_to_vec(&data[0]);
        let (dropped, band) = (counts[words::DROPPED] as u64, counts[words::BAND] as u64);
        self.last_sizes.set((dropped, band));
        self.bytes_read.set(words::COUNT as u64 * 4 + guess_dropped * 4 + guess_band * 48);
        if band > self.list_capacity {
            return Ok(Err(band));
        }
        let rest: Vec<(&wgpu::Buffer, u64, u64)> = [(&self.dropped, guess_dropped * 4, dropped * 4), (&self.band, guess_band * 48, band * 48)]
            .into_iter()
            .filter(|r| r.2 > r.1)
            .map(|(b, from, to)| (b, from, to - from))
            .collect();
        if !rest.is_empty() {
            let more = read_ranges(ctx, &rest)?;
            self.bytes_read.set(self.bytes_read.get() + rest.iter().map(|r| r.2).sum::<u64>());
            let mut more = more.into_iter();
            for (k, (from, to)) in [(guess_dropped * 4, dropped * 4), (guess_band * 48, band * 48)].into_iter().enumerate() {
                if to > from {
                    data[k + 1].extend(more.next().expect("read"));
                }
            }
        }
        data[1].truncate(dropped as usize * 4);
        data[2].truncate(band as usize * 48);
        let dropped: Vec<u32> = bytemuck::pod_collect_to_vec(&data[1]);
        let entries: Vec<[[f32; 4]; 3]> = bytemuck::pod_collect_to_vec(&data[2]);
        Ok(Ok(DeviceBand { dropped, entries }))
    }

    /// The held particles written again without the `dropped` slots (sorted) and with the
    /// received particles (positions and velocities, w included, sorted by their places in the
    /// one-process order `keys`; with DFSPH the id in the position's w, the constant-density
    /// warm start in the velocity's w and the divergence one in `warm_divergence`), in that
    /// order; the solver then holds them. False, and nothing changed, where they do not fit the
    /// arrays.
    pub fn merge(&self, solver: &mut GpuSolver, dropped: &[u32], positions: &[[f32; 4]], velocities: &[[f32; 4]], keys: &[u64], warm_divergence: &[f32]) -> bool {
        let held = solver.fluid_count as u64;
        let merged = held - dropped.len() as u64 + positions.len() as u64;
        if merged > self.capacity || positions.len() as u64 > self.list_capacity || merged == 0 {
            return false;
        }
        let ctx = solver.ctx.clone();
        let mut control = [0u32; words::COUNT];
        control[words::DROPPED] = dropped.len() as u32;
        control[words::INSERTS] = positions.len() as u32;
        control[words::HELD] = held as u32;
        control[words::PLACES] = self.capacity as u32;
        ctx.queue.write_buffer(&self.words, 0, bytemuck::cast_slice(&control));
        if !dropped.is_empty() {
            ctx.queue.write_buffer(&self.dropped, 0, bytemuck::cast_slice(dropped));
        }
        if !positions.is_empty() {
            let mut vectors = Vec::with_capacity(3 * positions.len());
            for k in 0..positions.len() {
                let divergence = warm_divergence.get(k).map_or(0, |w| w.to_bits());
                let key = [(keys[k] >> 32) as u32, keys[k] as u32, divergence, 0].map(f32::from_bits);
                vectors.extend([positions[k], velocities[k], key]);
            }
            ctx.queue.write_buffer(&self.inserts, 0, bytemuck::cast_slice(&vectors));
        }
        let groups = &self.groups[solver.current];
        let mut rec = PlainRecorder::new(&ctx.device, "merge");
        solver.dispatch_threads(&mut rec, &self.place_inserts, &groups[1], positions.len() as u64);
        solver.dispatch_threads(&mut rec, &self.merge_kept, &groups[2], held);
        let state = solver.store.state(solver.current);
        rec.copy(&self.merged_positions, &state.positions, merged * 16);
        rec.copy(&self.merged_velocities, &state.velocities, merged * 16);
        if let Some((from, to)) = &self.places {
            // Each part of the merged places to its array: the new slots are the next places.
            for (k, array) in to.iter().enumerate() {
                rec.copy_range(from, k as u64 * self.capacity * 4, array, 0, merged * 4);
            }
        }
        ctx.queue.submit([rec.finish()]);
        solver.set_held_count(merged as u32);
        true
    }

    /// The own particles' health after the step just run, read back in one wait with the
    /// first `status_words` status words.
    pub fn own_health(&self, solver: &GpuSolver, status_words: u64) -> anyhow::Result<(OwnHealth, Vec<u32>)> {
        let ctx = &solver.ctx;
        ctx.queue.write_buffer(&self.words, 0, bytemuck::cast_slice(&[0u32; words::COUNT]));
        let mut rec = PlainRecorder::new(&ctx.device, "own health");
        solver.dispatch_particles(&mut rec, &self.own_health, &self.groups[solver.current][3]);
        ctx.queue.submit([rec.finish()]);
        let data = read_ranges(ctx, &[(&self.words, 0, words::COUNT as u64 * 4), (&solver.status, 0, status_words.max(1) * 4)])?;
        let w: Vec<u32> = bytemuck::pod_collect_to_vec(&data[0]);
        let health = OwnHealth {
            non_finite: w[words::NON_FINITE],
            escaped: w[words::ESCAPED],
            max_speed2: f32::from_bits(w[words::MAX_SPEED2]),
            max_density: f32::from_bits(w[words::MAX_DENSITY]),
        };
        Ok((health, bytemuck::pod_collect_to_vec(&data[1])))
    }

    /// The own particles (ghosts left out) per cell layer along `axis` of the state the last
    /// step left, for moving the slab bounds without reading the particles back.
    pub fn layer_counts(&self, solver: &GpuSolver, axis: usize) -> anyhow::Result<Vec<u32>> {
        let ctx = &solver.ctx;
        let layers = solver.params.grid.dims[axis] as u64;
        let mut control = [0u32; words::COUNT];
        control[words::AXIS] = axis as u32;
        ctx.queue.write_buffer(&self.words, 0, bytemuck::cast_slice(&control));
        ctx.queue.write_buffer(&self.layer_counts, 0, bytemuck::cast_slice(&vec![0u32; layers as usize]));
        let mut rec = PlainRecorder::new(&ctx.device, "layer counts");
        solver.dispatch_particles(&mut rec, &self.count_layers, &self.groups[solver.current][4]);
        ctx.queue.submit([rec.finish()]);
        let data = read_ranges(ctx, &[(&self.layer_counts, 0, layers * 4)])?;
        Ok(bytemuck::pod_collect_to_vec(&data[0]))
    }
}

impl GpuSolver {
    /// Binds the stages to `n` held particles (every stage reads the count from the uniform
    /// block).
    pub(super) fn set_held_count(&mut self, n: u32) {
        if n != self.fluid_count {
            self.fluid_count = n;
            let p = super::params::GpuParams::new(&self.params, n, self.wall_count, self.uniform_viscosity);
            self.ctx.queue.write_buffer(&self.uniform, 0, &p.bytes());
        }
    }
}

/// The w of a received particle's position: its id, with [`GHOST_BIT`] for a ghost.
pub fn received_w(id: u32, ghost: bool) -> f32 {
    f32::from_bits(id | if ghost { GHOST_BIT } else { 0 })
}

/// What [`GpuSolver::resident_exchange_alone`] gives back.
pub struct ResidentExchangeRun {
    /// The state before, in slot order (w included), and the cell starts of its binning.
    pub positions: Vec<[f32; 4]>,
    pub velocities: Vec<[f32; 4]>,
    pub starts: Vec<u32>,
    /// The band as the device listed it.
    pub band: DeviceBand,
    /// The held particles after the merge, in slot order.
    pub merged_positions: Vec<[f32; 4]>,
    pub merged_velocities: Vec<[f32; 4]>,
    /// `own_health` of the state before (with its densities where the step keeps them).
    pub health: OwnHealth,
    pub densities: Option<Vec<f32>>,
    /// `count_layers` of the state before along the slab axis.
    pub layer_counts: Vec<u32>,
    /// DFSPH: each place's id and warm starts (constant density, divergence) before, and after
    /// the merge by new slot.
    pub places: Option<[Vec<[u32; 3]>; 2]>,
}

/// A received particle for [`GpuSolver::resident_exchange_alone`]: position and velocity (w
/// included), place in the one-process order, and with DFSPH its divergence warm start.
pub type Received = ([f32; 4], [f32; 4], u64, f32);

impl GpuSolver {
    /// The resident exchange's stage alone on the current state (for the stage tests): the
    /// slots `ghosts` marked as ghosts, the band of `faces` listed, the own particles' health
    /// and their layers counted, then the held particles merged without the dropped slots and
    /// with `received` (sorted by place). The solver holds the merged particles afterwards. With DFSPH the
    /// positions' w (one GPU's ids) serve as places, whose ids are `place_ids`.
    pub fn resident_exchange_alone(&mut self, faces: &SlabFaces, ghosts: &[u32], received: &[Received], place_ids: Option<&[u32]>) -> anyhow::Result<ResidentExchangeRun> {
        let n = self.fluid_count as u64;
        let state = self.store.state(self.current);
        let cells = self.params.grid.cell_count() as u64 + 1;
        let data = read_ranges(&self.ctx, &[(&state.positions, 0, n * 16), (&state.velocities, 0, n * 16), (&self.starts, 0, cells * 4)])?;
        let mut positions: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&data[0]);
        let velocities: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&data[1]);
        let starts: Vec<u32> = bytemuck::pod_collect_to_vec(&data[2]);
        for &slot in ghosts {
            let p = &mut positions[slot as usize];
            p[3] = f32::from_bits(p[3].to_bits() | GHOST_BIT);
        }
        self.ctx.queue.write_buffer(&state.positions, 0, bytemuck::cast_slice(&positions));
        let densities = match &self.densities {
            Some(d) => Some(bytemuck::pod_collect_to_vec(&read_ranges(&self.ctx, &[(d, 0, n * 4)])?.remove(0))),
            None => None,
        };
        let capacity = self.store.capacity();
        let ids_buffer = place_ids.map(|ids| {
            let buffer = storage(&self.ctx.device, "place ids", capacity * 4);
            self.ctx.queue.write_buffer(&buffer, 0, bytemuck::cast_slice(ids));
            buffer
        });
        // The places' ids and warm starts, as (warm pressure, warm divergence, id) bits.
        let read_places = |solver: &GpuSolver, count: u64| -> anyhow::Result<Option<Vec<[u32; 3]>>> {
            let (Some(ids), Some(d)) = (&ids_buffer, &solver.dfsph) else { return Ok(None) };
            let b = &d.buffers;
            let data = read_ranges(&solver.ctx, &[(&b.warm_pressure, 0, count * 4), (&b.warm_divergence, 0, count * 4), (ids, 0, count * 4)])?;
            let words: Vec<Vec<u32>> = data.iter().map(|d| bytemuck::pod_collect_to_vec(d)).collect();
            Ok(Some((0..count as usize).map(|k| [words[0][k], words[1][k], words[2][k]]).collect()))
        };
        let before = read_places(self, n)?;
        let places = match (&ids_buffer, &self.dfsph) {
            (Some(ids), Some(d)) => Some(PlaceArrays { ids, warm_pressure: &d.buffers.warm_pressure, warm_divergence: &d.buffers.warm_divergence }),
            _ => None,
        };
        let stage = ResidentExchange::new(self, n.max(received.len() as u64), places)?;
        let (health, _) = stage.own_health(self, 1)?;
        let layer_counts = stage.layer_counts(self, faces.axis)?;
        let band = stage.band(self, faces)?.map_err(|size| anyhow::anyhow!("the band of {size} particles outgrows its array"))?;
        let mut dropped = band.dropped.clone();
        dropped.sort_unstable();
        let p: Vec<[f32; 4]> = received.iter().map(|r| r.0).collect();
        let v: Vec<[f32; 4]> = received.iter().map(|r| r.1).collect();
        let keys: Vec<u64> = received.iter().map(|r| r.2).collect();
        let warm: Vec<f32> = received.iter().map(|r| r.3).collect();
        anyhow::ensure!(stage.merge(self, &dropped, &p, &v, &keys, &warm), "the merge does not fit the arrays");
        let m = self.fluid_count as u64;
        let state = self.store.state(self.current);
        let data = read_ranges(&self.ctx, &[(&state.positions, 0, m * 16), (&state.velocities, 0, m * 16)])?;
        let after = read_places(self, m)?;
        Ok(ResidentExchangeRun {
            positions,
            velocities,
            starts,
            band,
            merged_positions: bytemuck::pod_collect_to_vec(&data[0]),
            merged_velocities: bytemuck::pod_collect_to_vec(&data[1]),
            health,
            densities,
            layer_counts,
            places: before.zip(after).map(|(b, a)| [b, a]),
        })
    }
}
