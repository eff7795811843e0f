//! `wgsph profile`: stage times on every adapter, the pair count against brute force, the
//! profiled step against the normal step, and the command with its JSON file.

use crate::common;

use std::process::Command;
use wgsph::solver::gpu::schedule::{ProfiledStage, PROFILED_STAGES};
use wgsph::solver::gpu::GpuOptions;
use wgsph::app::profile::neighbour_pairs;
use wgsph::app::profile::profile;
use wgsph::app::profile::Profile;
use wgsph::app::profile::FUSED_STAGE_NAMES;
use wgsph::model::scene::Scene;

fn small_dam_break() -> Scene {
    Scene::builtin("dam_break").unwrap().with_fluid_particles(600)
}

#[test]
fn stage_times_are_positive_and_shares_sum_to_100() {
    let scene = small_dam_break();
    for (ctx, fuse) in common::contexts().into_iter().flat_map(|c| [(c.clone(), true), (c, false)]) {
        let adapter = ctx.describe();
        let timestamps = ctx.device.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        let p = profile(ctx, &scene, 3, GpuOptions { fuse_forces_and_integration: Some(fuse), ..Default::default() }).unwrap();
        let names: Vec<&str> = p.stages.iter().map(|s| s.stage.as_str()).collect();
        if timestamps {
            assert_eq!(p.timing, "timestamp queries", "{adapter}");
            assert_eq!(names, if fuse { FUSED_STAGE_NAMES } else { PROFILED_STAGES }, "{adapter}");
        } else {
            assert_eq!(names, ["step"], "{adapter}");
        }
        for s in &p.stages {
            assert!(s.time_us > 0.0 && s.time_us.is_finite(), "{adapter}: {s:?}");
            assert!(s.bytes_per_step > 0 && s.bandwidth_gb_s > 0.0, "{adapter}: {s:?}");
        }
        let shares: f64 = p.stages.iter().map(|s| s.share_percent).sum();
        assert!((shares - 100.0).abs() < 1e-6, "{adapter}: shares sum to {shares}");
        let total: f64 = p.stages.iter().map(|s| s.time_us).sum();
        assert!((total - p.step_time_us).abs() <= 1e-9 * total, "{adapter}");
        let n = p.fluid_particles as f64;
        assert!((p.particle_steps_per_second - n / (p.step_time_us * 1e-6)).abs() <= 1e-6 * p.particle_steps_per_second);
        assert!(p.neighbour_pairs > p.fluid_particles, "{adapter}: {} pairs", p.neighbour_pairs);
        assert!(p.gpu_memory_bytes > 0 && (p.gpu_bytes_per_particle - p.gpu_memory_bytes as f64 / n).abs() < 1e-9);
        // The buffers add up to the total (no probes here), the particle state the largest part.
        assert_eq!(p.gpu_memory_by_buffer.iter().map(|b| b.bytes).sum::<u64>(), p.gpu_memory_bytes, "{adapter}");
        let state: u64 = p.gpu_memory_by_buffer.iter().filter(|b| b.buffer.starts_with("particle state") || b.buffer.starts_with("positions") || b.buffer.starts_with("velocities")).map(|b| b.bytes).sum();
        assert!(state >= 48 * p.fluid_particles, "{adapter}: {state} bytes of state");
    }
}

/// With surface tension the normals stage is a row of its own between the density and the
/// forces (fused and in two passes), with its time and its bytes.
#[test]
fn the_surface_normals_are_a_row_of_their_own() {
    let mut scene = small_dam_break();
    scene.physics.surface_tension = 0.05;
    for (ctx, fuse) in common::contexts().into_iter().flat_map(|c| [(c.clone(), true), (c, false)]) {
        if !ctx.device.features().contains(wgpu::Features::TIMESTAMP_QUERY) {
            continue;
        }
        let adapter = ctx.describe();
        let p = profile(ctx, &scene, 3, GpuOptions { fuse_forces_and_integration: Some(fuse), ..Default::default() }).unwrap();
        let names: Vec<&str> = p.stages.iter().map(|s| s.stage.as_str()).collect();
        let mut expected = if fuse { FUSED_STAGE_NAMES } else { PROFILED_STAGES }.to_vec();
        expected.insert(5, "surface_normals");
        assert_eq!(names, expected, "{adapter}");
        let normals = &p.stages[5];
        assert!(normals.time_us > 0.0 && normals.bytes_per_step > 0, "{adapter}: {normals:?}");
        let shares: f64 = p.stages.iter().map(|s| s.share_percent).sum();
        assert!((shares - 100.0).abs() < 1e-6, "{adapter}: shares sum to {shares}");
    }
}

