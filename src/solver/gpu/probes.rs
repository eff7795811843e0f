//! The probes on the GPU (wgsl/sim/probes.wgsl): the probe table, the one data buffer (the
//! row count, the values of a sample, the workgroups' partials and a buffer of rows), the
//! pipelines of the three entry points and their bind groups of each parity. Built only for a
//! scene with probes; `GpuSolver::schedule` records them on the steps where a probe is due, and
//! the rows (a few numbers each) are read back when the buffer is full or the samples are asked
//! for: no particle array is read back.

use super::buffers::{storage, storage_init};
use super::device::GpuContext;
use super::params::status;
use super::readback::read_ranges;
use super::shaders::{dispatch_size, stage_with_aliases, Alias, ArrayBuffers, ArrayLengths, Stage};
use crate::model::params::{Params, TimeSum};
use crate::model::probes::{ProbeGeometry, ProbeSample};

/// Rows the sample buffer holds before the host reads them back.
pub const ROW_CAPACITY: u64 = 1024;
/// Particles per workgroup of `probe_particles` (PROBE_WORKGROUP in probes.wgsl).
pub const PROBE_WORKGROUP: u32 = 128;
/// Words before each row's values: the step, the time's three words (status::TIME_LO, TIME_HI,
/// TIME_EXPONENT), the step's dt (PROBE_ROW_HEAD in probes.wgsl).
const ROW_HEAD: u64 = 5;
/// Slots of the partials: 6 per force probe, 2 per front probe.
const FORCE_SLOTS: u64 = 6;
const FRONT_SLOTS: u64 = 2;

/// DFSPH's stiffness sums, which its force probes read (`wall_push_pressure`).
pub(super) struct DfsphSums<'a> {
    pub pressure_sum: &'a wgpu::Buffer,
    pub divergence_sum: &'a wgpu::Buffer,
}

pub(super) struct GpuProbes {
    /// The row's head and the point probes and gauges (built for every scene with probes).
    points: Stage,
    particles: Option<Stage>,
    finish: Stage,
    /// Under DFSPH with force probes: `wall_push_pressure`, its output, its bind group per
    /// parity and its workgroups.
    push: Option<(Stage, wgpu::Buffer, Vec<wgpu::BindGroup>, (u32, u32))>,
    /// Per phase of the state read: the bind groups of the three entry points.
    groups: Vec<[wgpu::BindGroup; 3]>,
    pub data: wgpu::Buffer,
    table: wgpu::Buffer,
    masks: wgpu::Buffer,
    probe_count: u32,
    /// Workgroups `probe_particles` is dispatched with.
    particle_groups: (u32, u32),
    values: u64,
    rows_at: u64,
    /// The steps of the rows recorded and not yet read back, in order.
    pub pending: Vec<u64>,
    /// Rows read back and not yet handed out.
    pub samples: Vec<ProbeSample>,
    warned_full: bool,
}

