//! What the ranks read together: snapshots, step fields, states and rank reports gathered in
//! the one-process order (or streamed in pieces), a state restored onto any rank count, the
//! collectives of a step's health and maxima, and the probes sampled across ranks. See
//! docs/scale-out.md.

use super::exchange::RankPart;
use super::probes::{self, ProbeInput};
use super::CpuSolver;
use crate::model::probes::{Probe, ProbeGeometry};
use crate::model::real::{Real, V3};
use crate::model::state::{BackendState, Snapshot, StepFields};
use crate::solver::backend::{StateArray, StatePiece, StateSource};
use crate::solver::communicator::{all_max, all_sum, Communicator};
use crate::solver::decomposition::{RankReport, RankStats, Slabs};
use std::ops::Range;
use std::time::Instant;

impl<R: Real> CpuSolver<R> {
    /// Every probe's values read from `input` by the ranks together ([`probes_across_ranks`]),
    /// and the error of a failed collective.
    pub(super) fn probes_on_ranks(&self, input: &ProbeInput<R>) -> (Vec<f64>, Option<String>) {
        let part = self.ranks.as_deref().expect("across ranks");
        let p = &self.params.probes;
        probes_across_ranks(input, part, &self.own_slots(), &p.probes, &p.offsets())
    }

    /// The own slots with their places in the one-process order.
    fn own_order(&self) -> Vec<(usize, u64)> {
        let part = self.ranks.as_ref().expect("only across ranks");
        if let Some(first) = &part.first_order {
            return first.iter().enumerate().map(|(slot, &o)| (slot, o)).collect();
        }
        let mut out = Vec::new();
        for cell in self.own_cells(part).into_iter().flatten() {
            let (a, b) = (self.starts[cell] as usize, self.starts[cell + 1] as usize);
            out.extend((a..b).map(|slot| (slot, ((cell as u64) << 32) | (slot - a) as u64)));
        }
        out
    }

    /// Across ranks: every rank's rows `f(slot)` of its own particles, each after its place in
    /// the one-process order (two words), in rank order, on rank 0 (`None` on the others).
    fn gather_own(&mut self, width: usize, row: impl Fn(&Self, usize) -> Vec<f64>) -> anyhow::Result<Option<Vec<f64>>> {
        let own = self.own_order();
        let mut mine = Vec::with_capacity((width + 2) * own.len());
        for (slot, order) in own {
            mine.push((order >> 32) as f64);
            mine.push((order & 0xffff_ffff) as f64);
            mine.extend(row(self, slot));
        }
        let comm = self.ranks.as_ref().expect("only across ranks").comm.clone();
        let t0 = Instant::now();
        let all = comm.gather(&mine)?;
        if let Some(part) = &mut self.ranks {
            part.stats.exchange_seconds += t0.elapsed().as_secs_f64();
        }
        Ok(all.map(|parts| parts.concat()))
    }

    /// [`CpuSolver::snapshot`] across ranks: each rank bins its particles with fresh ghosts
    /// and evaluates density; the rows are gathered on rank 0, which writes the files (the
    /// other ranks get a snapshot of no particle, at the same step and time).
    pub(super) fn snapshot_across_ranks(&mut self) -> anyhow::Result<Snapshot> {
        self.snapshot_fields_across_ranks()?;
        let rows = self.gather_own(9, Self::snapshot_row)?;
        let Some(rows) = rows else { return Ok(Snapshot::with_len(0, self.step, self.time())) };
        let n = self.ranks.as_ref().map_or(0, |p| p.total_fluid);
        let mut s = Snapshot::with_len(n, self.step, self.time());
        for r in rows.chunks_exact(11).map(|r| &r[2..]) {
            let id = r[0] as usize;
            s.positions[id] = [r[1], r[2], r[3]];
            s.velocities[id] = [r[4], r[5], r[6]];
            s.densities[id] = r[7];
            s.pressures[id] = r[8];
        }
        Ok(s)
    }

