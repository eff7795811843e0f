//! THE order of the GPU's work: one function, `GpuSolver::schedule`, records a step (or the
//! fields of the current state) against a [`Recorder`]. The normal path records into as few
//! compute passes as possible ([`PlainRecorder`]); the profile records the very same order with
//! every stage in its own timed pass ([`TimedRecorder`]), so what is timed is what runs.

use super::shaders::{dispatch_size, Stage};
use super::solver::GpuSolver;
use super::readback::read_buffers;
use super::params::status;

/// The stages of a step as the profile names them, in dispatch order. With the fused step the
/// forces and the integration are one pass, timed as `forces`; `integrate` then holds only the
/// step's one-thread bookkeeping.
pub const PROFILED_STAGES: [&str; 7] = ["bin_count", "prefix_sum", "bin_scatter", "reorder", "density", "forces", "integrate"];

/// A profiled stage: an index into [`PROFILED_STAGES`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProfiledStage {
    BinCount = 0,
    PrefixSum = 1,
    BinScatter = 2,
    Reorder = 3,
    Density = 4,
    Forces = 5,
    Integrate = 6,
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
}

/// Records every profiled stage into its own compute pass with timestamps at its start (query
/// 2i) and end (2i + 1).
pub struct TimedRecorder<'q> {
    encoder: wgpu::CommandEncoder,
    pass: Option<wgpu::ComputePass<'static>>,
    queries: &'q wgpu::QuerySet,
    /// Which stages were recorded.
    pub ran: [bool; 7],
}

impl<'q> TimedRecorder<'q> {
    pub fn new(device: &wgpu::Device, queries: &'q wgpu::QuerySet) -> Self {
        let encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("profiled step") });
        TimedRecorder { encoder, pass: None, queries, ran: [false; 7] }
    }
    /// The command buffer, with the timestamps resolved into `resolved`.
    pub fn finish(mut self, resolved: &wgpu::Buffer) -> wgpu::CommandBuffer {
        self.pass = None;
        self.encoder.resolve_query_set(self.queries, 0..2 * PROFILED_STAGES.len() as u32, resolved, 0);
        self.encoder.finish()
    }
}

impl Recorder for TimedRecorder<'_> {
    fn begin(&mut self, stage: ProfiledStage) {
        let i = stage as usize;
        self.pass = None;
        self.ran[i] = true;
        let writes = wgpu::ComputePassTimestampWrites {
            query_set: self.queries,
            beginning_of_pass_write_index: Some(2 * i as u32),
            end_of_pass_write_index: Some(2 * i as u32 + 1),
        };
        let pass = self.encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some(PROFILED_STAGES[i]), timestamp_writes: Some(writes) });
        self.pass = Some(pass.forget_lifetime());
    }
    fn pass(&mut self) -> &mut wgpu::ComputePass<'static> {
        let encoder = &mut self.encoder;
        self.pass.get_or_insert_with(|| encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("untimed"), timestamp_writes: None }).forget_lifetime())
    }
    fn clear(&mut self, buffer: &wgpu::Buffer, offset: u64, size: Option<u64>) {
        self.pass = None;
        self.encoder.clear_buffer(buffer, offset, size);
    }
}

impl GpuSolver {
    /// THE order of the GPU's work, recorded against `rec`: the binning of the current state
    /// into the other buffer of the pair (when due), the fields on it, and (for a step) the
    /// forces, the integration back into the first buffer and the bookkeeping.
    pub(super) fn schedule(&mut self, work: Work, rec: &mut dyn Recorder) {
        let bins = match work {
            Work::Step => self.rebuilds(),
            Work::Fields => true,
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
            self.dispatch_particles(rec, &self.pipelines.reorder, &g.reorder);
            self.current = 1 - self.current;
        }
        let read = self.current;
        let g = &self.groups[read];
        if work == Work::Fields {
            rec.begin(ProfiledStage::Density);
            self.dispatch_particles(rec, &self.pipelines.density, &g.density);
            self.fields_state = read;
            self.accelerations_valid = false;
            return;
        }
        // This step's counts of bad particles start from zero.
        rec.clear(&self.status, status::NON_FINITE as u64 * 4, Some(8));
        rec.begin(ProfiledStage::Density);
        self.dispatch_particles(rec, &self.pipelines.density, &g.density);
        // The probes sample the state the step starts from, with its density stage's fields;
        // only in a scene with probes, only on the steps where one is due (profiled with the
        // density).
        if let Some(probes) = self.probes.as_mut() {
            if self.params.probes.samples_step(self.steps, self.params.dt, self.params.adaptive.is_some()) {
                probes.record(rec.pass(), read, self.steps);
            }
        }
        rec.begin(ProfiledStage::Forces);
        if self.pipelines.fused {
            self.dispatch_particles(rec, &self.pipelines.advance, &g.advance);
        } else if let Some(acc) = &self.accelerations {
            self.dispatch_particles(rec, &self.pipelines.forces, &acc.groups[read]);
        }
        rec.begin(ProfiledStage::Integrate);
        if let Some((reduce, choose)) = &self.pipelines.adaptive {
            self.dispatch_particles(rec, reduce, &g.advance);
            dispatch_one(rec, choose, &g.advance);
        }
        if !self.pipelines.fused {
            self.dispatch_particles(rec, &self.pipelines.advance, &g.advance);
        }
        dispatch_one(rec, &self.pipelines.finish_step, &self.finish_group);
        self.current = 1 - read;
        self.fields_state = read;
        self.accelerations_valid = !self.pipelines.fused;
    }

