//! `wgsph profile`: the time of each compute stage of the GPU step, its share, an estimate of
//! the memory traffic it needs, and the particle interactions per second (PIPS).
//!
//! Stage times come from timestamp queries (one timed compute pass per stage) where the device
//! has `TIMESTAMP_QUERY`; elsewhere only whole steps are timed on the host (submit and wait).

use super::args::ProfileArgs;
use anyhow::Context;
use std::io::Write;
use crate::model::kernels::{sort_by_cell, KernelCoefficients};
use crate::model::params::Params;
use crate::model::real::V3;
use crate::model::scene::Scene;
use crate::solver::gpu::memory::MemoryPlan;
use crate::solver::gpu::schedule::ProfiledStage;
pub use crate::solver::gpu::schedule::FUSED_STAGE_NAMES;
use crate::solver::gpu::{GpuContext, GpuOptions};
use crate::solver::gpu::device::TILE_LANES;
use crate::solver::{open_with, Backend, BackendChoice};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// The status words one thread reads and writes after each step (wgsl/sim/integrate.wgsl
/// finish_step).
const BOOKKEEPING_BYTES: u64 = 24;

/// One row of the profile.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct StageProfile {
    pub stage: String,
    /// Mean time per step, microseconds.
    pub time_us: f64,
    /// Share of the step time, percent.
    pub share_percent: f64,
    /// Estimated bytes the stage reads and writes per step (see `stage_bytes`).
    pub bytes_per_step: u64,
    /// bytes_per_step / time: the effective memory bandwidth, GB/s (1e9 bytes).
    pub bandwidth_gb_s: f64,
}

/// One buffer of the GPU memory (or all buffers of one label).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct BufferMemory {
    pub buffer: String,
    pub bytes: u64,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct Profile {
    pub scene: String,
    pub adapter: String,
    /// The driver and its version, as the adapter reports them.
    #[serde(default)]
    pub driver: String,
    /// "timestamp queries" or "host (whole steps, submit and wait)".
    pub timing: String,
    /// How the neighbour stages walk the neighbours: "subgroup tiles of 8" (with ", and
    /// neighbour lists of N slots" and how full they were where the forces or DFSPH's solves
    /// walk lists) or "one particle per invocation".
    #[serde(default)]
    pub neighbour_loops: String,
    pub fluid_particles: u64,
    pub wall_particles: u64,
    pub grid_cells: u64,
    pub steps: u64,
    pub stages: Vec<StageProfile>,
    /// GPU time of a step (the sum of the stages) or, with host timing, its wall-clock time, µs.
    pub step_time_us: f64,
    /// Wall-clock time per step of the normal path (STEPS_PER_SUBMIT steps per submission,
    /// one wait at the end), µs.
    pub host_step_time_us: f64,
    /// Wall-clock time per step with a host round trip after every step (submit one step, wait
    /// for it), µs: what the normal path saves by not waiting.
    pub host_step_time_with_waits_us: f64,
    pub particle_steps_per_second: f64,
    /// Distinct pairs within the kernel support per step (fluid-fluid counted once, plus
    /// fluid-wall), the mean of the first and last state.
    pub neighbour_pairs: u64,
    /// neighbour_pairs / step_time: particle interactions per second (PIPS).
    pub interactions_per_second: f64,
    pub gpu_memory_bytes: u64,
    pub gpu_bytes_per_particle: f64,
    /// The GPU memory by buffer (the memory plan's labels, buffers of one label summed), in
    /// the plan's order; the probes' buffers are in the total only.
    #[serde(default)]
    pub gpu_memory_by_buffer: Vec<BufferMemory>,
    /// DFSPH: iterations per step of the constant-density and the divergence solve over the
    /// profiled steps (absent for WCSPH).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pressure_iterations_per_step: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub divergence_iterations_per_step: Option<f64>,
}

