//! DFSPH's solves across ranks on the GPU (docs/scale-out.md). A Jacobi step changes every
//! velocity from the neighbours' stiffnesses, and the outer layer of ghosts lacks the neighbours
//! beyond it, so after every velocity change the ghosts must take their owners' velocities, and
//! each check must see the error of every rank's own particles. One GPU decides both on the
//! device (`dfsph_convergence.wgsl`); across ranks the host runs the loop instead: the
//! velocities the rank sends are gathered on the device and read back, exchanged through the
//! rank's [`GhostLink`](crate::solver::cpu::exchange::GhostLink), and those received written
//! and scattered onto the ghosts (`ghost_velocities.wgsl`), the link's lists made from the
//! device's binning (`ghost_link.wgsl`); the error sum of the own particles (the shaders leave
//! the ghosts out) is read back, added over the ranks and checked with the CPU's twin of the
//! GPU's check. Every rank then runs the iterations one GPU runs, on the same numbers.
//!
//! The recorder of the profile cannot wait, so a profile never takes this path.

use super::dfsph::{GhostLinkCells, GhostVelocities, SolvePasses};
use super::params::status;
use super::readback::read_ranges;
use super::schedule::Recorder;
use super::solver::GpuSolver;
use crate::model::real::V3;
use crate::solver::cpu::dfsph_convergence::{begin_solve, check_convergence, SolveLimits};
use crate::solver::cpu::dfsph_shared::error_threshold;
use crate::solver::cpu::ghost_link::{link_cells, link_slots};
use crate::solver::cpu::resident_exchange::SlabFaces;

impl GpuSolver {
    /// Whether the DFSPH step under way runs its solves across ranks.
    pub(super) fn solves_across_ranks(&self) -> bool {
        self.rank_solves.borrow().as_ref().is_some_and(|r| r.link.is_some())
    }

    /// Keeps the first failure of the solves across ranks (the rank reads it after the step).
    fn solves_failed(&self, e: anyhow::Error) {
        if let Some(r) = self.rank_solves.borrow_mut().as_mut() {
            r.failure.get_or_insert(format!("{e:#}"));
        }
    }

    /// Counts `bytes` moved between host and device by the solves' loops (the rank's
    /// `bus_bytes`).
    fn count_bus_bytes(&self, bytes: u64) {
        if let Some(r) = self.rank_solves.borrow_mut().as_mut() {
            r.bus_bytes += bytes;
        }
    }

    /// The work recorded so far submitted and waited for, then `bytes` of `buffer` from `offset`
    /// read back.
    fn wait_and_read(&self, rec: &mut dyn Recorder, buffer: &wgpu::Buffer, offset: u64, bytes: u64) -> anyhow::Result<Vec<u8>> {
        // One submission and one wait for the work and the read (nothing read where `bytes` is 0).
        let ranges: &[(&wgpu::Buffer, u64, u64)] = if bytes == 0 { &[] } else { &[(buffer, offset, bytes)] };
        let mut data = rec.submit_and_read(&self.ctx, ranges).ok_or_else(|| anyhow::anyhow!("DFSPH across ranks cannot run in timed passes"))??;
        self.count_bus_bytes(bytes);
        Ok(data.pop().unwrap_or_default())
    }