    /// A snapshot's row of the particle in `slot`: its id, then `x y z vx vy vz density pressure`.
    fn snapshot_row(&self, slot: usize) -> Vec<f64> {
        let (x, v) = (self.positions[slot].to64(), self.velocities[slot].to64());
        vec![self.ids[slot] as f64, x[0], x[1], x[2], v[0], v[1], v[2], self.densities[slot].to64(), self.pressures[slot].to64()]
    }

    /// [`crate::solver::Backend::snapshot_piece`]: the fields of a snapshot as for
    /// [`CpuSolver::snapshot`], then every own particle's row to the rank whose block of ids
    /// holds it (one all-to-all), which puts its rows in id order.
    pub(super) fn snapshot_piece_across_ranks(&mut self) -> anyhow::Result<crate::solver::backend::SnapshotPiece> {
        self.snapshot_fields_across_ranks()?;
        let part = self.ranks.as_ref().expect("only across ranks");
        let (comm, total) = (part.comm.clone(), part.total_fluid as u64);
        let size = comm.size();
        let blocks: Vec<Range<u64>> = (0..size).map(|r| crate::solver::backend::id_block(total, size, r)).collect();
        let mut parts = vec![Vec::new(); size];
        for (slot, _) in self.own_order() {
            let id = self.ids[slot] as u64;
            let owner = blocks.partition_point(|b| b.end <= id);
            parts[owner].extend(self.snapshot_row(slot));
        }
        let t0 = Instant::now();
        let received = comm.all_to_all(&parts);
        if let Some(part) = &mut self.ranks {
            part.stats.exchange_seconds += t0.elapsed().as_secs_f64();
        }
        let mine = blocks[comm.rank()].clone();
        let mut rows = vec![[f64::NAN; 8]; (mine.end - mine.start) as usize];
        let mut filled = 0;
        for r in received?.iter().flat_map(|p| p.chunks_exact(9)) {
            let id = r[0] as u64;
            anyhow::ensure!(mine.contains(&id), "rank {} of {size} received the snapshot row of particle {id}, outside its block {mine:?}", comm.rank());
            rows[(id - mine.start) as usize].copy_from_slice(&r[1..]);
            filled += 1;
        }
        anyhow::ensure!(filled == rows.len(), "rank {} of {size} received {filled} snapshot rows for its block of {} particles", comm.rank(), rows.len());
        Ok(crate::solver::backend::SnapshotPiece { step: self.step, time: self.time(), total, first: mine.start, rows, comm })
    }

    /// A snapshot's fields on every rank: the exchange with fresh ghosts, the binning and the
    /// density (and the pressure of the last solve, for DFSPH).
    fn snapshot_fields_across_ranks(&mut self) -> anyhow::Result<()> {
        self.take_back_held();
        self.exchange(false);
        if self.rank_failure().is_none() && self.device.is_some() {
            self.fields_on_device();
        } else {
            // Each particle's warm start (DFSPH's last pressure) is its owner's.
            self.snapshot_fields();
        }
        if let Some(e) = self.rank_failure() {
            anyhow::bail!("{e}");
        }
        Ok(())
    }

    /// [`CpuSolver::step_fields`] across ranks, gathered on rank 0 (empty on the others).
    pub(super) fn step_fields_across_ranks(&mut self) -> anyhow::Result<StepFields> {
        self.take_back_held();
        let rows = self.gather_own(6, |s, i| {
            let a = s.accelerations[i].to64();
            vec![s.ids[i] as f64, s.densities[i].to64(), s.pressures[i].to64(), a[0], a[1], a[2]]
        })?;
        let n = if rows.is_some() { self.ranks.as_ref().map_or(0, |p| p.total_fluid) } else { 0 };
        let rows = rows.unwrap_or_default();
        let mut out = StepFields { densities: vec![0.0; n], pressures: vec![0.0; n], accelerations: vec![[0.0; 3]; n] };
        for r in rows.chunks_exact(8).map(|r| &r[2..]) {
            let id = r[0] as usize;
            out.densities[id] = r[1];
            out.pressures[id] = r[2];
            out.accelerations[id] = [r[3], r[4], r[5]];
        }
        Ok(out)
    }

