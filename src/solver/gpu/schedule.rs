//! THE order of the GPU's work: one function, `GpuSolver::schedule`, records a step (or the
//! fields of the current state) against a [`Recorder`]. The normal path records into as few
//! compute passes as possible ([`PlainRecorder`]); the profile records the very same order with
//! every stage in its own timed pass ([`TimedRecorder`]), so what is timed is what runs.

use super::shaders::{dispatch_size, Stage};
use super::solver::GpuSolver;
use super::readback::{read_buffers, read_ranges, read_staged, stage_ranges};
use super::buffers::storage;
use super::dfsph::{SharedBuffers, SolvePasses};
use super::workgroups::{SolverLoop, ADAPTIVE_BLOCK};
use super::params::status;

/// The stages of a step as the profile names them, in dispatch order. With the fused step the
/// forces and the integration are one pass, timed as `forces`; `integrate` then holds only the
/// step's one-thread bookkeeping.
pub const PROFILED_STAGES: [&str; 7] = ["bin_count", "prefix_sum", "bin_scatter", "reorder", "density", "forces", "integrate"];

/// The stages of a DFSPH step as the profile names them, in dispatch order: a solve is timed
/// whole (its warm start and the iterations its loop records: with the default loop, up to the
/// end of the block in which it converged); `dfsph_integrate` includes the step's bookkeeping.
pub const DFSPH_PROFILED_STAGES: [&str; 9] =
    ["bin_count", "prefix_sum", "bin_scatter", "reorder", "dfsph_factors", "divergence_solve", "dfsph_predict", "pressure_solve", "dfsph_integrate"];

/// Every profiled stage of both methods: the weakly compressible step's seven, then DFSPH's
/// own five, then the surface normals (a row of their own before the forces, in a weakly
/// compressible scene with surface tension; DFSPH times them with its prediction).
pub const ALL_PROFILED_STAGES: usize = 13;

/// The rows of a profile whose forces and integration are one pass: the fused pass is timed as
/// `forces_integrate`, and what remains of the integration pass (one thread updating the step's
/// status words) as `bookkeeping`.
pub const FUSED_STAGE_NAMES: [&str; 7] = ["bin_count", "prefix_sum", "bin_scatter", "reorder", "density", "forces_integrate", "bookkeeping"];

/// A profiled stage: an index into the timestamps (the first seven those of
/// [`PROFILED_STAGES`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProfiledStage {
    BinCount = 0,
    PrefixSum = 1,
    BinScatter = 2,
    Reorder = 3,
    Density = 4,
    Forces = 5,
    Integrate = 6,
    DfsphFactors = 7,
    DivergenceSolve = 8,
    DfsphPredict = 9,
    PressureSolve = 10,
    DfsphIntegrate = 11,
    SurfaceNormals = 12,
}

impl ProfiledStage {
    /// The weakly compressible step's stages, in the order of [`PROFILED_STAGES`].
    pub const WCSPH: [ProfiledStage; 7] = [
        ProfiledStage::BinCount,
        ProfiledStage::PrefixSum,
        ProfiledStage::BinScatter,
        ProfiledStage::Reorder,
        ProfiledStage::Density,
        ProfiledStage::Forces,
        ProfiledStage::Integrate,
    ];

    /// The stage's row name in a profile; `fused`: the forces and the integration ran as one
    /// pass ([`FUSED_STAGE_NAMES`]).
    pub fn name(self, fused: bool) -> &'static str {
        match self {
            ProfiledStage::DfsphFactors => "dfsph_factors",
            ProfiledStage::DivergenceSolve => "divergence_solve",
            ProfiledStage::DfsphPredict => "dfsph_predict",
            ProfiledStage::PressureSolve => "pressure_solve",
            ProfiledStage::DfsphIntegrate => "dfsph_integrate",
            ProfiledStage::SurfaceNormals => "surface_normals",
            // The shared first four and the weakly compressible step's own three.
            wcsph if fused => FUSED_STAGE_NAMES[wcsph as usize],
            wcsph => PROFILED_STAGES[wcsph as usize],
        }
    }

    /// The stages of a DFSPH step, in the order of [`DFSPH_PROFILED_STAGES`].
    pub const DFSPH: [ProfiledStage; 9] = [
        ProfiledStage::BinCount,
        ProfiledStage::PrefixSum,
        ProfiledStage::BinScatter,
        ProfiledStage::Reorder,
        ProfiledStage::DfsphFactors,
        ProfiledStage::DivergenceSolve,
        ProfiledStage::DfsphPredict,
        ProfiledStage::PressureSolve,
        ProfiledStage::DfsphIntegrate,
    ];
}

/// What one recording holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Work {
    /// A whole step: the binning when due, density, forces, integration and bookkeeping.
    Step,
    /// The binning (always: a sorted state stays as it is) and the density and pressure of
    /// the current state, without advancing time (before a snapshot).
    Fields,
}

