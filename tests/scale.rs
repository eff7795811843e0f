//! Big scenes: the GPU memory plan checked before allocating, and snapshots streamed in pieces.

mod common;

use std::process::Command;
use wgsph::gpu::memory::MemoryPlan;
use wgsph::gpu::GpuSolver;
use wgsph::scene::Scene;

#[test]
fn the_memory_figure_is_the_plan_and_matches_the_buffers_created() {
    for ctx in common::contexts() {
        // With walls (dam_break's tank) and without (the seed scene's planes).
        for name in ["dam_break", "seed"] {
            let scene = Scene::load(name).unwrap().with_fluid_particles(600);
            let (params, initial) = (scene.params(), scene.initial_state());
            let solver = GpuSolver::new(ctx.clone(), &params, &initial).unwrap();
            let plan = MemoryPlan::new(
                initial.fluid_positions.len() as u64,
                Some(initial.wall_positions.len() as u64),
                params.grid.cell_count() as u64,
                wgsph::gpu::solver::GpuParams::default().bytes().len() as u64,
            );
            assert_eq!(solver.memory_bytes(), plan.total(), "{name} on {}", ctx.describe());
            assert_eq!(solver.allocated_bytes(), plan.total(), "{name} on {}", ctx.describe());
        }
    }
}

#[test]
fn a_plan_over_the_binding_limit_is_refused_naming_adapter_particles_bytes_and_limit() {
    for ctx in common::contexts() {
        let l = ctx.device.limits();
        let fit = (l.max_storage_buffer_binding_size as u64).min(l.max_buffer_size) / 16;
        assert!(MemoryPlan::new(fit, Some(0), 1000, 256).check(&ctx).is_ok(), "{} particles fit {}", fit, ctx.describe());
        let plan = MemoryPlan::new(fit + 1, Some(0), 1000, 256);
        let e = plan.check(&ctx).unwrap_err();
        let msg = e.to_string();
        assert_eq!((e.particles, e.total), (fit + 1, plan.total()));
        assert!(e.need > e.have && e.have == fit * 16, "{msg}");
        for part in [ctx.info.name.as_str(), &format!("{} fluid particles", fit + 1), &format!("{} bytes", plan.total()), e.limit] {
            assert!(msg.contains(part), "'{part}' missing from: {msg}");
        }
        assert!(msg.contains(&format!("at most {fit} fluid particles fit")), "{msg}");
    }
}

#[test]
fn particles_too_many_for_the_adapter_exit_2_before_allocating() {
    let Ok(adapter) = wgsph::gpu::device::choose_adapter() else {
        eprintln!("SKIPPED: no GPU adapter with compute shaders");
        return;
    };
    let l = adapter.limits();
    let fit = (l.max_storage_buffer_binding_size as u64).min(l.max_buffer_size) / 16;
    let n = fit + fit / 4;
    let scene = Scene::load("hydrostatic").unwrap().with_fluid_particles(n);
    if let Err(e) = scene.validate(&wgsph::scene::SceneOrigin::Text) {
        // On a GPU with a large binding limit the host refuses such a scene first.
        eprintln!("SKIPPED: {n} particles do not fit this host either: {e}");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_wgsph"))
        .args(["run", "hydrostatic", "--particles", &n.to_string(), "--steps", "1", "--backend", "gpu", "--out", "o"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    let name = adapter.get_info().name;
    assert!(err.contains(&name) && err.contains("fluid particles") && err.contains("bytes") && err.contains("at most"), "{err}");
    assert!(err.contains("max_storage_buffer_binding_size") || err.contains("max_buffer_size"), "{err}");
    assert!(!dir.path().join("o/snapshots/step_000000.csv").exists());
}

#[test]
fn streamed_csv_snapshots_equal_the_whole_array_ones_byte_for_byte() {
    use wgsph::sim::Backend;
    for ctx in common::contexts() {
        let scene = Scene::load("dam_break").unwrap().with_fluid_particles(700);
        let mut solver = GpuSolver::new(ctx.clone(), &scene.params(), &scene.initial_state()).unwrap();
        solver.step(5).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let whole = dir.path().join("whole.csv");
        let snapshot = solver.snapshot().unwrap();
        wgsph::output::write_snapshot_csv(&whole, &snapshot).unwrap();
        let expected = std::fs::read(&whole).unwrap();
        // 7: pieces that split every array unevenly and more than MAX_PASSES passes' worth of
        // pieces; 1 << 20: one piece, one pass.
        for chunk in [1, 7, 64, wgsph::gpu::solver::STREAM_CHUNK] {
            let path = dir.path().join(format!("streamed_{chunk}.csv"));
            let s = solver.write_snapshot_csv_streamed(&path, chunk).unwrap();
            assert_eq!(std::fs::read(&path).unwrap(), expected, "chunk {chunk} on {}", ctx.describe());
            assert_eq!((s.step, s.particles), (5, snapshot.len() as u64));
            assert_eq!(s.max_speed, snapshot.max_speed());
        }
    }
}