    /// Every rank's [`RankReport`], in rank order (collective).
    pub(super) fn gather_rank_reports(&mut self) -> anyhow::Result<Option<Vec<RankReport>>> {
        let Some(mine) = self.rank_report() else { return Ok(None) };
        let comm = self.ranks.as_ref().expect("across ranks").comm.clone();
        let s = &mine.stats;
        let all = comm.all_gather(&[mine.own_particles as f64, s.exchange_seconds, s.migrated as f64, s.ghosts as f64, mine.node_rank as f64, mine.node_ranks as f64, mine.threads as f64, mine.walls as f64, s.resident_steps as f64, s.bus_bytes as f64, s.device_seconds])?;
        // The adapters' names travel as bytes, padded to the longest.
        let longest = all_max(comm.as_ref(), &[mine.adapter.len() as f64])?[0] as usize;
        let mut name: Vec<f64> = mine.adapter.bytes().map(f64::from).collect();
        name.resize(longest, 0.0);
        let names: Vec<String> = comm.all_gather(&name)?.iter().map(|b| String::from_utf8_lossy(&b.iter().take_while(|&&c| c != 0.0).map(|&c| c as u8).collect::<Vec<u8>>()).into_owned()).collect();
        Ok(Some(
            all.iter()
                .enumerate()
                .map(|(rank, r)| RankReport {
                    rank,
                    own_particles: r[0] as usize,
                    walls: r[7] as usize,
                    node_rank: r[4] as usize,
                    node_ranks: r[5] as usize,
                    threads: r[6] as usize,
                    adapter: names[rank].clone(),
                    stats: RankStats { exchange_seconds: r[1], migrated: r[2] as u64, ghosts: r[3] as usize, resident_steps: r[8] as u64, bus_bytes: r[9] as u64, device_seconds: r[10], ..s.clone() },
                    ..mine.clone()
                })
                .collect(),
        ))
    }

    /// [`CpuSolver::save_state`] across ranks (collective): the state one process would save,
    /// its arrays streamed to rank 0 as a checkpoint streams them, in one piece each; the other
    /// ranks' holds the step, time and health, and no particle.
    pub(super) fn save_state_across_ranks(&mut self) -> anyhow::Result<BackendState> {
        let mut state = self.state_header_across_ranks();
        for array in [StateArray::Positions, StateArray::Velocities, StateArray::Ids, StateArray::WarmStart, StateArray::Densities] {
            self.visit_state_array_across_ranks(array, u64::MAX, &mut |piece| {
                match piece {
                    StatePiece::Vectors(v) if array == StateArray::Positions => state.positions = v.to_vec(),
                    StatePiece::Vectors(v) => state.velocities = v.to_vec(),
                    StatePiece::Ids(v) => state.ids = v.to_vec(),
                    StatePiece::Pairs(v) => state.warm_start = v.to_vec(),
                    StatePiece::Scalars(v) => state.densities = v.to_vec(),
                }
                Ok(())
            })?;
        }
        Ok(state)
    }

    /// [`crate::solver::Backend::save_state_header`] across ranks: this rank's step, time,
    /// health and dt, which every rank shares (no particle is gathered).
    pub(super) fn state_header_across_ranks(&self) -> BackendState {
        crate::solver::backend::state_header(self.save_state())
    }