/// Where the schedule's commands go.
pub trait Recorder {
    /// Marks the start of a profiled stage (the timed recorder opens its timed pass here).
    fn begin(&mut self, stage: ProfiledStage);
    /// The compute pass to record dispatches into, opened when none is.
    fn pass(&mut self) -> &mut wgpu::ComputePass<'static>;
    /// Clears a range of a buffer (outside any pass).
    fn clear(&mut self, buffer: &wgpu::Buffer, offset: u64, size: Option<u64>);
    /// Copies the first `bytes` bytes of `from` into `to` (outside any pass).
    fn copy(&mut self, from: &wgpu::Buffer, to: &wgpu::Buffer, bytes: u64);
    /// Submits what is recorded and waits for it, so that the host can read a result back
    /// before recording more (the DFSPH loop with readbacks). `false` where the recorder cannot.
    fn submit_and_wait(&mut self, ctx: &super::device::GpuContext) -> bool;
    /// Submits what is recorded, waits for it and reads byte ranges `(buffer, offset, bytes)`
    /// back (the DFSPH loop's words across ranks, a solve's end); `None` where the recorder
    /// cannot wait. Here as `submit_and_wait` and a read after it: two submissions and waits.
    fn submit_and_read(&mut self, ctx: &super::device::GpuContext, ranges: &[(&wgpu::Buffer, u64, u64)]) -> Option<anyhow::Result<Vec<Vec<u8>>>> {
        self.submit_and_wait(ctx).then(|| read_ranges(ctx, ranges))
    }
}

/// Records into as few compute passes as the clears allow.
pub struct PlainRecorder {
    encoder: wgpu::CommandEncoder,
    pass: Option<wgpu::ComputePass<'static>>,
}

impl PlainRecorder {
    pub fn new(device: &wgpu::Device, label: &str) -> Self {
        PlainRecorder { encoder: device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) }), pass: None }
    }
    pub fn finish(mut self) -> wgpu::CommandBuffer {
        self.pass = None;
        self.encoder.finish()
    }
    /// Clears `bytes` bytes of `buffer` from `offset`.
    pub fn clear_range(&mut self, buffer: &wgpu::Buffer, offset: u64, bytes: u64) {
        self.clear(buffer, offset, Some(bytes));
    }
    /// Submits what is recorded and goes on recording into a new encoder.
    fn submit(&mut self, ctx: &super::device::GpuContext) {
        self.pass = None;
        let next = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("steps") });
        let done = std::mem::replace(&mut self.encoder, next);
        ctx.queue.submit([done.finish()]);
    }
    /// Copies `bytes` bytes of `from` at `from_offset` to `to` at `to_offset`.
    pub fn copy_range(&mut self, from: &wgpu::Buffer, from_offset: u64, to: &wgpu::Buffer, to_offset: u64, bytes: u64) {
        self.pass = None;
        self.encoder.copy_buffer_to_buffer(from, from_offset, to, to_offset, bytes);
    }
}

impl Recorder for PlainRecorder {
    fn begin(&mut self, _: ProfiledStage) {}
    fn pass(&mut self) -> &mut wgpu::ComputePass<'static> {
        let encoder = &mut self.encoder;
        self.pass.get_or_insert_with(|| encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("step"), timestamp_writes: None }).forget_lifetime())
    }
    fn clear(&mut self, buffer: &wgpu::Buffer, offset: u64, size: Option<u64>) {
        self.pass = None;
        self.encoder.clear_buffer(buffer, offset, size);
    }
    fn copy(&mut self, from: &wgpu::Buffer, to: &wgpu::Buffer, bytes: u64) {
        self.pass = None;
        self.encoder.copy_buffer_to_buffer(from, 0, to, 0, bytes);
    }
    fn submit_and_wait(&mut self, ctx: &super::device::GpuContext) -> bool {
        self.submit(ctx);
        let _ = ctx.device.poll(wgpu::PollType::Wait { submission_index: None, timeout: None });
        true
    }
    fn submit_and_read(&mut self, ctx: &super::device::GpuContext, ranges: &[(&wgpu::Buffer, u64, u64)]) -> Option<anyhow::Result<Vec<Vec<u8>>>> {
        // The copies behind the recorded work, in its submission: one wait for both (on a GPU
        // a submission and a wait cost tens of microseconds, paid here at every check of a
        // DFSPH solve).
        self.pass = None;
        let staged = stage_ranges(ctx, &mut self.encoder, ranges);
        self.submit(ctx);
        Some(read_staged(ctx, &staged, ranges))
    }
}

/// Records every profiled stage into its own compute pass with timestamps at its start (query
/// 2i) and end (2i + 1). Where `waits` allows, it submits and waits as the normal step does (a
/// DFSPH solve's loop asking whether to go on): the stage open then is timed in segments, the
/// ones before the last summed in `carried`.
pub struct TimedRecorder<'q> {
    encoder: wgpu::CommandEncoder,
    pass: Option<wgpu::ComputePass<'static>>,
    queries: &'q wgpu::QuerySet,
    /// Where the timestamps are resolved to (also between segments).
    resolved: &'q wgpu::Buffer,
    /// The stage whose timed pass was opened last.
    open: Option<usize>,
    /// Whether `submit_and_wait` may submit (not across ranks, whose exchanges between the
    /// submissions the profile does not time).
    waits: bool,
    /// Which stages were recorded.
    pub ran: [bool; ALL_PROFILED_STAGES],
    /// Ticks of each stage's segments before its last (a stage open at a submission).
    pub carried: [u64; ALL_PROFILED_STAGES],
}

