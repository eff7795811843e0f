//! A profiled recording of the step: every stage in its own compute pass with timestamp writes
//! at its start and end, so the time of each stage can be read back. The normal step
//! (`record_step`) keeps all its dispatches in as few passes as possible and is not changed.

use super::{read_buffers, GpuSolver};

/// The stages of a step, in dispatch order, as the profile names them.
pub const PROFILED_STAGES: [&str; 7] = ["bin_count", "prefix_sum", "bin_scatter", "reorder", "density", "forces", "integrate"];

impl GpuSolver {
    /// Whether the device can time stages (wgpu `TIMESTAMP_QUERY`).
    pub fn has_timestamps(&self) -> bool {
        self.ctx.device.features().contains(wgpu::Features::TIMESTAMP_QUERY)
    }

    /// Runs `steps` steps, each stage in its own timed pass, and returns the total GPU time of
    /// each stage of `PROFILED_STAGES` in nanoseconds (a stage that did not run, like the binning
    /// between neighbour rebuilds, adds 0). `None` when the device has no timestamp queries.
    /// Each step is submitted and read back on its own: slower than `advance`, but the GPU
    /// time of the stages does not include the host round trips.
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
            let mut encoder = self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("profiled step") });
            let ran = self.record_profiled_step(&mut encoder, &queries);
            encoder.resolve_query_set(&queries, 0..count, &resolved, 0);
            self.ctx.queue.submit([encoder.finish()]);
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

    /// Records one step like `record_step`, one timed pass per stage; returns which stages ran.
    /// With the fused step the forces and the integration are one pass, timed as `forces`; the
    /// `integrate` pass then holds only the step's one-thread bookkeeping.
    fn record_profiled_step(&mut self, encoder: &mut wgpu::CommandEncoder, queries: &wgpu::QuerySet) -> [bool; 7] {
        let mut ran = [false; 7];
        if self.rebuilds() {
            encoder.clear_buffer(&self.starts, 0, None);
            let g = &self.groups[self.current];
            let mut pass = timed_pass(encoder, queries, &mut ran, 0);
            self.dispatch_particles(&mut pass, &self.pipelines.bin_count, &g.bin_count);
            drop(pass);
            let mut pass = timed_pass(encoder, queries, &mut ran, 1);
            self.scan.record(&mut pass);
            drop(pass);
            let mut pass = timed_pass(encoder, queries, &mut ran, 2);
            self.dispatch_particles(&mut pass, &self.pipelines.bin_scatter, &g.bin_scatter);
            drop(pass);
            let mut pass = timed_pass(encoder, queries, &mut ran, 3);
            self.dispatch_particles(&mut pass, &self.pipelines.reorder, &g.reorder);
            drop(pass);
            self.current = 1 - self.current;
        }
        let read = self.current;
        encoder.clear_buffer(&self.status, 4, Some(8));
        let g = &self.groups[read];
        let mut pass = timed_pass(encoder, queries, &mut ran, 4);
        self.dispatch_particles(&mut pass, &self.pipelines.density, &g.density);
        drop(pass);
        let mut pass = timed_pass(encoder, queries, &mut ran, 5);
        if self.pipelines.fused {
            self.dispatch_particles(&mut pass, &self.pipelines.advance, &g.advance);
        } else {
            let acc = self.accelerations.as_ref().expect("kept without fusion");
            self.dispatch_particles(&mut pass, &self.pipelines.forces, &acc.groups[read]);
        }
        drop(pass);
        let mut pass = timed_pass(encoder, queries, &mut ran, 6);
        if let Some((reduce, choose)) = &self.pipelines.adaptive {
            self.dispatch_particles(&mut pass, reduce, &g.advance);
            pass.set_pipeline(&choose.pipeline);
            pass.set_bind_group(0, &g.advance, &[]);
            pass.dispatch_workgroups(1, 1, 1);
        }
        if !self.pipelines.fused {
            self.dispatch_particles(&mut pass, &self.pipelines.advance, &g.advance);
        }
        pass.set_pipeline(&self.pipelines.finish_step.pipeline);
        pass.set_bind_group(0, &self.finish_group, &[]);
        pass.dispatch_workgroups(1, 1, 1);
        drop(pass);
        self.finish_step(read);
        ran
    }
}

/// A compute pass for stage `i` of `PROFILED_STAGES` with timestamps at 2i and 2i + 1.
fn timed_pass<'e>(encoder: &'e mut wgpu::CommandEncoder, queries: &wgpu::QuerySet, ran: &mut [bool; 7], i: usize) -> wgpu::ComputePass<'e> {
    ran[i] = true;
    let writes = wgpu::ComputePassTimestampWrites {
        query_set: queries,
        beginning_of_pass_write_index: Some(2 * i as u32),
        end_of_pass_write_index: Some(2 * i as u32 + 1),
    };
    encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some(PROFILED_STAGES[i]), timestamp_writes: Some(writes) })
}