/// Bytes each stage of [`ProfiledStage::WCSPH`] must read and write per step, for `n` fluid particles,
/// `w` walls and `cells` grid cells: every array element the stage touches counted once (the
/// compulsory traffic; neighbour loads are assumed to hit the cache after their first load, so
/// this is a lower bound). `vec4<f32>` = 16 bytes, `u32`/`f32` = 4 bytes.
/// `fused`: the forces and the integration run as one pass (rows `forces_integrate` and
/// `bookkeeping`).
pub fn stage_bytes(n: u64, w: u64, cells: u64, adaptive: bool, fused: bool) -> [u64; 7] {
    let starts = (cells + 1) * 4;
    let walls = if w > 0 { w * 16 + starts } else { 0 };
    [
        // bin_count: positions in; keys and ranks out; one atomic read-modify-write of a count.
        n * 16 + n * 8 + n * 8,
        // prefix_sum: the cell counts read and written by the block scan and again by the
        // block-offset pass (the higher levels are 1/256 of that).
        4 * starts,
        // bin_scatter: keys, ranks and a cell start in; the unordered slot out.
        n * 12 + n * 4,
        // reorder: the rank reads keys, starts and slots and writes each destination; the two
        // gathers read the destinations and the state (position with id, velocity) and write it.
        n * 12 + n * 4 + n * 8 + n * 32 + n * 32,
        // density: positions and cell starts (and walls) in; density out (in the w of the
        // velocities, or its array with the continuity equation).
        n * 16 + starts + walls + n * 4,
        // forces: positions, velocities with the density in w, starts (and walls) in (the
        // pressure comes from the density; the continuity equation's density array is 4 bytes
        // more); accelerations out, or with fusion the new positions and velocities.
        n * 32 + starts + walls + if fused { n * 32 } else { n * 16 },
        // integrate: positions, velocities and accelerations in, positions and velocities out
        // (the accelerations and velocities read again by the adaptive reduction of |v|max and
        // |a|max); with fusion only the step's status words.
        if fused { BOOKKEEPING_BYTES } else { n * 80 + if adaptive { n * 32 } else { 0 } },
    ]
}

/// Bytes the surface normals stage must read and write per step (the row before the forces in
/// a scene with surface tension), counted as [`stage_bytes`] counts: positions, the densities
/// and the cell starts in, the normals out.
pub fn surface_normals_bytes(n: u64, cells: u64) -> u64 {
    n * 16 + n * 4 + (cells + 1) * 4 + n * 16
}

/// Bytes each stage of [`ProfiledStage::DFSPH`] must read and write per step, counted as
/// [`stage_bytes`] counts them, with `pressure` and `divergence` iterations per step (each
/// iteration a velocity change and a new error; the warm start one more pass of each).
pub fn dfsph_stage_bytes(n: u64, w: u64, cells: u64, adaptive: bool, viscous: bool, pressure: f64, divergence: f64) -> [u64; 9] {
    let base = stage_bytes(n, w, cells, adaptive, false);
    let starts = (cells + 1) * 4;
    let walls = if w > 0 { w * 16 + starts } else { 0 };
    // A pass computing D_i: positions, velocities, the wall gradient and the factor in, K out;
    // a velocity change: positions, K, the wall gradient, the velocity and the sum in and out.
    let rate = n * 56 + starts;
    let apply = n * 76 + starts;
    let solve = |iterations: f64| (rate as f64 + iterations * (rate + apply) as f64) as u64;
    [
        base[0],
        base[1],
        base[2],
        base[3],
        // Positions (and walls) in; density, pressure, factor, divergence sum and the wall
        // gradient out; the last stiffness read by id.
        n * 16 + starts + walls + n * 36 + n * 4,
        solve(divergence),
        // Velocities in, predicted velocities and the pressure sum out (with viscosity the
        // neighbours' positions and densities, with adaptive dt the accelerations twice).
        n * 36 + if viscous { n * 20 + starts + walls } else { 0 } + if adaptive { n * 32 } else { 0 },
        solve(pressure) + n * 4 * pressure.ceil() as u64,
        // Positions, velocities and the two sums in; positions, velocities and the two warm
        // starts out; the bookkeeping's status words.
        n * 80 + BOOKKEEPING_BYTES,
    ]
}