    /// Each own slot's place in the one-process order of the saved state: its index in the
    /// initial or restored state before the first binning; after it, the particles of the
    /// cells before its cell (the ranks' cell runs and their counts, all-gathered) plus its
    /// place in the cell. Sorted by place.
    fn places_in_one_process_order(&self) -> anyhow::Result<Vec<(usize, u64)>> {
        let part = self.ranks.as_ref().expect("only across ranks");
        if let Some(first) = &part.first_order {
            let mut places: Vec<(usize, u64)> = first.iter().enumerate().map(|(slot, &o)| (slot, o)).collect();
            places.sort_unstable_by_key(|p| p.1);
            return Ok(places);
        }
        let runs = self.own_cells(part);
        let mine: Vec<f64> = runs.iter().flat_map(|r| [r.start as f64, (self.starts[r.end] - self.starts[r.start]) as f64]).collect();
        let mut all: Vec<(u64, u64)> = part.comm.all_gather(&mine)?.iter().flat_map(|r| r.chunks_exact(2).map(|c| (c[0] as u64, c[1] as u64)).collect::<Vec<_>>()).collect();
        all.sort_unstable();
        // The particles before each run's first cell.
        let mut before = std::collections::HashMap::with_capacity(runs.len());
        let mut running = 0u64;
        for (cell, count) in all {
            before.insert(cell, running);
            running += count;
        }
        let mut places = Vec::with_capacity(self.positions.len());
        for run in runs {
            let (first, offset) = (self.starts[run.start] as usize, before[&(run.start as u64)]);
            places.extend((first..self.starts[run.end] as usize).map(|slot| (slot, offset + (slot - first) as u64)));
        }
        places.sort_unstable_by_key(|p| p.1);
        Ok(places)
    }

    /// [`crate::solver::Backend::visit_state_array`] across ranks (collective): for each piece
    /// of `chunk` places of the saved state's order (by id for DFSPH's warm starts), every rank
    /// sends its own particles' values there to rank 0, which hands the piece to `visit`; the
    /// other ranks visit nothing. No rank holds more than its own particles and one piece.
    pub(super) fn visit_state_array_across_ranks(&mut self, array: StateArray, chunk: u64, visit: &mut dyn FnMut(StatePiece) -> anyhow::Result<()>) -> anyhow::Result<()> {
        self.take_back_held();
        let total = crate::solver::backend::Backend::state_array_len(self, array) as u64;
        let mut places = self.places_in_one_process_order()?;
        if array == StateArray::WarmStart {
            places = places.iter().map(|&(slot, _)| (slot, self.ids[slot] as u64)).collect();
            places.sort_unstable_by_key(|p| p.1);
        }
        let width = match array {
            StateArray::Positions | StateArray::Velocities => 3,
            StateArray::WarmStart => 2,
            StateArray::Ids | StateArray::Densities => 1,
        };
        let value = |slot: usize| -> Vec<f64> {
            match array {
                StateArray::Positions => self.positions[slot].to64().to_vec(),
                StateArray::Velocities => self.velocities[slot].to64().to_vec(),
                StateArray::Ids => vec![self.ids[slot] as f64],
                StateArray::Densities => vec![self.carried_densities[slot].to64()],
                StateArray::WarmStart => {
                    let (d, k) = (self.dfsph.as_ref().expect("DFSPH's array"), self.warm_keys[slot] as usize);
                    vec![d.warm_pressure[k].to64(), d.warm_divergence[k].to64()]
                }
            }
        };
        let comm = self.ranks.as_ref().expect("only across ranks").comm.clone();
        let chunk = chunk.max(1);
        let mut next = 0;
        let mut start = 0u64;
        while start < total {
            let end = start.saturating_add(chunk).min(total);
            let mut mine = Vec::new();
            while next < places.len() && places[next].1 < end {
                mine.push((places[next].1 - start) as f64);
                mine.extend(value(places[next].0));
                next += 1;
            }
            let t0 = Instant::now();
            let gathered = comm.gather(&mine)?;
            if let Some(part) = &mut self.ranks {
                part.stats.exchange_seconds += t0.elapsed().as_secs_f64();
            }
            if let Some(parts) = gathered {
                let n = (end - start) as usize;
                let mut values = vec![f64::NAN; n * width];
                let mut filled = 0;
                for row in parts.iter().flat_map(|p| p.chunks_exact(width + 1)) {
                    let at = row[0] as usize;
                    anyhow::ensure!(at < n, "a rank sent place {} of a piece of {n}", at);
                    values[at * width..(at + 1) * width].copy_from_slice(&row[1..]);
                    filled += 1;
                }
                anyhow::ensure!(filled == n, "the ranks sent {filled} of the {n} values of places {start}..{end} of the saved state's {array:?}");
                match array {
                    StateArray::Positions | StateArray::Velocities => visit(StatePiece::Vectors(&values.chunks_exact(3).map(|v| [v[0], v[1], v[2]]).collect::<Vec<_>>()))?,
                    StateArray::WarmStart => visit(StatePiece::Pairs(&values.chunks_exact(2).map(|v| [v[0], v[1]]).collect::<Vec<_>>()))?,
                    StateArray::Ids => visit(StatePiece::Ids(&values.iter().map(|&v| v as u32).collect::<Vec<_>>()))?,
                    StateArray::Densities => visit(StatePiece::Scalars(&values))?,
                }
            }
            start = end;
        }
        Ok(())
    }