impl<'q> TimedRecorder<'q> {
    pub fn new(device: &wgpu::Device, queries: &'q wgpu::QuerySet, resolved: &'q wgpu::Buffer, waits: bool) -> Self {
        let encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("profiled step") });
        TimedRecorder { encoder, pass: None, queries, resolved, open: None, waits, ran: [false; ALL_PROFILED_STAGES], carried: [0; ALL_PROFILED_STAGES] }
    }
    /// Opens the timed pass of stage `i` (its timestamps at queries 2i and 2i + 1).
    fn open_timed(&mut self, i: usize) {
        self.pass = None;
        self.open = Some(i);
        let writes = wgpu::ComputePassTimestampWrites {
            query_set: self.queries,
            beginning_of_pass_write_index: Some(2 * i as u32),
            end_of_pass_write_index: Some(2 * i as u32 + 1),
        };
        let pass = self.encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("profiled stage"), timestamp_writes: Some(writes) });
        self.pass = Some(pass.forget_lifetime());
    }
    /// Ends the open pass and resolves every timestamp into `resolved`.
    fn resolve(&mut self) {
        self.pass = None;
        self.encoder.resolve_query_set(self.queries, 0..2 * ALL_PROFILED_STAGES as u32, self.resolved, 0);
    }
    /// The command buffer, with the timestamps resolved.
    pub fn finish(mut self) -> wgpu::CommandBuffer {
        self.resolve();
        self.encoder.finish()
    }
}

impl Recorder for TimedRecorder<'_> {
    fn begin(&mut self, stage: ProfiledStage) {
        let i = stage as usize;
        self.ran[i] = true;
        self.open_timed(i);
    }
    fn pass(&mut self) -> &mut wgpu::ComputePass<'static> {
        let encoder = &mut self.encoder;
        self.pass.get_or_insert_with(|| encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("untimed"), timestamp_writes: None }).forget_lifetime())
    }
    fn clear(&mut self, buffer: &wgpu::Buffer, offset: u64, size: Option<u64>) {
        // The timed pass ends here; what follows is untimed until the next stage begins.
        self.pass = None;
        self.open = None;
        self.encoder.clear_buffer(buffer, offset, size);
    }
    fn copy(&mut self, from: &wgpu::Buffer, to: &wgpu::Buffer, bytes: u64) {
        // As a clear: untimed, between the timed passes.
        self.pass = None;
        self.open = None;
        self.encoder.copy_buffer_to_buffer(from, 0, to, 0, bytes);
    }
    fn submit_and_wait(&mut self, ctx: &super::device::GpuContext) -> bool {
        if !self.waits {
            return false;
        }
        self.resolve();
        let next = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("profiled step") });
        let done = std::mem::replace(&mut self.encoder, next);
        ctx.queue.submit([done.finish()]);
        // The segment of the open stage so far (reading waits for the submission); the rest of
        // the stage is timed from a new pass.
        let Ok(data) = read_buffers(ctx, &[(self.resolved, 2 * ALL_PROFILED_STAGES as u64 * 8)]) else { return false };
        let ticks: Vec<u64> = bytemuck::pod_collect_to_vec(&data[0]);
        if let Some(i) = self.open {
            self.carried[i] += ticks[2 * i + 1].saturating_sub(ticks[2 * i]);
            self.open_timed(i);
        }
        true
    }
}