/// Distinct pairs of particles closer than the kernel support: fluid-fluid pairs counted once,
/// plus fluid-wall pairs (computed on the CPU in f64 with the same grid as the solver).
pub fn neighbour_pairs(params: &Params, fluid: &[[f64; 3]], walls: &[[f64; 3]]) -> u64 {
    let grid = params.grid;
    let h2 = KernelCoefficients::<f64>::new(params.kernel, params.h).h2;
    let sorted = |points: &[[f64; 3]]| {
        let p: Vec<V3<f64>> = points.iter().map(|&x| V3::from64(x)).collect();
        let (order, starts) = sort_by_cell(&grid, &p);
        (order.iter().map(|&i| p[i as usize]).collect::<Vec<_>>(), starts)
    };
    let (fp, fs) = sorted(fluid);
    let (wp, ws) = sorted(walls);
    (0..fp.len())
        .into_par_iter()
        .map(|i| {
            let xi = fp[i];
            let mut count = 0u64;
            for (k0, k1) in grid.stencil_runs(grid.cell_coords(xi)) {
                // j > i: each fluid pair once.
                for j in (fs[k0 as usize] as usize).max(i + 1)..fs[k1 as usize] as usize {
                    count += ((xi - fp[j]).length_squared() < h2) as u64;
                }
                if !wp.is_empty() {
                    for j in ws[k0 as usize] as usize..ws[k1 as usize] as usize {
                        count += ((xi - wp[j]).length_squared() < h2) as u64;
                    }
                }
            }
            count
        })
        .sum()
}