impl GpuProbes {
    /// The table, the buffers and the pipelines of `params.probes` for `fluid` particles;
    /// `wall_masks` is each sorted wall particle's mask of force probes; `lens` gives the
    /// lengths of the solver's arrays, `buffers[c]` their buffers when phase `c` of the state is read;
    /// `places`: where arrays without buffers of their own live (the solver's
    /// `array_places`); `dfsph`: DFSPH's stiffness sums in a DFSPH scene.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn new(
        ctx: &GpuContext,
        params: &Params,
        fluid: u64,
        wall_masks: &[u32],
        constants: &[(&str, f64)],
        lens: ArrayLengths,
        uniform: &wgpu::Buffer,
        buffers: &[ArrayBuffers],
        places: &[(&str, Alias)],
        dfsph: Option<DfsphSums>,
    ) -> anyhow::Result<Self> {
        let stage = |ctx: &GpuContext, name: &str, entry: &str, lens: ArrayLengths, k: &[(&str, f64)]| stage_with_aliases(ctx, name, entry, lens, k, places);
        let probes = &params.probes;
        let max_dim = ctx.device.limits().max_compute_workgroups_per_dimension;
        let particle_groups = dispatch_size(fluid, PROBE_WORKGROUP, max_dim);
        let group_count = particle_groups.0 as u64 * particle_groups.1 as u64;
        let (forces, fronts) = (probes.force_count() as u64, probes.front_count() as u64);
        let values = probes.value_count() as u64;
        let partials = (FORCE_SLOTS * forces + FRONT_SLOTS * fronts) * group_count;
        let rows_at = values + partials;
        let data_len = 1 + rows_at + ROW_CAPACITY * (ROW_HEAD + values);
        let mut table: Vec<[u32; 4]> = vec![
            [probes.probes.len() as u32, forces as u32, fronts as u32, group_count as u32],
            [values as u32, values as u32, rows_at as u32, ROW_CAPACITY as u32],
        ];
        let f = |v: f64| (v as f32).to_bits();
        for (p, at) in probes.probes.iter().zip(probes.offsets()) {
            let (kind, b, c) = match &p.geometry {
                ProbeGeometry::Point { position } => (0, [f(position[0]), f(position[1]), f(position[2]), 0], [0; 4]),
                ProbeGeometry::Gauge { x, z, bottom, top, step } => (1, [f(*x), f(*bottom), f(*z), f(*top)], [f(*step), 0, 0, 0]),
                ProbeGeometry::Force { centre, .. } => (2, [f(centre[0]), f(centre[1]), f(centre[2]), 0], [0; 4]),
                ProbeGeometry::Front { direction, floor, height } => (3, [f(direction[0]), f(direction[1]), f(direction[2]), 0], [f(*floor), f(*height), 0, 0]),
            };
            table.extend([[kind, at as u32, 0, 0], b, c]);
        }
        let device = &ctx.device;
        let table_buffer = storage_init(device, "probe table", bytemuck::cast_slice(&table));
        let masks = storage_init(device, "wall probe masks", bytemuck::cast_slice(wall_masks));
        let data = storage(device, "probe data", data_len * 4);
        let table_len = table.len() as u64;
        let walls = wall_masks.len() as u64;
        // Under DFSPH the force probes read the step's wall push through the consistent wall
        // pressure (src/solver/cpu/probes.rs `wall_push_pressure`).
        let dfsph_forces = dfsph.as_ref().filter(|_| forces > 0);
        let push_pressures = dfsph_forces.map(|_| storage(device, "probe push pressures", fluid.max(1) * 4));
        let pushed = if dfsph_forces.is_some() { fluid } else { 0 };
        let len = |name: &str| -> u64 {
            match name {
                "probe_table" => table_len,
                "probe_data" => data_len,
                "wall_probe_masks" => walls,
                "pressure_sum" | "divergence_sum" | "push_pressures" => pushed,
                other => lens(other),
            }
        };
        let mut k = constants.to_vec();
        k.push(("WORKGROUP_SIZE", 64.0));
        if dfsph.is_some() {
            for (name, value) in k.iter_mut() {
                match *name {
                    "CONSISTENT_WALL_PRESSURE" => *value = 1.0,
                    "ADAMI_WALL_PRESSURE" | "ARTIFICIAL_VISCOSITY" => *value = 0.0,
                    _ => {}
                }
            }
        }
        let points = stage(ctx, "probes", "probe_points", &len, &k)?;
        let particles = if forces + fronts > 0 { Some(stage(ctx, "probes", "probe_particles", &len, &k)?) } else { None };
        let finish = stage(ctx, "probes", "probe_finish", &len, &k)?;
        // `pressures_read`: whether `pressures` binds the push's output (for the DFSPH force
        // probes' sums in probe_particles).
        let group = |stage: &Stage, label: &str, c: usize, pressures_read: bool| {
            let (table_buffer, masks, data, push_pressures, dfsph) = (&table_buffer, &masks, &data, &push_pressures, &dfsph_forces);
            let b = buffers[c];
            stage.bind_group(device, label, uniform, &|name: &str| match (name, push_pressures, dfsph) {
                ("probe_table", ..) => table_buffer.clone(),
                ("probe_data", ..) => data.clone(),
                ("wall_probe_masks", ..) => masks.clone(),
                // With the push's output read as `pressures`, its own name binds the scene's
                // pressures (unused there), since one buffer may not be bound both ways.
                ("push_pressures", Some(_), _) if pressures_read => b("pressures"),
                ("push_pressures", Some(push), _) => push.clone(),
                ("pressures", Some(push), _) if pressures_read => push.clone(),
                ("pressure_sum", _, Some(d)) => d.pressure_sum.clone(),
                ("divergence_sum", _, Some(d)) => d.divergence_sum.clone(),
                (other, ..) => b(other),
            })
        };
        let parity = |c: usize| {
            [
                group(&points, "probe_points", c, false),
                group(particles.as_ref().unwrap_or(&finish), "probe_particles", c, true),
                group(&finish, "probe_finish", c, false),
            ]
        };
        let groups: Vec<_> = (0..buffers.len()).map(parity).collect();
        let push = match push_pressures.clone() {
            Some(buffer) => {
                let stage = stage(ctx, "probes", "wall_push_pressure", &len, &k)?;
                let groups: Vec<_> = (0..buffers.len()).map(|c| group(&stage, "wall_push_pressure", c, false)).collect();
                let size = dispatch_size(fluid, stage.threads_per_group, max_dim);
                Some((stage, buffer, groups, size))
            }
            None => None,
        };
        Ok(GpuProbes {
            points,
            particles,
            finish,
            push,
            groups,
            data,
            table: table_buffer,
            masks,
            probe_count: probes.probes.len() as u32,
            particle_groups,
            values,
            rows_at,
            pending: Vec::new(),
            samples: Vec::new(),
            warned_full: false,
        })
    }

    /// Bytes of the probes' buffers.
    pub fn bytes(&self) -> u64 {
        self.data.size() + self.table.size() + self.masks.size() + self.push.as_ref().map_or(0, |p| p.1.size())
    }

    /// Whether the row buffer is full (the rows must be read back before another sample).
    pub fn full(&self) -> bool {
        self.pending.len() as u64 >= ROW_CAPACITY
    }

    /// Records into `pass` a sample of the state `read` (after its density stage) taken after
    /// `step` steps.
    pub(super) fn record(&mut self, pass: &mut wgpu::ComputePass<'static>, read: usize, step: u64) {
        if self.room(step) {
            self.record_points(pass, read);
            self.record_particles(pass, read, step);
        }
    }

    /// Whether the row buffer has room for the sample of `step` (it warns once when not).
    pub(super) fn room(&mut self, step: u64) -> bool {
        if self.full() {
            // Only a caller that steps without ever reading the samples gets here.
            if !self.warned_full {
                log::warn!("the probes' row buffer is full: samples from step {step} on are not taken until the rows are read");
                self.warned_full = true;
            }
            return false;
        }
        true
    }

    /// The first part of a sample ([`GpuProbes::room`] first): its row's head (the step and
    /// the time the sample is taken at, before a DFSPH step's choice of dt advances them), the
    /// point probes and gauges.
    pub(super) fn record_points(&self, pass: &mut wgpu::ComputePass<'static>, read: usize) {
        pass.set_pipeline(&self.points.pipeline);
        pass.set_bind_group(0, &self.groups[read][0], &[]);
        pass.dispatch_workgroups(self.probe_count.div_ceil(self.points.threads_per_group), 1, 1);
    }

    /// The rest of a sample of `step`: the force and front probes (under DFSPH after the solves,
    /// the push's pressure first) and the row.
    pub(super) fn record_particles(&mut self, pass: &mut wgpu::ComputePass<'static>, read: usize, step: u64) {
        let g = &self.groups[read];
        if let Some((push, _, groups, size)) = &self.push {
            pass.set_pipeline(&push.pipeline);
            pass.set_bind_group(0, &groups[read], &[]);
            pass.dispatch_workgroups(size.0, size.1, 1);
        }
        if let Some(particles) = &self.particles {
            pass.set_pipeline(&particles.pipeline);
            pass.set_bind_group(0, &g[1], &[]);
            pass.dispatch_workgroups(self.particle_groups.0, self.particle_groups.1, 1);
        }
        pass.set_pipeline(&self.finish.pipeline);
        pass.set_bind_group(0, &g[2], &[]);
        pass.dispatch_workgroups(1, 1, 1);
        self.pending.push(step);
    }

    /// Reads the pending rows back into `samples` and empties the row buffer. With a fixed
    /// `dt` the host knows each row's time; with adaptive dt it is the device's.
    pub(super) fn read_rows(&mut self, ctx: &GpuContext, params: &Params) -> anyhow::Result<()> {
        if self.pending.is_empty() {
            return Ok(());
        }
        let width = ROW_HEAD + self.values;
        let rows = self.pending.len() as u64;
        let data = read_ranges(ctx, &[(&self.data, 0, 4), (&self.data, (1 + self.rows_at) * 4, rows * width * 4)])?;
        let written = u32::from_le_bytes(data[0][..4].try_into().expect("4 bytes"));
        anyhow::ensure!(written as u64 == rows, "the GPU wrote {written} probe rows; {rows} were recorded");
        let words: Vec<u32> = bytemuck::pod_collect_to_vec(&data[1]);
        for (row, &step) in words.chunks_exact(width as usize).zip(&self.pending) {
            anyhow::ensure!(row[0] as u64 == step % (1 << 32), "a probe row holds step {}; step {step} was recorded", row[0]);
            let (time, previous_time) = match params.adaptive {
                Some(_) => {
                    let t = TimeSum::from_words([row[1], row[2], row[3]]).seconds();
                    (t, if step == 0 { 0.0 } else { t - status::float(row, 4) })
                }
                None => (step as f64 * params.dt, step.saturating_sub(1) as f64 * params.dt),
            };
            let values = row[ROW_HEAD as usize..].iter().map(|&w| f32::from_bits(w) as f64).collect();
            self.samples.push(ProbeSample { step, time, previous_time, values });
        }
        self.pending.clear();
        ctx.queue.write_buffer(&self.data, 0, &0u32.to_le_bytes());
        Ok(())
    }

    /// Forgets every row (a restored state continues from its own step).
    pub(super) fn reset(&mut self, ctx: &GpuContext) {
        self.pending.clear();
        self.samples.clear();
        ctx.queue.write_buffer(&self.data, 0, &0u32.to_le_bytes());
    }
}

#[cfg(test)]
mod tests {
    /// The sizes the host lays the data buffer out by are those the shader writes it by.
    #[test]
    fn the_row_layout_is_the_same_on_both_sides() {
        let wgsl = super::super::shaders::source("sim/probes.wgsl").expect("the probe stage");
        for (name, value) in [("PROBE_WORKGROUP", super::PROBE_WORKGROUP as u64), ("FORCE_SLOTS", super::FORCE_SLOTS), ("FRONT_SLOTS", super::FRONT_SLOTS), ("PROBE_ROW_HEAD", super::ROW_HEAD)] {
            assert!(wgsl.contains(&format!("const {name}: u32 = {value}u;")), "{name} is not {value} in probes.wgsl");
        }
    }
}