impl GpuSolver {
    /// THE order of the GPU's work, recorded against `rec`: the binning of the current state
    /// into the other buffer of the pair (when due), the fields on it, and (for a step) the
    /// forces, the integration back into the first buffer and the bookkeeping.
    pub(super) fn schedule(&mut self, work: Work, rec: &mut dyn Recorder) {
        // The fields of the current state bin it (a sorted state stays as it is), but with a
        // skin only where a rebuild is due: a snapshot then leaves the run's order, and its bits,
        // as they were.
        let bins = match work {
            Work::Step => self.rebuilds(),
            Work::Fields => self.skin.is_none() || self.rebuilds(),
        };
        if bins {
            rec.clear(&self.starts, 0, None);
            let g = &self.groups[self.current];
            rec.begin(ProfiledStage::BinCount);
            self.dispatch_particles(rec, &self.pipelines.bin_count, &g.bin_count);
            rec.begin(ProfiledStage::PrefixSum);
            self.scan.record(rec.pass());
            rec.begin(ProfiledStage::BinScatter);
            self.dispatch_particles(rec, &self.pipelines.bin_scatter, &g.bin_scatter);
            rec.begin(ProfiledStage::Reorder);
            self.dispatch_particles(rec, &self.pipelines.reorder_rank, &g.reorder_rank);
            for gather in &g.reorder {
                self.dispatch_particles(rec, &self.pipelines.reorder, gather);
            }
            self.current = self.store.after_binning(self.current);
            // DFSPH across ranks: the ghosts of the solves follow the binning.
            self.link_in_device_order(rec);
            // With a skin: the positions the next rebuild is due from (the fields' rebuild is
            // the one the next step would have made, on the same positions).
            if let Some(skin) = &self.skin {
                rec.copy(&self.store.state(self.current).positions, &skin.rebuild_positions, self.fluid_count as u64 * 16);
                skin.rebuild_due.set(false);
                skin.rebuilds.set(skin.rebuilds.get() + 1);
            }
        }
        if self.dfsph.is_some() {
            self.schedule_dfsph(work, rec);
            return;
        }
        let read = self.current;
        // Field borrows, not a method's, so that the probes below can be borrowed mutably.
        let w = self.pipelines.wcsph.as_ref().expect("a weakly compressible scene");
        let g = self.groups[read].wcsph.as_ref().expect("a weakly compressible scene");
        // With a skin, between rebuilds: the density over the lists of the last rebuild.
        let (density, density_group) = match (&w.density_listed, &g.density_listed) {
            (Some(stage), Some(group)) if !bins => (stage, group),
            _ => (&w.density, &g.density),
        };
        if work == Work::Fields {
            rec.begin(ProfiledStage::Density);
            self.dispatch_particles(rec, density, density_group);
            if let (Some(stage), Some(group)) = (&w.wall_pressure, &g.wall_pressure) {
                self.dispatch_walls(rec, stage, group);
            }
            self.fields_state = read;
            self.accelerations_valid = false;
            return;
        }
        // This step's counts of bad particles start from zero.
        rec.clear(&self.status, status::NON_FINITE as u64 * 4, Some(8));
        if let Some(skin) = &self.skin {
            rec.clear(&skin.left, 0, None);
        }
        rec.begin(ProfiledStage::Density);
        self.dispatch_particles(rec, density, density_group);
        // With the Adami wall pressure, the wall particles' pressure from this step's fluid
        // fields (profiled with the density).
        if let (Some(stage), Some(group)) = (&w.wall_pressure, &g.wall_pressure) {
            self.dispatch_walls(rec, stage, group);
        }
        // The probes sample the state the step starts from, with its density stage's fields;
        // only in a scene with probes, only on the steps where one is due (profiled with the
        // density).
        if let Some(probes) = self.probes.as_mut() {
            if self.params.probes.samples_step(self.steps, self.params.dt, self.params.adaptive.is_some()) {
                probes.record(rec.pass(), read, self.steps);
            }
        }
        // With surface tension, the normals its curvature term reads.
        if let (Some(stage), Some(group)) = (&w.surface_normals, &g.surface_normals) {
            rec.begin(ProfiledStage::SurfaceNormals);
            self.dispatch_particles(rec, stage, group);
        }
        rec.begin(ProfiledStage::Forces);
        if self.pipelines.fused {
            self.dispatch_particles(rec, &w.advance, &g.advance);
        } else if let Some(forces) = &g.forces {
            self.dispatch_particles(rec, &w.forces, forces);
        }
        rec.begin(ProfiledStage::Integrate);
        if let Some((reduce, choose)) = &w.adaptive {
            self.dispatch_particles(rec, reduce, &g.advance);
            self.maxima_across_ranks(rec);
            dispatch_one(rec, choose, &g.advance);
        }
        if !self.pipelines.fused {
            self.dispatch_particles(rec, &w.advance, &g.advance);
        }
        dispatch_one(rec, &self.pipelines.finish_step, &self.finish_group);
        self.current = self.store.after_integration(read);
        // With a skin: how far the particles have moved since the rebuild (read by the host
        // after the step, see `read_skin_check`).
        if let Some(skin) = &self.skin {
            self.dispatch_particles(rec, &skin.check, &skin.groups[self.current]);
        }
        self.fields_state = read;
        self.accelerations_valid = !self.pipelines.fused;
    }

    /// Across ranks, between the adaptive step's reduction and its choice of dt: the work so
    /// far is submitted and waited for, this rank's largest speed and acceleration (of its own
    /// particles) read back, the largest over the ranks written in their place, so that every
    /// rank's choose_dt computes the dt one GPU computes for all the particles. Alone nothing.
    fn maxima_across_ranks(&self, rec: &mut dyn Recorder) {
        let Some(comm) = &self.ranks else { return };
        let words = status::MAX_SPEED as u64 * 4;
        debug_assert_eq!(status::MAX_ACCELERATION, status::MAX_SPEED + 1);
        let reduced = (|| -> anyhow::Result<[f32; 2]> {
            let data = rec.submit_and_read(&self.ctx, &[(&self.status, words, 8)]).ok_or_else(|| anyhow::anyhow!("the adaptive step across ranks cannot run in timed passes"))??;
            let mine: [f32; 2] = std::array::from_fn(|k| f32::from_le_bytes(data[0][4 * k..4 * k + 4].try_into().expect("4 bytes")));
            // f32 to f64 and back is exact, and so is the largest of them.
            let all = crate::solver::communicator::all_max(&**comm, &[mine[0] as f64, mine[1] as f64])?;
            Ok([all[0] as f32, all[1] as f32])
        })();
        match reduced {
            Ok(all) => self.ctx.queue.write_buffer(&self.status, words, bytemuck::cast_slice(&all)),
            Err(e) => {
                self.rank_error.borrow_mut().get_or_insert(format!("{e:#}"));
            }
        }
    }