    /// [`CpuSolver::restore_state`] across ranks (any rank count saved it), each rank reading
    /// its part of `source`: the positions counted per cell layer cut slabs of equal counts,
    /// and this rank takes the particles of its slab, in the state's order, and the walls
    /// near it.
    pub(super) fn restore_state_across_ranks(&mut self, source: &mut dyn StateSource) -> anyhow::Result<()> {
        // The device's particles are replaced with the rest: the next step uploads them.
        self.forget_device_state();
        let part = self.ranks.as_ref().expect("only across ranks");
        let grid = self.grid;
        let axis = part.axis;
        let layer_of = |p: [f64; 3]| grid.layer(V3::<R>::from64(p), axis);
        let mut counts = vec![0u64; grid.dims[axis] as usize];
        let mut total = 0usize;
        source.visit_positions(&mut |p| {
            counts[layer_of(p) as usize] += 1;
            total += 1;
        })?;
        anyhow::ensure!(total == part.total_fluid, "the state holds {total} particles; the scene has {}", part.total_fluid);
        let slabs = Slabs::balanced(&counts, part.comm.size(), part.slabs.halo)?;
        let mine = slabs.layers_of(part.comm.rank());
        let (local, chosen) = source.read_kept(&mut |_, p| mine.contains(&layer_of(p)))?;
        let kind = self.saved_kind();
        anyhow::ensure!(local.kind == kind, "the state was saved by the {} backend, not {kind}", local.kind);
        anyhow::ensure!(local.velocities.len() == chosen.len() && local.ids.len() == chosen.len(), "the state's arrays differ in length");
        anyhow::ensure!(local.ids.iter().all(|&id| (id as usize) < total), "the state's particle ids are not a permutation");
        let state = &local;
        let n = chosen.len();
        self.positions = local.positions.iter().map(|&p| V3::from64(p)).collect();
        self.velocities = local.velocities.iter().map(|&v| V3::from64(v)).collect();
        self.ids = local.ids.clone();
        anyhow::ensure!(
            local.densities.is_empty() == !self.params.continuity_density,
            "the state holds {} carried densities for {} particles; the scene's density method needs {}",
            local.densities.len(),
            chosen.len(),
            if self.params.continuity_density { "one per particle" } else { "none" }
        );
        self.carried_densities = local.densities.iter().map(|&d| R::of(d)).collect();
        for v in [&mut self.densities, &mut self.pressures] {
            v.resize(n, R::zero());
        }
        self.accelerations.resize(n, V3::zero());
        self.keys.resize(n, 0);
        self.sorted.resize(n, 0);
        self.step = state.step;
        self.probe_samples.clear();
        self.health = state.health();
        self.time = state.time;
        let [min, max, last] = state.dt_min_max_last;
        self.dt_stats = crate::model::state::DtStats { min, max, last, ..Default::default() };
        if let Some(d) = &mut self.dfsph {
            // The held particles' (the part read holds them in its particles' order).
            anyhow::ensure!(state.warm_start.len() == n, "the state holds {} warm-start stiffnesses for DFSPH for this rank's {n} particles", state.warm_start.len());
            d.warm_pressure = state.warm_start.iter().map(|w| R::of(w[0])).collect();
            d.warm_divergence = state.warm_start.iter().map(|w| R::of(w[1])).collect();
            self.warm_keys = (0..n as u32).collect();
            d.stats = state.iterations;
            d.last_dt = if state.step > 0 { last } else { 0.0 };
            d.resize(n);
        }
        let part = self.ranks.as_mut().expect("only across ranks");
        part.slabs = slabs;
        part.first_order = Some(chosen);
        part.failure = None;
        // The walls near the slab cut for the state.
        let walls = self.walls_near_slab();
        self.install_walls(&walls);
        Ok(())
    }

