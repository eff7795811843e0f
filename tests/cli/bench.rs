//! `wgsph bench`: the peers' block workload, timed on the paths asked for.

use std::process::Command;
use wgsph::app::bench::{block_scene, dfsph_block_scene};
use wgsph::model::scene::{BoundaryVolume, PressureSolver};

#[test]
fn the_block_workload_is_the_one_the_peers_were_measured_on() {
    // 30^3 fluid particles; the container's two wall layers (the first on the walls at x = 0
    // and 2L, y = 0 and 1.5L, z = 0 and L + dx) hold 24,936 particles.
    let scene = block_scene(30);
    let initial = scene.initial_state();
    assert_eq!(initial.fluid_positions.len(), 27_000);
    assert_eq!(initial.wall_positions.len(), 24_936);
    let lowest = initial.fluid_positions.iter().map(|x| x[0]).fold(f64::INFINITY, f64::min);
    assert!((lowest - 0.02).abs() < 1e-12, "the first fluid particle at (i + 1) dx: {lowest}");
    let p = scene.params();
    assert_eq!((p.h, p.dt, p.stiffness, p.clamp_negative_pressure), (0.04, 0.0004, 50_000.0, true));
    // DFSPH's: the same particles, steps of 1 ms, one wall layer (on the walls: 61 x 46 x 32
    // lattice points on the box's faces) with Akinci's volumes, 0.01 % density error.
    let dfsph = dfsph_block_scene(30);
    dfsph.validate(&wgsph::model::scene::SceneOrigin::Text).unwrap();
    let dfsph_initial = dfsph.initial_state();
    assert_eq!(dfsph_initial.fluid_positions, initial.fluid_positions);
    assert_eq!(dfsph_initial.wall_positions.len(), 61 * 46 * 32 - 59 * 44 * 30);
    let lowest_wall = dfsph_initial.wall_positions.iter().map(|x| x[0]).fold(f64::INFINITY, f64::min);
    assert!(lowest_wall.abs() < 1e-12, "the wall layer on the wall at x = 0: {lowest_wall}");
    assert_eq!((dfsph.physics.solver, dfsph.physics.boundary_volume, dfsph.time.dt), (PressureSolver::Dfsph, BoundaryVolume::Akinci, 0.001));
    assert_eq!(dfsph.params().dfsph.unwrap().density_error, 1e-4);
}

#[test]
fn bench_times_each_path_asked_for_and_writes_the_figures() {
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("bench.json");
    let out = Command::new(env!("CARGO_BIN_EXE_wgsph"))
        .args(["bench", "--n", "6", "--steps", "3", "--paths", "cpu-f32,cpu-f64,dfsph-cpu-f32", "--out"])
        .arg(&json)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("cpu-f32") && stdout.contains("cpu-f64") && stdout.contains("dfsph-cpu-f32") && stdout.contains("p-steps/s"), "{stdout}");
    let rows: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let rows = rows.as_array().unwrap();
    assert_eq!(rows.len(), 3);
    // Iterations per step: DFSPH's only, at least one of each solve per step.
    for r in &rows[..2] {
        assert!(r["pressure_iterations_per_step"].is_null() && r["divergence_iterations_per_step"].is_null(), "{r}");
    }
    assert!(rows[2]["pressure_iterations_per_step"].as_f64().unwrap() >= 1.0, "{}", rows[2]);
    assert!(rows[2]["divergence_iterations_per_step"].as_f64().unwrap() >= 1.0, "{}", rows[2]);
    for r in rows {
        assert_eq!(r["fluid_particles"], 216);
        assert_eq!(r["steps"], 3);
        assert!(r["particle_steps_per_second"].as_f64().unwrap() > 0.0);
        // Linux gives the processor time of the timed steps, which took some.
        #[cfg(target_os = "linux")]
        assert!(r["cpu_seconds"].as_f64().unwrap() > 0.0, "{r}");
        // No peer figure was measured at n = 6.
        assert!(r["ratio_to_splishsplash"].is_null());
        // The CPU paths have no driver, so the table names none.
        assert_eq!(r["driver"], "", "{r}");
    }
    assert!(!stdout.contains("driver of"), "{stdout}");
    let bad = Command::new(env!("CARGO_BIN_EXE_wgsph")).args(["bench", "--paths", "cpu-f16"]).output().unwrap();
    assert_eq!(bad.status.code(), Some(2));
}