    /// Whether the step about to run rebuilds the neighbour grid (every `rebuild_every` steps;
    /// in between, the stages use the cells of the last rebuild), or with a skin when it is due.
    fn rebuilds(&self) -> bool {
        match &self.skin {
            Some(skin) => skin.rebuild_due.get(),
            None => self.steps % self.params.rebuild_every.max(1) as u64 == 0,
        }
    }

    /// With a skin, after a step has been submitted: reads its check and makes the next step
    /// rebuild where the lists may miss a neighbour (`SkinCheck::rebuild_due`; or where the
    /// check cannot be read).
    pub(super) fn read_skin_check(&self) {
        let Some(skin) = &self.skin else { return };
        match read_ranges(&self.ctx, &[(&skin.left, 0, super::skin::CHECK_BYTES)]) {
            Ok(data) => {
                if super::skin::read_check(&data[0]).rebuild_due(skin.reach) {
                    skin.rebuild_due.set(true);
                }
            }
            Err(e) => {
                log::error!("reading the neighbour skin's check failed: {e:#}");
                skin.rebuild_due.set(true);
            }
        }
    }

    /// With a skin, the next step rebuilds (the host saved or restored the state).
    pub(super) fn rebuild_next_step(&self) {
        if let Some(skin) = &self.skin {
            skin.rebuild_due.set(true);
        }
    }

    pub(super) fn dispatch_particles(&self, rec: &mut dyn Recorder, stage: &Stage, group: &wgpu::BindGroup) {
        self.dispatch_threads(rec, stage, group, self.fluid_count as u64);
    }

    /// A stage with one invocation per wall particle.
    fn dispatch_walls(&self, rec: &mut dyn Recorder, stage: &Stage, group: &wgpu::BindGroup) {
        self.dispatch_threads(rec, stage, group, self.wall_count as u64);
    }

    pub(super) fn dispatch_threads(&self, rec: &mut dyn Recorder, stage: &Stage, group: &wgpu::BindGroup, threads: u64) {
        let pass = rec.pass();
        pass.set_pipeline(&stage.pipeline);
        pass.set_bind_group(0, group, &[]);
        let (x, y) = dispatch_size(threads, stage.threads_per_group, self.max_groups_per_dim);
        pass.dispatch_workgroups(x, y, 1);
    }

    /// THE order of a DFSPH step (after the binning, which `schedule` records): the factors on
    /// the state just binned, the divergence solve on its velocities, the prediction into the
    /// other buffer of the pair, the constant-density solve there, the integration and the
    /// bookkeeping. For the fields of the current state, the factors alone (density and the
    /// pressure of the last solve).
    fn schedule_dfsph(&mut self, work: Work, rec: &mut dyn Recorder) {
        let read = self.current;
        if work == Work::Step {
            rec.clear(&self.status, status::NON_FINITE as u64 * 4, Some(8));
        }
        let d = self.dfsph.as_ref().expect("a DFSPH scene");
        let g = &d.groups[read];
        rec.begin(ProfiledStage::DfsphFactors);
        self.dispatch_particles(rec, &d.stages.factors, &g.factors);
        if work == Work::Fields {
            self.fields_state = read;
            self.accelerations_valid = false;
            return;
        }
        // The point probes and gauges sample the state the step starts from with its factors'
        // density and output pressure, as the weakly compressible step's with its density stage
        // (profiled with the factors; only on the steps where one is due); the force and front
        // probes after the solves (src/solver/cpu/mod.rs `step_once`).
        let mut sampling = false;
        if let Some(probes) = self.probes.as_mut() {
            if self.params.probes.samples_step(self.steps, self.params.dt, self.params.adaptive.is_some()) && probes.room(self.steps) {
                probes.record_points(rec.pass(), read);
                sampling = true;
            }
        }
        let d = self.dfsph.as_ref().expect("a DFSPH scene");
        let g = &d.groups[read];
        if d.settings.divergence_solve {
            rec.begin(ProfiledStage::DivergenceSolve);
            self.record_solve(rec, 0, read);
        }
        // Across ranks, where the host samples force probes this step.
        self.keep_prediction_start(rec, read);
        rec.begin(ProfiledStage::DfsphPredict);
        // With surface tension, the normals its curvature term reads (profiled with the
        // prediction).
        if let (Some(stage), Some(group)) = (&d.stages.surface_normals, &g.surface_normals) {
            self.dispatch_particles(rec, stage, group);
        }
        match (&d.stages.adaptive, &g.adaptive) {
            (Some([accelerations, choose, predict]), Some([ga, gc, gp])) => {
                self.dispatch_particles(rec, accelerations, ga);
                self.maxima_across_ranks(rec);
                dispatch_one(rec, choose, gc);
                self.dispatch_particles(rec, predict, gp);
            }
            _ => self.dispatch_particles(rec, &d.stages.predict, &g.predict),
        }
        if self.solves_across_ranks() {
            // The ghosts take their owners' predicted velocities.
            self.sync_ghost_velocities(rec, read, true);
        }
        rec.begin(ProfiledStage::PressureSolve);
        self.record_solve(rec, 1, read);
        // The rest of the probes' sample, on the step's first positions (profiled with the
        // solve): the forces are the step's wall push.
        if let (true, Some(probes)) = (sampling, self.probes.as_mut()) {
            probes.record_particles(rec.pass(), read, self.steps);
        }
        rec.begin(ProfiledStage::DfsphIntegrate);
        self.dispatch_particles(rec, &d.stages.integrate, &g.integrate);
        dispatch_one(rec, &self.pipelines.finish_step, &self.finish_group);
        self.current = self.store.after_prediction(read);
        self.fields_state = read;
        self.accelerations_valid = false;
    }