    /// Across ranks: the step's maxima (largest speed, acceleration) over every rank; alone
    /// they are returned as they are.
    pub(super) fn all_max(&mut self, values: &[f64]) -> Vec<f64> {
        let Some(part) = &mut self.ranks else { return values.to_vec() };
        let t0 = Instant::now();
        let out = match crate::solver::communicator::all_max(&*part.comm, values) {
            Ok(v) => v,
            Err(e) => {
                part.failure.get_or_insert(format!("{e:#}"));
                // NaN makes the step count as bad on this rank, which then stops.
                vec![f64::NAN; values.len()]
            }
        };
        part.stats.exchange_seconds += t0.elapsed().as_secs_f64();
        out
    }

    /// Across ranks: the step's health found on every rank (counts added, speeds and the
    /// largest density the largest); alone returned as it is.
    pub(super) fn all_step_health(&mut self, found: super::integrate::StepHealth, max_density: f64) -> (super::integrate::StepHealth, f64) {
        let Some(part) = &mut self.ranks else { return (found, max_density) };
        let t0 = Instant::now();
        let reduced = part.comm.all_gather(&[found.non_finite as f64, found.escaped as f64, found.max_speed, max_density]);
        part.stats.exchange_seconds += t0.elapsed().as_secs_f64();
        match reduced {
            Ok(all) => {
                let mut out = super::integrate::StepHealth::default();
                let mut density = 0.0f64;
                for r in &all {
                    out = out.add(super::integrate::StepHealth { non_finite: r[0] as u32, escaped: r[1] as u32, max_speed: r[2] });
                    density = density.max(r[3]);
                }
                (out, density)
            }
            Err(e) => {
                part.failure.get_or_insert(format!("{e:#}"));
                (super::integrate::StepHealth { non_finite: 1, ..found }, max_density)
            }
        }
    }
}