    /// Whether the step about to run rebuilds the neighbour grid (every `rebuild_every` steps;
    /// in between, the stages use the cells of the last rebuild).
    fn rebuilds(&self) -> bool {
        self.steps % self.params.rebuild_every.max(1) as u64 == 0
    }

    fn dispatch_particles(&self, rec: &mut dyn Recorder, stage: &Stage, group: &wgpu::BindGroup) {
        let pass = rec.pass();
        pass.set_pipeline(&stage.pipeline);
        pass.set_bind_group(0, group, &[]);
        let (x, y) = dispatch_size(self.fluid_count as u64, stage.threads_per_group, self.max_groups_per_dim);
        pass.dispatch_workgroups(x, y, 1);
    }

    /// Advances `n` steps, `steps_per_submit` per command buffer; a viscosity change from the
    /// schedule starts a new command buffer after a uniform write.
    pub fn advance(&mut self, n: u64) {
        let mut left = n;
        // Without a schedule the viscosity never changes: no per-step look-up.
        let scheduled = self.params.viscosity.len() > 1;
        while left > 0 {
            let nu = self.params.viscosity_at_step(self.steps);
            self.set_viscosity(nu);
            let mut rec = PlainRecorder::new(&self.ctx.device, "steps");
            let mut batch = 0;
            while batch < left.min(self.steps_per_submit) {
                if scheduled && batch > 0 && self.params.viscosity_at_step(self.steps) != nu {
                    break;
                }
                self.schedule(Work::Step, &mut rec);
                self.steps += 1;
                batch += 1;
            }
            self.ctx.queue.submit([rec.finish()]);
            left -= batch;
        }
    }

    /// Sorts the current state by cell (idempotent: a sorted state stays as it is) and
    /// evaluates density and pressure for it, without advancing time.
    pub(super) fn refresh_fields(&mut self) {
        let mut rec = PlainRecorder::new(&self.ctx.device, "refresh");
        self.schedule(Work::Fields, &mut rec);
        self.ctx.queue.submit([rec.finish()]);
    }

    /// The forces of the state the fields belong to, into the accelerations array (the fused
    /// step keeps them in registers; `step_fields` asks for them).
    pub(super) fn record_accelerations(&mut self) {
        let mut rec = PlainRecorder::new(&self.ctx.device, "accelerations");
        let acc = self.accelerations.as_ref().expect("made by the caller");
        self.dispatch_particles(&mut rec, &self.pipelines.forces, &acc.groups[self.fields_state]);
        self.ctx.queue.submit([rec.finish()]);
    }

    /// Whether the device can time stages (wgpu `TIMESTAMP_QUERY`).
    pub fn has_timestamps(&self) -> bool {
        self.ctx.device.features().contains(wgpu::Features::TIMESTAMP_QUERY)
    }

    /// Runs `steps` steps in the order of `GpuSolver::schedule`, each stage in its own timed
    /// pass, and returns the total GPU time of each stage of [`PROFILED_STAGES`] in nanoseconds
    /// (a stage that did not run, like the binning between neighbour rebuilds, adds 0). `None`
    /// when the device has no timestamp queries. Each step is submitted and read back on its
    /// own: slower than `advance`, but the GPU time of the stages holds no host round trip.
    pub fn profile_stages(&mut self, steps: u64) -> anyhow::Result<Option<[f64; 7]>> {
        if !self.has_timestamps() {
            return Ok(None);
        }
        let device = &self.ctx.device;
        let count = 2 * PROFILED_STAGES.len() as u32;
        let queries = device.create_query_set(&wgpu::QuerySetDescriptor { label: Some("stage timestamps"), ty: wgpu::QueryType::Timestamp, count });
        let resolved = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("resolved timestamps"),
            size: count as u64 * 8,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let period_ns = self.ctx.queue.get_timestamp_period() as f64;
        let mut totals = [0.0f64; 7];
        for _ in 0..steps {
            let nu = self.params.viscosity_at_step(self.steps);
            self.set_viscosity(nu);
            let mut rec = TimedRecorder::new(&self.ctx.device, &queries);
            self.schedule(Work::Step, &mut rec);
            let ran = rec.ran;
            self.ctx.queue.submit([rec.finish(&resolved)]);
            self.steps += 1;
            let data = read_buffers(&self.ctx, &[(&resolved, count as u64 * 8)])?;
            let ticks: Vec<u64> = bytemuck::pod_collect_to_vec(&data[0]);
            for (i, total) in totals.iter_mut().enumerate() {
                if ran[i] {
                    // Timestamps can wrap or come back equal on coarse clocks: never negative.
                    *total += ticks[2 * i + 1].saturating_sub(ticks[2 * i]) as f64 * period_ns;
                }
            }
        }
        Ok(Some(totals))
    }
}

/// A one-thread stage (the choice of dt, the bookkeeping).
fn dispatch_one(rec: &mut dyn Recorder, stage: &Stage, group: &wgpu::BindGroup) {
    let pass = rec.pass();
    pass.set_pipeline(&stage.pipeline);
    pass.set_bind_group(0, group, &[]);
    pass.dispatch_workgroups(1, 1, 1);
}