#[test]
fn the_gpu_path_runs_with_and_without_subgroup_tiles() {
    if crate::common::contexts().is_empty() {
        return;
    }
    for extra in [&[][..], &["--no-subgroup-tiles"][..]] {
        let out = Command::new(env!("CARGO_BIN_EXE_wgsph")).args(["bench", "--n", "6", "--steps", "3", "--paths", "gpu"]).args(extra).output().unwrap();
        assert!(out.status.success(), "{extra:?}: {}", String::from_utf8_lossy(&out.stderr));
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(stdout.lines().any(|l| l.starts_with("gpu ")), "{extra:?}: {stdout}");
        // The adapter's name does not say which driver ran it (two Mesa releases' llvmpipe
        // share one); the line under the table does, as the adapter reports it.
        let drivers: Vec<String> = crate::common::contexts().iter().map(|c| c.driver()).filter(|d| !d.is_empty()).collect();
        if !drivers.is_empty() {
            let line = stdout.lines().find(|l| l.starts_with("driver of ")).unwrap_or_else(|| panic!("{extra:?}: no driver line: {stdout}"));
            assert!(drivers.iter().any(|d| line.ends_with(&format!(": {d}"))), "{line} names none of {drivers:?}");
        }
    }
}

#[test]
fn flags_for_paths_not_asked_for_are_refused_by_name() {
    // A flag that tunes only paths left out of --paths would change nothing: exit code 2,
    // naming the flag and the paths it needs, before any path is timed.
    for (args, named) in [
        (&["--paths", "cpu-f32", "--no-neighbour-lists"][..], "--no-neighbour-lists tunes the GPU paths, and --paths cpu-f32 has no such path (gpu, dfsph-gpu)"),
        (&["--paths", "cpu-f64", "--every-adapter"][..], "--every-adapter"),
        (&["--paths", "gpu", "--threads", "2"][..], "--threads sets the CPU paths' threads"),
        (&["--paths", "gpu,cpu-f32", "--solver-loop", "indirect"][..], "(dfsph-gpu)"),
        (&["--paths", "cpu-f32,dfsph-gpu", "--neighbour-skin", "0.1"][..], "--neighbour-skin tunes the weakly compressible GPU path"),
        (&["--paths", "cpu-f32,gpu,cpu-f32"][..], "--paths cpu-f32,gpu,cpu-f32 names cpu-f32 twice"),
    ] {
        let o = Command::new(env!("CARGO_BIN_EXE_wgsph")).args(["bench", "--n", "2", "--steps", "1"]).args(args).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(named), "{args:?}: {err}");
        assert!(o.stdout.is_empty(), "{args:?}: timed before refusing");
    }
}

/// `--out FILE.json` of `bench` and `profile` that cannot be written (a directory, a path under
/// a regular file) is refused before any work, naming the flag and the path; a file that can
/// be is written whole.
#[test]
fn an_unusable_out_file_is_refused_before_the_work() {
    let dir = tempfile::tempdir().unwrap();
    let plain = dir.path().join("notes.txt");
    std::fs::write(&plain, "mine").unwrap();
    let under_a_file = plain.join("b.json");
    let is_dir = dir.path().to_str().unwrap();
    for (command, path) in [("bench", is_dir), ("bench", under_a_file.to_str().unwrap()), ("profile", is_dir), ("profile", under_a_file.to_str().unwrap())] {
        let extra: &[&str] = if command == "bench" { &["--n", "2", "--steps", "1", "--paths", "cpu-f32"] } else { &["--particles", "500", "--steps", "1"] };
        let o = Command::new(env!("CARGO_BIN_EXE_wgsph")).arg(command).args(extra).args(["--out", path]).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{command} --out {path}: {err}");
        assert!(err.contains(&format!("--out {path}: ")) && err.contains("allowed:"), "{err}");
        assert!(o.stdout.is_empty(), "{command} --out {path}: worked before refusing");
    }
    assert_eq!(std::fs::read_to_string(&plain).unwrap(), "mine");
    let json = dir.path().join("bench.json");
    let o = Command::new(env!("CARGO_BIN_EXE_wgsph")).args(["bench", "--n", "2", "--steps", "1", "--paths", "cpu-f32", "--out", json.to_str().unwrap()]).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rows: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(rows[0]["path"], "cpu-f32");
    // Its own earlier output is replaced; a user's file of the same name is refused, untouched.
    let o = Command::new(env!("CARGO_BIN_EXE_wgsph")).args(["bench", "--n", "2", "--steps", "1", "--paths", "cpu-f64", "--out", json.to_str().unwrap()]).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rows: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(rows[0]["path"], "cpu-f64");
    let theirs = dir.path().join("results.json");
    for (command, text) in [("bench", "{\"mine\": 1}"), ("profile", "[{\"path\": \"x\"}]"), ("bench", "not json"), ("bench", "[]")] {
        std::fs::write(&theirs, text).unwrap();
        let extra: &[&str] = if command == "bench" { &["--n", "2", "--steps", "1", "--paths", "cpu-f32"] } else { &["--particles", "500", "--steps", "1"] };
        let o = Command::new(env!("CARGO_BIN_EXE_wgsph")).arg(command).args(extra).args(["--out", theirs.to_str().unwrap()]).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{command}: {err}");
        assert!(err.contains("exists and is not a") && err.contains("that wgsph wrote"), "{command}: {err}");
        assert!(o.stdout.is_empty(), "{command}: worked before refusing");
        assert_eq!(std::fs::read_to_string(&theirs).unwrap(), text, "{command}");
    }
}