    /// One DFSPH solve (0: divergence, 1: constant density) on the state pair read from `read`:
    /// the check's state reset, the warm start (its stiffness and its velocity change), the
    /// first error, then the iterations, each a velocity change, a new error and a check. With
    /// [`SolverLoop::Indirect`] every iteration up to the limit is recorded and the GPU's checks
    /// make those after the last empty; with [`SolverLoop::Readback`] blocks of them are recorded
    /// while the solve goes on, its state read back after each.
    fn record_solve(&self, rec: &mut dyn Recorder, solve: usize, read: usize) {
        if self.solves_across_ranks() {
            self.record_solve_across_ranks(rec, solve, read);
            return;
        }
        let d = self.dfsph.as_ref().expect("a DFSPH scene");
        let st = &d.stages;
        let SolvePasses { warm: (warm, gw), rate: (rate, gr), apply: (apply, ga) } = d.solve_passes(solve, read);
        let (begin_group, check_group) = &d.control[solve];
        dispatch_one(rec, &st.begin[solve], begin_group);
        if d.settings.warm_start {
            self.dispatch_particles(rec, warm, gw);
            self.dispatch_particles(rec, apply, ga);
        }
        self.dispatch_particles(rec, rate, gr);
        dispatch_one(rec, &st.check[solve], check_group);
        let iteration = |rec: &mut dyn Recorder| {
            dispatch_indirect(rec, apply, ga, &d.buffers.solve_dispatch);
            dispatch_indirect(rec, rate, gr, &d.buffers.solve_dispatch);
            dispatch_one(rec, &st.check[solve], check_group);
        };
        let limit = d.recorded_iterations(solve);
        let warm = d.settings.warm_start as u32;
        let (first, later) = match self.solver_loop {
            SolverLoop::Indirect => (limit, limit),
            SolverLoop::Readback(k) => (k, k),
            SolverLoop::Adaptive => (self.last_iterations.get()[solve] + 1, ADAPTIVE_BLOCK),
        };
        let mut recorded = 0;
        let mut block = first.clamp(1, limit.max(1));
        while recorded < limit {
            let n = block.min(limit - recorded);
            for _ in 0..n {
                iteration(rec);
            }
            recorded += n;
            block = later;
            // A block boundary: ask the GPU whether the solve goes on (a recorder that cannot
            // wait, the profile's across ranks, records every iteration up to the limit).
            if recorded < limit {
                let Some(read) = rec.submit_and_read(&self.ctx, &[(&self.status, status::DFSPH_ITERATION as u64 * 4, 8)]) else { continue };
                if let Some(done) = self.solve_ended(read) {
                    let mut last = self.last_iterations.get();
                    last[solve] = done.saturating_sub(warm);
                    self.last_iterations.set(last);
                    break;
                }
            }
        }
    }

    /// The iterations of the DFSPH solve under way once it has ended (the warm start counts
    /// as one), `None` while it goes on: from `read`, the two status words from
    /// `DFSPH_ITERATION` read back.
    fn solve_ended(&self, read: anyhow::Result<Vec<Vec<u8>>>) -> Option<u32> {
        debug_assert_eq!(status::DFSPH_SOLVING, status::DFSPH_ITERATION + 1);
        match read {
            Ok(data) => {
                let word = |k: usize| u32::from_le_bytes(data[0][4 * k..4 * k + 4].try_into().expect("4 bytes"));
                (word(1) == 0).then(|| word(0))
            }
            Err(e) => {
                log::error!("reading the DFSPH solve's state failed: {e:#}");
                None
            }
        }
    }

    /// Advances `n` steps, `steps_per_submit` per command buffer; a viscosity change from the
    /// schedule starts a new command buffer after a uniform write.
    pub fn advance(&mut self, n: u64) {
        let mut left = n;
        // Without a schedule the viscosity never changes: no per-step look-up.
        let scheduled = self.params.viscosity.len() > 1;
        // With a skin the host reads each step's check before recording the next.
        let per_submit = if self.skin.is_some() { 1 } else { self.steps_per_submit };
        while left > 0 {
            let nu = self.params.viscosity_at_step(self.steps);
            self.set_viscosity(nu);
            let mut rec = PlainRecorder::new(&self.ctx.device, "steps");
            let mut batch = 0;
            while batch < left.min(per_submit) {
                if scheduled && batch > 0 && self.params.viscosity_at_step(self.steps) != nu {
                    break;
                }
                self.schedule(Work::Step, &mut rec);
                self.steps += 1;
                batch += 1;
            }
            self.ctx.queue.submit([rec.finish()]);
            self.read_skin_check();
            left -= batch;
        }
    }