/// Profiles `steps` steps of `scene` on `ctx` (after 2 warm-up steps).
pub fn profile(ctx: GpuContext, scene: &Scene, steps: u64, options: GpuOptions) -> anyhow::Result<Profile> {
    // Before the particles are created on the host: a scene too big for the adapter fails at once.
    MemoryPlan::for_scene(scene).check(&ctx)?;
    let params = scene.params();
    let initial = scene.initial_state();
    let (n, w) = (initial.fluid_positions.len() as u64, initial.wall_positions.len() as u64);
    anyhow::ensure!(n > 0, "the scene {} has no fluid particles to profile", scene.name);
    let pairs_before = neighbour_pairs(&params, &initial.fluid_positions, &initial.wall_positions);
    let walls = initial.wall_positions.clone();
    let choice = BackendChoice::gpu_on(ctx).with_gpu_options(options);
    let mut gpu = open_with(scene, Some(initial), &choice)?.into_gpu().expect("a GPU was chosen");
    gpu.advance(2);
    gpu.wait()?;
    let cells = params.grid.cell_count() as u64;
    let before = gpu.health()?.iterations;
    let profiled_steps = gpu.steps_done();
    let per_step = |now: Option<crate::model::state::IterationStats>, steps: u64| {
        now.zip(before).map(|(a, b)| {
            let s = steps.max(1) as f64;
            ((a.pressure.total - b.pressure.total) as f64 / s, (a.divergence.total - b.divergence.total) as f64 / s)
        })
    };
    let rows = gpu.profiled_rows();
    let totals = gpu.profile_stages(steps)?;
    let iterations = per_step(gpu.health()?.iterations, gpu.steps_done() - profiled_steps);
    // The bytes of each row, counted by the method's own table.
    let adaptive = params.adaptive.is_some();
    let wcsph_bytes = stage_bytes(n, w, cells, adaptive, gpu.fused());
    let dfsph_bytes = iterations.map(|(p, d)| dfsph_stage_bytes(n, w, cells, adaptive, params.uses_viscosity(), p, d));
    let row_bytes = |stage: ProfiledStage| match (stage, &dfsph_bytes) {
        (ProfiledStage::SurfaceNormals, _) => surface_normals_bytes(n, cells),
        (stage, Some(dfsph)) => dfsph[ProfiledStage::DFSPH.iter().position(|&s| s == stage).expect("a DFSPH stage")],
        (stage, None) => wcsph_bytes[stage as usize],
    };

    let (timing, times_ns): (&str, Vec<(String, f64, u64)>) = match totals {
        Some(totals) => (
            "timestamp queries",
            totals.into_iter().map(|(stage, t)| (stage.name(gpu.fused()).to_string(), t / steps as f64, row_bytes(stage))).collect(),
        ),
        None => {
            let mut total = 0.0;
            for _ in 0..steps {
                let t = Instant::now();
                gpu.advance(1);
                gpu.wait()?;
                total += t.elapsed().as_secs_f64() * 1e9;
            }
            ("host (whole steps, submit and wait)", vec![("step".to_string(), total / steps as f64, rows.into_iter().map(row_bytes).sum())])
        }
    };
    let t = Instant::now();
    gpu.advance(steps);
    gpu.wait()?;
    let host_step_time_us = t.elapsed().as_secs_f64() * 1e6 / steps as f64;
    let t = Instant::now();
    for _ in 0..steps {
        gpu.advance(1);
        gpu.wait()?;
    }
    let host_step_time_with_waits_us = t.elapsed().as_secs_f64() * 1e6 / steps as f64;

    let health = gpu.health()?;
    anyhow::ensure!(
        health.non_finite == 0,
        "the profiled run went bad: {} non-finite values (first at step {:?})",
        health.non_finite,
        health.first_bad_step
    );
    let last = gpu.snapshot()?;
    let pairs_after = neighbour_pairs(&params, &last.positions, &walls);
    let neighbour_pairs = (pairs_before + pairs_after) / 2;

    let step_ns: f64 = times_ns.iter().map(|s| s.1).sum();
    anyhow::ensure!(step_ns > 0.0, "the adapter reported a step time of 0 (its timestamps do not advance)");
    let stages = times_ns
        .into_iter()
        .map(|(stage, ns, b)| StageProfile {
            stage,
            time_us: ns / 1e3,
            share_percent: 100.0 * ns / step_ns,
            bytes_per_step: b,
            bandwidth_gb_s: if ns > 0.0 { b as f64 / ns } else { 0.0 },
        })
        .collect();
    let memory = gpu.memory_bytes();
    let mut by_buffer: Vec<BufferMemory> = Vec::new();
    for b in &gpu.memory_plan().buffers {
        match by_buffer.iter_mut().find(|m| m.buffer == b.label) {
            Some(m) => m.bytes += b.bytes,
            None => by_buffer.push(BufferMemory { buffer: b.label.into(), bytes: b.bytes }),
        }
    }
    Ok(Profile {
        scene: scene.name.clone(),
        adapter: gpu.adapter(),
        driver: gpu.driver(),
        timing: timing.into(),
        neighbour_loops: match (gpu.subgroup_tiles(), gpu.neighbour_list_usage()?) {
            (true, Some(u)) => format!(
                "subgroup tiles of {TILE_LANES}, and neighbour lists of {} slots (after the last step: the longest used {}, {} of {n} full)",
                u.slots, u.longest, u.full
            ),
            (true, None) => format!("subgroup tiles of {TILE_LANES}"),
            _ => "one particle per invocation".to_string(),
        } + &match gpu.neighbour_skin() {
            Some((skin, rebuilds)) => format!("; a neighbour skin of {skin} h: {rebuilds} rebuilds in {} steps", gpu.steps_done()),
            None => String::new(),
        },
        fluid_particles: n,
        wall_particles: w,
        grid_cells: cells,
        steps,
        stages,
        step_time_us: step_ns / 1e3,
        host_step_time_us,
        host_step_time_with_waits_us,
        particle_steps_per_second: n as f64 / (step_ns * 1e-9),
        neighbour_pairs,
        interactions_per_second: neighbour_pairs as f64 / (step_ns * 1e-9),
        gpu_memory_bytes: memory,
        gpu_bytes_per_particle: memory as f64 / n as f64,
        gpu_memory_by_buffer: by_buffer,
        pressure_iterations_per_step: iterations.map(|i| i.0),
        divergence_iterations_per_step: iterations.map(|i| i.1),
    })
}