/// The probes' sample across ranks, the same on every rank: each point probe and each level of
/// a gauge evaluated by the rank whose slab holds it (its neighbourhood is whole there: the
/// rank's own particles and two ghost layers), the force probes and fronts over each rank's own
/// particles (`own`, not its ghosts); then added over the ranks in rank order (the values of
/// points and gauge levels come from one rank and zeros, so they are the one-process run's bits;
/// force sums are added in another grouping) and the fronts' farthest taken over the ranks that
/// saw fluid in their band. Returns the values and the error of a failed collective.
pub(super) fn probes_across_ranks<R: Real>(input: &ProbeInput<R>, part: &RankPart, own: &[Range<usize>], list: &[Probe], offsets: &[usize]) -> (Vec<f64>, Option<String>) {
    let rank = part.comm.rank();
    let evaluates = |x: V3<R>| part.slabs.owner(input.grid.layer(x, part.axis)) == rank;
    let count = offsets.last().zip(list.last()).map_or(0, |(&at, p)| at + p.geometry.columns().len());
    let mut local = vec![R::zero(); count];
    // Forces and fronts over the own particles.
    let mut counted = vec![false; input.fluid.positions.len()];
    for slots in own {
        counted[slots.clone()].fill(true);
    }
    let mut partials = Vec::new();
    probes::probe_particles(input, list, Some(&counted), &mut partials);
    probes::probe_finish(list, offsets, &partials, &mut local);
    // The point probes of this slab.
    let (mine, mine_at): (Vec<Probe>, Vec<usize>) = list
        .iter()
        .zip(offsets)
        .filter(|(p, _)| matches!(p.geometry, ProbeGeometry::Point { position } if evaluates(V3::from64(position))))
        .map(|(p, &at)| (p.clone(), at))
        .unzip();
    probes::probe_points(input, &mine, &mine_at, &mut local);
    // Every column, then each gauge's level fractions (this slab's levels).
    let mut sums: Vec<f64> = local.iter().map(|v| v.to64()).collect();
    for probe in list {
        if let ProbeGeometry::Gauge { x, z, bottom, top, step } = probe.geometry {
            let f = probes::gauge_fractions(input, R::of(x), R::of(z), R::of(bottom), R::of(top), R::of(step), evaluates);
            sums.extend(f.iter().map(|v| v.to64()));
        }
    }
    let (mut values, fractions) = match add_probes_over_ranks(&*part.comm, list, offsets, sums) {
        Ok(added) => added,
        Err(e) => return (vec![f64::NAN; count], Some(e)),
    };
    let mut level = 0;
    for (probe, &at) in list.iter().zip(offsets) {
        if let ProbeGeometry::Gauge { bottom, top, step, .. } = probe.geometry {
            let (bottom, top, step) = (R::of(bottom), R::of(top), R::of(step));
            let levels = probes::gauge_levels(bottom, top, step).len();
            let fractions = &fractions[level..level + levels];
            let surface = probes::surface_from_fractions(bottom, top, step, |k, _| R::of(fractions[k]));
            values[at] = surface.to64();
            values[at + 1] = (surface - bottom).to64();
            level += levels;
        }
    }
    (values, None)
}

/// The probes' sample across ranks from each rank's device (wgsl/sim/probes.wgsl on the held
/// particles, the ghosts left out of the forces and fronts): `device` holds every column as
/// the device computed it; a point's and a gauge's values are kept by the rank that
/// `evaluates` them (whose neighbourhood of them is whole, so they are the one-process run's
/// bits) and zeroed elsewhere, then the ranks add them up as [`probes_across_ranks`] does.
///
/// `failed` says that this rank's device gave no row (`device` then holds zeros): the ranks add
/// that flag with the values, so each of them learns of it in the same collective and returns
/// an error instead of a sample that lacks the failed rank's part.
pub(super) fn device_probes_across_ranks(comm: &dyn Communicator, list: &[Probe], offsets: &[usize], mut device: Vec<f64>, failed: bool, evaluates: impl Fn([f64; 3]) -> bool) -> (Vec<f64>, Option<String>) {
    let count = device.len();
    for (probe, &at) in list.iter().zip(offsets) {
        let point = match probe.geometry {
            ProbeGeometry::Point { position } => position,
            // The gauge's line lies in one cell layer of the slab axis (probes_on_device).
            ProbeGeometry::Gauge { x, z, bottom, .. } => [x, bottom, z],
            _ => continue,
        };
        if !evaluates(point) {
            device[at..at + probe.geometry.columns().len()].fill(0.0);
        }
    }
    device.push(if failed { 1.0 } else { 0.0 });
    match add_probes_over_ranks(comm, list, offsets, device) {
        Ok((values, failed_ranks)) if failed_ranks[0] == 0.0 => (values, None),
        Ok((values, failed_ranks)) => {
            let n = failed_ranks[0];
            (values, Some(format!("{n} rank(s) of {} sampled no probe row of this step on their device; the step's sample is left out", comm.size())))
        }
        Err(e) => (vec![f64::NAN; count], Some(e)),
    }
}