    /// Sorts the current state by cell (idempotent: a sorted state stays as it is; with a skin
    /// only where a rebuild is due) and evaluates density and pressure for it, without
    /// advancing time.
    pub(super) fn refresh_fields(&mut self) {
        let mut rec = PlainRecorder::new(&self.ctx.device, "refresh");
        self.schedule(Work::Fields, &mut rec);
        self.ctx.queue.submit([rec.finish()]);
    }

    /// The forces of the state the fields belong to, into the accelerations array (the fused
    /// step keeps them in registers, a refresh overwrites the spare buffer that holds them in
    /// place; `step_fields` asks for them).
    pub(super) fn record_accelerations(&mut self) {
        let mut rec = PlainRecorder::new(&self.ctx.device, "accelerations");
        let stages = self.wcsph_stages();
        let normals = self.groups[self.fields_state].wcsph.as_ref().and_then(|g| g.surface_normals.as_ref());
        if let (Some(stage), Some(group)) = (&stages.surface_normals, normals) {
            self.dispatch_particles(&mut rec, stage, group);
        }
        let in_place = self.groups[self.fields_state].wcsph.as_ref().and_then(|g| g.forces.as_ref());
        let group = match in_place {
            Some(group) => group,
            None => &self.accelerations.as_ref().expect("made by the caller").groups[self.fields_state],
        };
        self.dispatch_particles(&mut rec, &self.wcsph_stages().forces, group);
        self.ctx.queue.submit([rec.finish()]);
    }

    /// The density and pressure of the current state into the output arrays (`stage` and its
    /// `group`, see `GpuSolver::particle_buffers`).
    pub(super) fn record_output_fields(&self, stage: &Stage, group: &wgpu::BindGroup) {
        let mut rec = PlainRecorder::new(&self.ctx.device, "output fields");
        self.dispatch_particles(&mut rec, stage, group);
        self.ctx.queue.submit([rec.finish()]);
    }

    /// DFSPH: the accelerations of the last step, (v_end - v_start) / dt, into the accelerations
    /// array (made on first use with a fixed dt).
    pub(super) fn record_step_accelerations(&mut self) {
        let n = self.fluid_count as u64;
        let d = self.dfsph.as_mut().expect("DFSPH");
        let buffer = d.accelerations.get_or_insert_with(|| storage(&self.ctx.device, "accelerations", n * 16)).clone();
        if self.step_accelerations_groups.is_none() {
            let d = self.dfsph.as_ref().expect("DFSPH");
            let shared = SharedBuffers {
                store: &self.store,
                starts: &self.starts,
                densities: self.densities.as_ref().expect("DFSPH keeps a densities array"),
                pressures: self.pressures.as_ref().expect("DFSPH keeps a pressures array"),
                status: &self.status,
                wall_positions: &self.wall_positions,
                wall_cell_blocks: &self.wall_cell_blocks,
                wall_cell_firsts: &self.wall_cell_firsts,
                accelerations: &buffer,
                lists: self.neighbour_lists.as_ref(),
                normals: self.normals.as_ref(),
            };
            self.step_accelerations_groups = Some((0..self.store.phases()).map(|c| d.step_accelerations_group(&self.ctx, &shared, &self.uniform, c)).collect());
        }
        let d = self.dfsph.as_ref().expect("DFSPH");
        let group = &self.step_accelerations_groups.as_ref().expect("made above")[self.fields_state];
        let mut rec = PlainRecorder::new(&self.ctx.device, "step accelerations");
        self.dispatch_particles(&mut rec, &d.stages.step_accelerations, group);
        self.ctx.queue.submit([rec.finish()]);
    }

    /// Runs one DFSPH stage on the current state (for the stage tests, after a snapshot has
    /// binned it and run the factors). Returns the error sum a stage that reduces one adds.
    pub fn dfsph_stage(&mut self, stage: crate::solver::backend::DfsphStage) -> anyhow::Result<u64> {
        use crate::solver::backend::DfsphStage as S;
        let c = self.current;
        let d = self.dfsph.as_ref().ok_or_else(|| anyhow::anyhow!("not a DFSPH scene"))?;
        let (g, st) = (&d.groups[c], &d.stages);
        let lo = status::DFSPH_ERROR_LO as u64 * 4;
        let mut rec = PlainRecorder::new(&self.ctx.device, "dfsph stage");
        rec.clear_range(&self.status, lo, 8);
        match stage {
            S::Factors => self.dispatch_particles(&mut rec, &st.factors, &g.factors),
            S::DivergenceWarmStart => self.dispatch_particles(&mut rec, &st.divergence_warm_start, &g.divergence_warm_start),
            S::DivergenceRate => self.dispatch_particles(&mut rec, &st.divergence_rate, &g.divergence_rate),
            S::DivergenceApply => self.dispatch_particles(&mut rec, &st.divergence_apply, &g.divergence_apply),
            S::Predict => {
                if let (Some(stage), Some(group)) = (&st.surface_normals, &g.surface_normals) {
                    self.dispatch_particles(&mut rec, stage, group);
                }
                match (&st.adaptive, &g.adaptive) {
                    (Some([a, choose, p]), Some([ga, gc, gp])) => {
                        self.dispatch_particles(&mut rec, a, ga);
                        self.dispatch_one(&mut rec, choose, gc);
                        self.dispatch_particles(&mut rec, p, gp);
                    }
                    _ => self.dispatch_particles(&mut rec, &st.predict, &g.predict),
                }
            }
            S::PressureWarmStart => self.dispatch_particles(&mut rec, &st.pressure_warm_start, &g.pressure_warm_start),
            S::PredictDensity => self.dispatch_particles(&mut rec, &st.predict_density, &g.predict_density),
            S::PressureApply => self.dispatch_particles(&mut rec, &st.pressure_apply, &g.pressure_apply),
        }
        self.ctx.queue.submit([rec.finish()]);
        let words = self.read_status()?;
        Ok(words[status::DFSPH_ERROR_LO] as u64 | (words[status::DFSPH_ERROR_HI] as u64) << 32)
    }