    /// After the binning: the ghost link's lists in the device's cell order, made from the
    /// binning itself without reading the particles back. The link lists the particles of the
    /// cell layers next to the slab's faces (the own ones within the ghost layers, the ghosts
    /// beyond), which are whole cells of the binning: the host lists those cells
    /// (`link_cells`), the device reads where each lies in the cell starts
    /// (`wgsl/sim/ghost_link.wgsl`), and the host joins the runs and checks their counts
    /// against the exchange's. Both sides of a face bin their shared particles from the same
    /// order with the same stable sort, so their lists stay in step.
    pub(super) fn link_in_device_order(&self, rec: &mut dyn Recorder) {
        if !self.solves_across_ranks() {
            return;
        }
        let Some(faces) = self.rank_solves.borrow().as_ref().and_then(|r| r.faces.clone()) else {
            self.solves_failed(anyhow::anyhow!("the solves across ranks were given no slab"));
            return;
        };
        let listed = self.ghost_link_cells_stage(&faces).and_then(|stage| {
            let mut listed = stage.listed.borrow_mut();
            if listed.as_ref().is_none_or(|(written, _)| *written != faces) {
                // The slab is new or its bounds moved: its cells, written once for the steps
                // until they move again.
                let lists = link_cells(self.params.grid.dims, &faces);
                self.count_bus_bytes(stage.write_cells(&self.ctx.queue, &lists)?);
                *listed = Some((faces.clone(), lists));
            }
            let lists = listed.as_ref().expect("written above").1.clone();
            let cells = lists.iter().map(|l| l.len()).sum::<usize>() as u64;
            if cells == 0 {
                return Ok((lists, Vec::new()));
            }
            self.dispatch_threads(rec, &stage.stage, &stage.group, cells);
            let data = self.wait_and_read(rec, &stage.bounds, 0, 8 * cells)?;
            Ok((lists, bytemuck::pod_collect_to_vec::<u8, [u32; 2]>(&data)))
        });
        let made = listed.and_then(|(lists, bounds)| {
            let mut solves = self.rank_solves.borrow_mut();
            let Some(link) = solves.as_mut().and_then(|r| r.link.as_mut()) else { return Ok(0) };
            *link = link.with_lists(link_slots(&lists, &bounds)).map_err(|e| anyhow::anyhow!(e))?;
            // The slots of the gather and the scatter, for every sync of the step.
            let [sent, received] = link.counts();
            let words: Vec<u32> = [sent, received].into_iter().chain(link.sent_slots()).chain(link.received_slots()).map(|v| v as u32).collect();
            let ghosts = self.ghost_velocities_stage()?;
            self.ctx.queue.write_buffer(&ghosts.slots, 0, bytemuck::cast_slice(&words));
            Ok(4 * words.len() as u64)
        });
        let made = made.map(|written| self.count_bus_bytes(written));
        if let Err(e) = made {
            self.solves_failed(e);
        }
    }

    /// The stage that reads the link's cells' bounds, made on first use with room for every
    /// cell of four times `faces`' ghost layers across any axis of the grid (the most the link
    /// can list).
    fn ghost_link_cells_stage(&self, faces: &SlabFaces) -> anyhow::Result<&GhostLinkCells> {
        if let Some(made) = self.ghost_link_cells.get() {
            return Ok(made);
        }
        let cells = self.params.grid.cell_count() as u64;
        let per_layer = cells / self.params.grid.dims.iter().copied().min().unwrap_or(1).max(1) as u64;
        let capacity = (4 * faces.halo as u64 * per_layer).max(1);
        let made = GhostLinkCells::new(&self.ctx, capacity, cells, &self.constants_sized(super::shaders::WORKGROUP_SIZE), &self.starts, &self.uniform)?;
        Ok(self.ghost_link_cells.get_or_init(|| made))
    }

    /// The gather and scatter of the ghosts' velocities, made on first use for the solver's
    /// capacity.
    fn ghost_velocities_stage(&self) -> anyhow::Result<&GhostVelocities> {
        if let Some(made) = self.ghost_velocities.get() {
            return Ok(made);
        }
        let made = GhostVelocities::new(&self.ctx, self.store.capacity(), &self.constants_sized(super::shaders::WORKGROUP_SIZE), &self.store, &self.uniform)?;
        Ok(self.ghost_velocities.get_or_init(|| made))
    }

    /// Where the step asks for them (force probes sampled on the host), the velocities the
    /// prediction starts from, read back after the divergence solve.
    pub(super) fn keep_prediction_start(&self, rec: &mut dyn Recorder, read: usize) {
        if !self.rank_solves.borrow().as_ref().is_some_and(|r| r.wants_prediction_start) {
            return;
        }
        let velocities = self.store.state(read).velocities;
        match self.wait_and_read(rec, &velocities, 0, self.fluid_count as u64 * 16) {
            Ok(data) => {
                if let Some(r) = self.rank_solves.borrow_mut().as_mut() {
                    r.prediction_start = Some(bytemuck::pod_collect_to_vec(&data));
                }
            }
            Err(e) => self.solves_failed(e),
        }
    }