/// The profiled recording runs the same dispatches as the normal step, only split into passes.
#[test]
fn profiled_steps_match_normal_steps() {
    let scene = small_dam_break();
    for (ctx, fuse) in common::contexts().into_iter().flat_map(|c| [(c.clone(), true), (c, false)]) {
        if !ctx.device.features().contains(wgpu::Features::TIMESTAMP_QUERY) {
            continue;
        }
        let options = GpuOptions { fuse_forces_and_integration: Some(fuse), ..Default::default() };
        let mut normal = common::gpu_with(ctx.clone(), &scene, None, options).unwrap();
        let mut profiled = common::gpu_with(ctx.clone(), &scene, None, options).unwrap();
        normal.advance(4);
        let times = profiled.profile_stages(4).unwrap().expect("the device has timestamps");
        assert!(times.iter().all(|&(_, t)| t > 0.0), "{times:?}");
        use wgsph::Backend;
        assert_eq!(profiled.steps_done(), 4);
        let (a, b) = (normal.snapshot().unwrap(), profiled.snapshot().unwrap());
        assert_eq!(a.positions, b.positions, "{}", ctx.describe());
        assert_eq!(a.velocities, b.velocities, "{}", ctx.describe());
    }
}

/// A DFSPH step profiled ends its solves as a normal one does (the timed recorder submits and
/// waits at each block's end, each solve timed in segments): the same bits after the same
/// steps, whichever way the loop ends, and both solves timed.
#[test]
fn profiled_dfsph_steps_match_normal_steps_whichever_way_the_loop_ends() {
    use wgsph::solver::gpu::SolverLoop;
    use wgsph::Backend;
    let scene = common::TestScene::small_tank().dfsph().build();
    for ctx in common::contexts() {
        if !ctx.device.features().contains(wgpu::Features::TIMESTAMP_QUERY) {
            continue;
        }
        for solver_loop in [SolverLoop::Adaptive, SolverLoop::Indirect, SolverLoop::Readback(2)] {
            let options = GpuOptions { solver_loop, ..Default::default() };
            let mut normal = common::gpu_with(ctx.clone(), &scene, None, options).unwrap();
            let mut profiled = common::gpu_with(ctx.clone(), &scene, None, options).unwrap();
            normal.advance(4);
            let times = profiled.profile_stages(4).unwrap().expect("the device has timestamps");
            let what = format!("{} with {solver_loop:?}", ctx.describe());
            // bin_count .. dfsph_integrate: every stage ran, the two solves included.
            let rows: Vec<_> = times.iter().map(|&(stage, _)| stage).collect();
            assert_eq!(rows, ProfiledStage::DFSPH, "{what}");
            assert!(times.iter().all(|&(_, t)| t > 0.0), "{what}: {times:?}");
            assert_eq!(profiled.steps_done(), 4);
            let (a, b) = (normal.snapshot().unwrap(), profiled.snapshot().unwrap());
            assert_eq!(a.positions, b.positions, "{what}");
            assert_eq!(a.velocities, b.velocities, "{what}");
        }
    }
}

#[test]
fn neighbour_pairs_match_brute_force() {
    let scene = small_dam_break();
    let (params, initial) = (scene.params(), scene.initial_state());
    let h2 = params.h * params.h;
    let d2 = |a: &[f64; 3], b: &[f64; 3]| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>();
    let f = &initial.fluid_positions;
    let mut brute = 0u64;
    for i in 0..f.len() {
        brute += (i + 1..f.len()).filter(|&j| d2(&f[i], &f[j]) < h2).count() as u64;
        brute += initial.wall_positions.iter().filter(|w| d2(&f[i], w) < h2).count() as u64;
    }
    assert!(brute > 0);
    assert_eq!(neighbour_pairs(&params, f, &initial.wall_positions), brute);
    // Walls alone add their pairs: without them only the fluid pairs remain.
    let fluid_only = neighbour_pairs(&params, f, &[]);
    assert!(fluid_only < brute);
}

#[test]
fn profile_command_prints_the_table_and_writes_json() {
    if common::contexts().is_empty() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_wgsph"))
        .args(["profile", "dam_break", "--particles", "500", "--steps", "2", "--out", "p/profile.json"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("interactions/s (PIPS)") && text.contains("bytes per fluid particle"), "{text}");
    let p: Profile = serde_json::from_str(&std::fs::read_to_string(dir.path().join("p/profile.json")).unwrap()).unwrap();
    assert_eq!(p.scene, "dam_break");
    assert_eq!(p.steps, 2);
    // The driver that ran it, as one of the adapters reports it, in the file and the table.
    let drivers: Vec<String> = common::contexts().iter().map(|c| c.driver()).collect();
    assert!(drivers.contains(&p.driver), "{} is none of {drivers:?}", p.driver);
    assert_eq!(text.lines().any(|l| l == format!("driver: {}", p.driver)), !p.driver.is_empty(), "{text}");
    for s in &p.stages {
        assert!(text.contains(&s.stage), "{} missing from the table", s.stage);
    }
    if p.timing == "timestamp queries" {
        let names: Vec<&str> = p.stages.iter().map(|s| s.stage.as_str()).collect();
        // The default: two passes on a software adapter, one on a hardware one.
        let software = p.adapter.contains("Cpu)");
        assert_eq!(names, if software { PROFILED_STAGES } else { FUSED_STAGE_NAMES });
    }
}

#[test]
fn profile_command_rejects_zero_particles_and_steps() {
    for args in [["profile", "--particles", "0"], ["profile", "--steps", "0"]] {
        let out = Command::new(env!("CARGO_BIN_EXE_wgsph")).args(args).output().unwrap();
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(args[1]), "{err}");
    }
}