    /// Whether the device can time stages (wgpu `TIMESTAMP_QUERY`).
    pub fn has_timestamps(&self) -> bool {
        self.ctx.device.features().contains(wgpu::Features::TIMESTAMP_QUERY)
    }

    /// The rows of this solver's profile, in dispatch order: [`PROFILED_STAGES`] with surface
    /// tension the normals between `density` and `forces` (DFSPH: [`DFSPH_PROFILED_STAGES`],
    /// which time the normals with the prediction).
    pub fn profiled_rows(&self) -> Vec<ProfiledStage> {
        if self.dfsph.is_some() {
            return ProfiledStage::DFSPH.to_vec();
        }
        let mut rows = ProfiledStage::WCSPH.to_vec();
        if self.params.surface_tension > 0.0 {
            let forces = rows.iter().position(|&s| s == ProfiledStage::Forces).expect("a forces row");
            rows.insert(forces, ProfiledStage::SurfaceNormals);
        }
        rows
    }

    /// Runs `steps` steps in the order of [`GpuSolver::schedule`], each stage in its own timed
    /// pass, and returns the total GPU time of each row of [`GpuSolver::profiled_rows`] in
    /// nanoseconds (a stage that did not run, like the binning between neighbour rebuilds, adds
    /// 0). `None` when the device has no timestamp queries.
    /// Each step is submitted and read back on its own: slower than `advance`, but the GPU time
    /// of the stages holds no host round trip. A DFSPH solve's loop ends as the solver's does
    /// (the recorder submits and waits at each block's end, the solve timed in segments); across
    /// ranks, whose exchanges it does not time, the recorder does not wait, and what needs a
    /// wait there is refused.
    pub fn profile_stages(&mut self, steps: u64) -> anyhow::Result<Option<Vec<(ProfiledStage, f64)>>> {
        if !self.has_timestamps() {
            return Ok(None);
        }
        let device = &self.ctx.device;
        let count = 2 * ALL_PROFILED_STAGES as u32;
        let queries = device.create_query_set(&wgpu::QuerySetDescriptor { label: Some("stage timestamps"), ty: wgpu::QueryType::Timestamp, count });
        let resolved = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("resolved timestamps"),
            size: count as u64 * 8,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let period_ns = self.ctx.queue.get_timestamp_period() as f64;
        let mut totals = [0.0f64; ALL_PROFILED_STAGES];
        for _ in 0..steps {
            let nu = self.params.viscosity_at_step(self.steps);
            self.set_viscosity(nu);
            let mut rec = TimedRecorder::new(&self.ctx.device, &queries, &resolved, self.ranks.is_none());
            self.schedule(Work::Step, &mut rec);
            let (ran, carried) = (rec.ran, rec.carried);
            self.ctx.queue.submit([rec.finish()]);
            self.steps += 1;
            self.read_skin_check();
            let data = read_buffers(&self.ctx, &[(&resolved, count as u64 * 8)])?;
            let ticks: Vec<u64> = bytemuck::pod_collect_to_vec(&data[0]);
            for (i, total) in totals.iter_mut().enumerate() {
                if ran[i] {
                    // Timestamps can wrap or come back equal on coarse clocks: never negative.
                    *total += (ticks[2 * i + 1].saturating_sub(ticks[2 * i]) + carried[i]) as f64 * period_ns;
                }
            }
        }
        Ok(Some(self.profiled_rows().into_iter().map(|s| (s, totals[s as usize])).collect()))
    }
}

/// A particle stage whose dispatch size the GPU wrote into `args` (its first three words).
fn dispatch_indirect(rec: &mut dyn Recorder, stage: &Stage, group: &wgpu::BindGroup, args: &wgpu::Buffer) {
    let pass = rec.pass();
    pass.set_pipeline(&stage.pipeline);
    pass.set_bind_group(0, group, &[]);
    pass.dispatch_workgroups_indirect(args, 0);
}

impl GpuSolver {
    /// A one-thread stage.
    pub(super) fn dispatch_one(&self, rec: &mut dyn Recorder, stage: &Stage, group: &wgpu::BindGroup) {
        dispatch_one(rec, stage, group);
    }
}

/// A one-thread stage (the choice of dt, the bookkeeping).
fn dispatch_one(rec: &mut dyn Recorder, stage: &Stage, group: &wgpu::BindGroup) {
    let pass = rec.pass();
    pass.set_pipeline(&stage.pipeline);
    pass.set_bind_group(0, group, &[]);
    pass.dispatch_workgroups(1, 1, 1);
}