    /// The ghosts' velocities in `buffer` replaced by their owners' (one message per
    /// neighbour): the sent ones gathered on the device and read back, the received ones
    /// written and scattered onto the ghosts (`ghost_velocities.wgsl`), so that only the face
    /// layers cross the bus. Every rank takes part in the messages even where its read failed,
    /// so that none waits.
    pub(super) fn sync_ghost_velocities(&self, rec: &mut dyn Recorder, read: usize, predicted: bool) {
        let Some([sent, received]) = self.rank_solves.borrow().as_ref().and_then(|r| r.link.as_ref()).map(|l| l.counts()) else { return };
        let gathered = self.ghost_velocities_stage().and_then(|g| {
            if sent > 0 {
                self.dispatch_threads(rec, &g.gather, &g.groups[read][predicted as usize][0], sent as u64);
            }
            let data = self.wait_and_read(rec, &g.values, 0, sent as u64 * 16)?;
            Ok(bytemuck::pod_collect_to_vec::<u8, [f32; 4]>(&data).iter().map(|v| V3([v[0], v[1], v[2]])).collect::<Vec<V3<f32>>>())
        });
        let mut solves = self.rank_solves.borrow_mut();
        let Some(r) = solves.as_mut() else { return };
        let Some(link) = r.link.as_mut() else { return };
        let (values, ok) = match gathered {
            Ok(v) => (v, true),
            Err(e) => {
                r.failure.get_or_insert(format!("{e:#}"));
                (vec![V3([0.0; 3]); sent], false)
            }
        };
        let values = link.exchange_gathered(&values);
        drop(solves);
        if let (true, true, Some(g)) = (ok, received > 0, self.ghost_velocities.get()) {
            let words: Vec<[f32; 4]> = values.iter().map(|v| [v.0[0], v.0[1], v.0[2], 0.0]).collect();
            self.ctx.queue.write_buffer(&g.values, 0, bytemuck::cast_slice(&words));
            self.count_bus_bytes(16 * words.len() as u64);
            self.dispatch_threads(rec, &g.scatter, &g.groups[read][predicted as usize][1], received as u64);
        }
    }

    /// The error sum of the rate pass just recorded, this rank's own particles', added over the
    /// ranks (the largest sum where a read failed: the solve then runs to its limit, and the
    /// failure stops the run).
    fn error_sum_across_ranks(&self, rec: &mut dyn Recorder) -> u64 {
        let words = self.wait_and_read(rec, &self.status, status::DFSPH_ERROR_LO as u64 * 4, 8).map(|data| {
            let word = |k: usize| u32::from_le_bytes(data[4 * k..4 * k + 4].try_into().expect("4 bytes"));
            word(0) as u64 | (word(1) as u64) << 32
        });
        let mine = words.unwrap_or_else(|e| {
            self.solves_failed(e);
            u32::MAX as u64
        });
        let mut solves = self.rank_solves.borrow_mut();
        match solves.as_mut().and_then(|r| r.link.as_mut()) {
            Some(link) => link.sum_units(mine),
            None => mine,
        }
    }

    /// One DFSPH solve (0: divergence, 1: constant density) across ranks, on the state pair read
    /// from `read`: the warm start and its velocity change, then the first error and its check,
    /// then velocity changes, errors and checks until the check ends the solve (the order of
    /// `record_solve`, with the check on the host).
    pub(super) fn record_solve_across_ranks(&self, rec: &mut dyn Recorder, solve: usize, read: usize) {
        debug_assert_eq!(status::DFSPH_ERROR_HI, status::DFSPH_ERROR_LO + 1);
        let d = self.dfsph.as_ref().expect("a DFSPH scene");
        let s = &d.settings;
        let SolvePasses { warm: (warm, gw), rate: (rate, gr), apply: (apply, ga) } = d.solve_passes(solve, read);
        // The velocities the solve changes: the state's own (divergence) or the predicted ones.
        let predicted = solve == 1;
        let (min_iterations, max_iterations, tolerance) = match solve {
            0 => (s.min_divergence_iterations, s.max_divergence_iterations, s.divergence_error),
            _ => (s.min_iterations, s.max_iterations, s.density_error),
        };
        let particles = self.rank_solves.borrow().as_ref().map_or(self.fluid_count as usize, |r| r.particles);
        let limits = SolveLimits { min_iterations, max_iterations, threshold: error_threshold(tolerance, particles), particles };
        if s.warm_start {
            self.dispatch_particles(rec, warm, gw);
            self.dispatch_particles(rec, apply, ga);
            self.sync_ghost_velocities(rec, read, predicted);
        }
        let mut state = begin_solve(s.warm_start);
        loop {
            rec.clear(&self.status, status::DFSPH_ERROR_LO as u64 * 4, Some(8));
            self.dispatch_particles(rec, rate, gr);
            let error = self.error_sum_across_ranks(rec);
            match self.rank_solves.borrow_mut().as_mut() {
                Some(r) => {
                    let stats = if solve == 0 { &mut r.stats.divergence } else { &mut r.stats.pressure };
                    check_convergence(&limits, &mut state, error, stats);
                }
                None => state.solving = false,
            }
            if !state.solving {
                break;
            }
            self.dispatch_particles(rec, apply, ga);
            self.sync_ghost_velocities(rec, read, predicted);
        }
    }
}