impl Profile {
    /// The table `wgsph profile` prints.
    pub fn table(&self) -> String {
        let mut s = format!(
            "{}: {} fluid + {} wall particles, {} cells, {} steps on {}\n",
            self.scene, self.fluid_particles, self.wall_particles, self.grid_cells, self.steps, self.adapter
        );
        if !self.driver.is_empty() {
            s += &format!("driver: {}\n", self.driver);
        }
        s += &format!("timing: {}\nneighbour loops: {}\n", self.timing, self.neighbour_loops);
        s += &format!("{:<16} {:>12} {:>8} {:>14} {:>10}\n", "stage", "µs/step", "share %", "bytes/step", "GB/s");
        for st in &self.stages {
            s += &format!(
                "{:<16} {:>12.1} {:>8.1} {:>14} {:>10.2}\n",
                st.stage, st.time_us, st.share_percent, st.bytes_per_step, st.bandwidth_gb_s
            );
        }
        s += &format!("{:<16} {:>12.1} {:>8.1}\n", "total", self.step_time_us, 100.0);
        s += &format!("host wall-clock per step (normal path): {:.1} µs\n", self.host_step_time_us);
        s += &format!("host wall-clock per step with a wait after every step: {:.1} µs\n", self.host_step_time_with_waits_us);
        s += &format!("particle-steps/s: {:.3e}\n", self.particle_steps_per_second);
        s += &format!("neighbour pairs per step: {}; interactions/s (PIPS): {:.3e}\n", self.neighbour_pairs, self.interactions_per_second);
        s += &format!("GPU memory: {} bytes, {:.2} bytes per fluid particle\n", self.gpu_memory_bytes, self.gpu_bytes_per_particle);
        // The buffers' share per fluid particle, the larger ones (the rest summed).
        let n = self.fluid_particles.max(1) as f64;
        let (large, small): (Vec<&BufferMemory>, Vec<&BufferMemory>) = self.gpu_memory_by_buffer.iter().partition(|b| b.bytes as f64 / n >= 0.01);
        let mut parts: Vec<String> = large.iter().map(|b| format!("{} {:.2}", b.buffer, b.bytes as f64 / n)).collect();
        let rest: u64 = small.iter().map(|b| b.bytes).sum();
        if rest > 0 {
            parts.push(format!("the rest {rest} bytes"));
        }
        if !parts.is_empty() {
            s += &format!("  by buffer, bytes per fluid particle: {}\n", parts.join(", "));
        }
        if let (Some(p), Some(d)) = (self.pressure_iterations_per_step, self.divergence_iterations_per_step) {
            s += &format!("DFSPH iterations per step: constant density {p:.2}, divergence {d:.2}\n");
        }
        s += "bytes/step: compulsory traffic estimated from the arrays each stage reads and writes (a lower bound)\n";
        s
    }
}

pub fn cmd_profile(args: &ProfileArgs) -> anyhow::Result<i32> {
    let scene = super::args::load_scene(&args.scene, &args.overrides, args.particles, false)?;
    args.tuning.check_scene(&scene.params())?;
    let ours = |text: &str| serde_json::from_str::<Profile>(text).is_ok();
    let file = args.out.as_deref().map(|p| super::errors::output_file("--out", p, "a profile", &ours)).transpose()?;
    let options = GpuOptions { single_cells: args.single_cells, ..args.tuning.options() };
    let profile = profile(GpuContext::new()?, &scene, args.steps, options)?;
    print!("{}", profile.table());
    if let Some(mut file) = file {
        let path = file.path().to_path_buf();
        serde_json::to_writer_pretty(&mut file, &profile)?;
        writeln!(file).with_context(|| format!("cannot write {}", path.display()))?;
        file.commit()?;
        println!("wrote {}", path.display());
    }
    Ok(0)
}