/// The ranks' probe sums added up (collective): `sums` holds every column of this rank
/// (a front's farthest and count from its own particles), then any further sums to add; each
/// front's farthest is taken over the ranks that saw fluid in its band. Returns the columns and
/// the further sums.
fn add_probes_over_ranks(comm: &dyn Communicator, list: &[Probe], offsets: &[usize], mut sums: Vec<f64>) -> Result<(Vec<f64>, Vec<f64>), String> {
    let count = offsets.last().zip(list.last()).map_or(0, |(&at, p)| at + p.geometry.columns().len());
    let mut farthest = Vec::new();
    for (probe, &at) in list.iter().zip(offsets) {
        if let ProbeGeometry::Front { .. } = probe.geometry {
            farthest.push(if sums[at + 1] > 0.0 { sums[at] } else { f64::NEG_INFINITY });
            sums[at] = 0.0;
        }
    }
    let (mut sums, farthest) = all_sum(comm, &sums).and_then(|s| Ok((s, all_max(comm, &farthest)?))).map_err(|e| format!("{e:#}"))?;
    let further = sums.split_off(count);
    let mut front = 0;
    for (probe, &at) in list.iter().zip(offsets) {
        if let ProbeGeometry::Front { .. } = probe.geometry {
            sums[at] = if sums[at + 1] > 0.0 { farthest[front] } else { 0.0 };
            front += 1;
        }
    }
    Ok((sums, further))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::probes::ProbeInterval;
    use crate::solver::communicator::LocalGroup;

    /// A device row of a point (read by rank 0) and a front (over both ranks), added over two
    /// ranks; then the same with rank 1's device failing: both ranks return its error and no
    /// sample, where they once returned NaN columns for the writer to write.
    #[test]
    fn a_rank_whose_device_gave_no_probe_row_fails_the_sample_on_every_rank() {
        let list = vec![
            Probe { name: "p".into(), interval: ProbeInterval::Steps(1), geometry: ProbeGeometry::Point { position: [0.1, 0.2, 0.3] } },
            Probe { name: "f".into(), interval: ProbeInterval::Steps(1), geometry: ProbeGeometry::Front { direction: [1.0, 0.0, 0.0], floor: 0.0, height: 0.1 } },
        ];
        let offsets = vec![0, 6];
        let rows = [vec![1.0, 2.0, 3.0, 4.0, 5.0, 0.5, 0.7, 10.0], vec![9.0, 9.0, 9.0, 9.0, 9.0, 9.0, 0.9, 5.0]];
        for failing in [None, Some(1)] {
            let results: Vec<(Vec<f64>, Option<String>)> = std::thread::scope(|s| {
                let handles: Vec<_> = LocalGroup::new(2)
                    .into_iter()
                    .map(|comm| {
                        let (list, offsets) = (&list, &offsets);
                        let rank = comm.rank();
                        let failed = failing == Some(rank);
                        let row = if failed { vec![0.0; 8] } else { rows[rank].clone() };
                        s.spawn(move || device_probes_across_ranks(&comm, list, offsets, row, failed, |_| rank == 0))
                    })
                    .collect();
                handles.into_iter().map(|h| h.join().unwrap()).collect()
            });
            for (rank, (values, error)) in results.iter().enumerate() {
                match failing {
                    None => {
                        assert!(error.is_none(), "rank {rank}: {error:?}");
                        assert_eq!(values, &vec![1.0, 2.0, 3.0, 4.0, 5.0, 0.5, 0.9, 15.0], "rank {rank}");
                    }
                    Some(_) => {
                        let e = error.as_deref().unwrap_or_else(|| panic!("rank {rank} took a sample that lacks rank 1's part: {values:?}"));
                        assert!(e.contains("1 rank(s) of 2 sampled no probe row"), "rank {rank}: {e}");
                        assert!(values.iter().all(|v| v.is_finite()), "rank {rank}: {values:?}");
                    }
                }
            }
        }
    }
}