impl GpuSolver {
    /// The ghost velocities stage alone on the current state's velocities (for the stage
    /// tests): the velocities of the slots `sent` gathered, then `values` scattered onto the
    /// slots `received`. Returns the velocities before, the gathered ones, and the velocities
    /// after, in slot order (w included).
    #[allow(clippy::type_complexity)]
    pub fn ghost_velocities_alone(&mut self, sent: &[u32], received: &[u32], values: &[[f32; 3]]) -> anyhow::Result<(Vec<[f32; 4]>, Vec<[f32; 4]>, Vec<[f32; 4]>)> {
        let n = self.fluid_count as u64;
        anyhow::ensure!(values.len() == received.len() && sent.len() as u64 <= 2 * n && received.len() as u64 <= n, "the slots and values do not fit the stage");
        let velocities = self.store.state(self.current).velocities;
        let g = self.ghost_velocities_stage()?;
        let words: Vec<u32> = [sent.len() as u32, received.len() as u32].into_iter().chain(sent.iter().copied()).chain(received.iter().copied()).collect();
        self.ctx.queue.write_buffer(&g.slots, 0, bytemuck::cast_slice(&words));
        let read = |buffer: &wgpu::Buffer, bytes: u64| -> anyhow::Result<Vec<[f32; 4]>> { Ok(bytemuck::pod_collect_to_vec(&read_ranges(&self.ctx, &[(buffer, 0, bytes.max(16))])?.remove(0))) };
        let before = read(&velocities, n * 16)?;
        let mut rec = super::schedule::PlainRecorder::new(&self.ctx.device, "ghost velocities");
        let groups = &g.groups[self.current][0];
        self.dispatch_threads(&mut rec, &g.gather, &groups[0], sent.len() as u64);
        self.ctx.queue.submit([rec.finish()]);
        let gathered = read(&g.values, sent.len() as u64 * 16)?;
        let words: Vec<[f32; 4]> = values.iter().map(|v| [v[0], v[1], v[2], 0.0]).collect();
        self.ctx.queue.write_buffer(&g.values, 0, bytemuck::cast_slice(&words));
        let mut rec = super::schedule::PlainRecorder::new(&self.ctx.device, "ghost velocities");
        self.dispatch_threads(&mut rec, &g.scatter, &groups[1], received.len() as u64);
        self.ctx.queue.submit([rec.finish()]);
        let after = read(&velocities, n * 16)?;
        Ok((before[..n as usize].to_vec(), gathered[..sent.len()].to_vec(), after[..n as usize].to_vec()))
    }
}

impl GpuSolver {
    /// The ghost link stage alone on the current state's binning (for the stage tests): the
    /// cells of `faces`' link listed, and where each lies in the cell starts. Returns the
    /// positions in slot order (w included), the cell starts and the cells' bounds, in the order
    /// of `link_cells`' lists joined.
    #[allow(clippy::type_complexity)]
    pub fn ghost_link_alone(&self, faces: &SlabFaces) -> anyhow::Result<(Vec<[f32; 4]>, Vec<u32>, Vec<[u32; 2]>)> {
        let n = self.fluid_count as u64;
        let cells = self.params.grid.cell_count() as u64 + 1;
        let state = self.store.state(self.current);
        let data = read_ranges(&self.ctx, &[(&state.positions, 0, n * 16), (&self.starts, 0, cells * 4)])?;
        let lists = link_cells(self.params.grid.dims, faces);
        let listed = lists.iter().map(Vec::len).sum::<usize>();
        let stage = self.ghost_link_cells_stage(faces)?;
        stage.write_cells(&self.ctx.queue, &lists)?;
        *stage.listed.borrow_mut() = None;
        let mut rec = super::schedule::PlainRecorder::new(&self.ctx.device, "ghost link");
        self.dispatch_threads(&mut rec, &stage.stage, &stage.group, listed as u64);
        self.ctx.queue.submit([rec.finish()]);
        let bounds = read_ranges(&self.ctx, &[(&stage.bounds, 0, (8 * listed as u64).max(8))])?.remove(0);
        let bounds: Vec<[u32; 2]> = bytemuck::pod_collect_to_vec(&bounds);
        Ok((bytemuck::pod_collect_to_vec(&data[0]), bytemuck::pod_collect_to_vec(&data[1]), bounds[..listed].to_vec()))
    }
}
