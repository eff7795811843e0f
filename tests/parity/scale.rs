//! Big scenes: the GPU memory plan checked before allocating, arrays bound in segments (forced
//! on at small sizes), and snapshots streamed in pieces.

use crate::common;
use crate::common::TestScene;

use std::process::Command;
use wgsph::solver::gpu::memory::{MemoryPlan, StepArrays};
use wgsph::solver::gpu::buffers::WallCellIndex;
use wgsph::solver::gpu::GpuOptions;
use wgsph::model::kernels::sort_by_cell;
use wgsph::model::real::V3;
use wgsph::model::scene::{EquationOfState, Kernel, Scene};

#[test]
fn the_memory_figure_is_the_plan_and_matches_the_buffers_created() {
    for ctx in common::contexts() {
        // With walls (dam_break's tank) and without (the seed scene's planes); the weakly
        // compressible step in place and fused, and DFSPH (in place, with its own arrays).
        let dam_break = Scene::load("dam_break").unwrap().with_fluid_particles(600);
        let mut dfsph = TestScene::small_tank().dfsph().build();
        dfsph.name = "dfsph".into();
        for (scene, fused) in [(dam_break.clone(), false), (dam_break, true), (Scene::load("seed").unwrap().with_fluid_particles(600), false), (dfsph, false)] {
            let (params, initial) = (scene.params(), scene.initial_state());
            let options = GpuOptions { fuse_forces_and_integration: Some(fused), ..Default::default() };
            let solver = common::gpu_with(ctx.clone(), &scene, None, options).unwrap();
            let n = initial.fluid_positions.len() as u64;
            let is_dfsph = params.dfsph.is_some();
            let plan = MemoryPlan::new(
                n,
                Some(initial.wall_positions.len() as u64),
                params.grid.cell_count() as u64,
                wgsph::solver::gpu::params::GpuParams::default().bytes().len() as u64,
                StepArrays::new(is_dfsph, false, false, fused),
            );
            // The wall cell starts are kept for the cells that hold walls.
            let walls: Vec<V3<f32>> = initial.wall_positions.iter().map(|&x| V3::from64(x)).collect();
            let (_, starts) = sort_by_cell(&params.grid.cast::<f32>(), &walls);
            let kept = if walls.is_empty() { 0 } else { WallCellIndex::new(&starts).firsts.len() as u64 };
            let plan = plan.with_wall_cell_starts(kept);
            // On an adapter with subgroup tiles the step keeps neighbour lists (none fused).
            let capacity = solver.neighbour_list_capacity();
            assert_eq!(capacity.is_some(), solver.subgroup_tiles() && !fused, "{} on {}", scene.name, ctx.describe());
            let plan = if is_dfsph { plan.with_dfsph(n) } else { plan }.with_neighbour_lists(n, capacity.unwrap_or(0));
            let name = &scene.name;
            assert_eq!(solver.fused(), fused);
            assert_eq!(solver.memory_bytes(), plan.total(), "{name} on {}", ctx.describe());
            assert_eq!(solver.allocated_bytes(), plan.total(), "{name} on {}", ctx.describe());
        }
    }
}

#[test]
fn the_wall_cell_index_gives_every_cell_start_of_the_dense_array() {
    // Empty cells at the ends and between, a cell count on and off the block size, and more
    // than one block.
    for cells in [1usize, 31, 32, 33, 64, 100] {
        let counts: Vec<u32> = (0..cells).map(|c| if c % 7 == 3 || c == cells - 1 { (c % 3 + 1) as u32 } else { 0 }).collect();
        let mut starts = vec![0u32];
        for &k in &counts {
            starts.push(starts.last().unwrap() + k);
        }
        let index = WallCellIndex::new(&starts);
        assert_eq!(index.firsts.len(), counts.iter().filter(|&&k| k > 0).count() + 1);
        for (c, &start) in starts.iter().enumerate() {
            assert_eq!(index.start(c), start, "cell {c} of {cells}");
        }
    }
}

#[test]
fn a_plan_over_the_buffer_limit_is_refused_naming_adapter_particles_bytes_and_limit() {
    for ctx in common::contexts() {
        // Arrays are bound in segments, so only max_buffer_size bounds one array.
        let fit = ctx.device.limits().max_buffer_size / 16;
        assert!(MemoryPlan::new(fit, Some(0), 1000, 256, StepArrays::new(false, false, false, false)).check(&ctx).is_ok(), "{} particles fit {}", fit, ctx.describe());
        let plan = MemoryPlan::new(fit + 1, Some(0), 1000, 256, StepArrays::new(false, false, false, false));
        let e = plan.check(&ctx).unwrap_err();
        let msg = e.to_string();
        assert_eq!((e.particles, e.total), (fit + 1, plan.total()));
        assert!(e.need > e.have && e.have == ctx.device.limits().max_buffer_size, "{msg}");
        for part in [ctx.info.name.as_str(), &format!("{} fluid particles", fit + 1), &format!("{} bytes", plan.total()), "max_buffer_size"] {
            assert!(msg.contains(part), "'{part}' missing from: {msg}");
        }
        assert!(msg.contains(&format!("at most {fit} fluid particles fit")), "{msg}");
    }
}

/// The smallest segment: 4096 vec4 or 16384 u32 values per binding.
const SMALL_SEGMENT: u64 = wgsph::solver::gpu::device::MIN_SEGMENT_BYTES;

#[test]
fn arrays_bound_in_segments_step_bit_for_bit_like_whole_arrays() {
    use wgsph::solver::Backend;
    for ctx in common::contexts() {
        let split_ctx = ctx.clone().with_storage_segment_bytes(SMALL_SEGMENT).unwrap();
        // The small tank in a longer domain with a larger block: its fluid vec4 arrays, the cell
        // arrays and the walls in 2 segments or more, within OpenGL's 16 storage buffers per stage.
        let scene = TestScene::small_tank()
            .domain([-0.1; 3], [1.5, 0.9, 0.7])
            .without_fluid()
            .fluid([0.0; 3], [0.44, 0.4, 0.2])
            .jitter(0.1)
            .moving_at([0.3, 0.0, 0.0])
            .build();
        let (params, initial) = (scene.params(), scene.initial_state());
        let n = initial.fluid_positions.len() as u64;
        let cells = params.grid.cell_count() as u64 + 1;
        let walls = initial.wall_positions.len() as u64;
        assert!(n * 16 > SMALL_SEGMENT && cells * 4 > SMALL_SEGMENT && walls * 16 > SMALL_SEGMENT, "{n} fluid, {cells} cells, {walls} walls");
        let mut whole = common::gpu(ctx.clone(), &scene);
        let mut split = common::gpu(split_ctx, &scene);
        for solver in [&mut whole, &mut split] {
            solver.step(40).unwrap();
        }
        let (a, b) = (whole.snapshot().unwrap(), split.snapshot().unwrap());
        assert!(a.positions == b.positions && a.velocities == b.velocities, "{}: states differ", ctx.describe());
        assert!(a.densities == b.densities && a.pressures == b.pressures, "{}: fields differ", ctx.describe());
        let (fa, fb) = (whole.step_fields().unwrap(), split.step_fields().unwrap());
        assert!(fa.accelerations == fb.accelerations, "{}: accelerations differ", ctx.describe());
        assert_eq!(whole.health().unwrap(), split.health().unwrap());
        // The particles moved: the comparison is not one of two initial states.
        assert!(a.positions != initial.fluid_positions);
    }
}

#[test]
fn prefix_sum_in_segments_is_exact() {
    use wgsph::solver::cpu::prefix_sum::prefix_sum;
    for ctx in common::contexts() {
        let ctx = ctx.with_storage_segment_bytes(SMALL_SEGMENT).unwrap();
        // One segment exactly, one value more, and several segments with a partial last one.
        for n in [16_383usize, 16_384, 70_001] {
            let counts: Vec<u32> = (0..n).map(|i| ((i as u64 * 2654435761) % 7) as u32).collect();
            let mut expected = vec![0u32; n + 1];
            prefix_sum(&counts, &mut expected);
            let got = wgsph::solver::gpu::prefix_sum::exclusive_scan(&ctx, &counts).unwrap();
            assert!(got == expected, "{}: scan of {n} values in segments differs", ctx.describe());
        }
    }
}

#[test]
fn too_many_segments_for_the_adapter_are_refused_before_allocating() {
    for ctx in common::contexts() {
        let have = ctx.device.limits().max_storage_buffers_per_shader_stage as u64;
        let ctx = ctx.with_storage_segment_bytes(SMALL_SEGMENT).unwrap();
        // The reorder binds four vec4 arrays: with this many segments each it cannot fit (nor,
        // with the walls split too, the density).
        let mut n = 4096 * (have / 4 + 1);
        // Where one array of that many particles is already beyond the adapter's buffer size
        // (adapters with hundreds of thousands of bindings per stage), the buffer limit refuses
        // first: the binding count cannot be reached, and the refusal names the buffer limit.
        // Then 5 % past that limit is enough (the lattice rounds the count), and keeps the scene
        // within a host's memory.
        let max_buffer = ctx.device.limits().max_buffer_size;
        let reachable = n * 16 <= max_buffer;
        if !reachable {
            eprintln!("{}: {have} bindings per stage are beyond its buffer size; checking that refusal instead", ctx.describe());
            n = max_buffer / 16 / 20 * 21;
        }
        let scene = Scene::load("dam_break").unwrap().with_fluid_particles(n);
        // Past the limit before the solver is asked: a scene under it would be generated and
        // allocated, which is not what this test is for.
        assert!(reachable || scene.fluid_particle_count() * 16 > max_buffer, "the scene is past the buffer limit");
        let e = common::gpu_with(ctx.clone(), &scene, None, Default::default()).err().expect("refused");
        let msg = format!("{e:#}");
        if msg.contains("of host memory") {
            // A host too small for the scene refuses it before any adapter is asked: also a
            // refusal before allocating, naming the count and the memory.
            eprintln!("{}: refused by the host's memory first: {msg}", ctx.describe());
            assert!(msg.contains("particles (fluid and walls)") && msg.contains("MiB are available"), "{msg}");
            continue;
        }
        let parts: Vec<String> = if reachable {
            vec!["max_storage_buffers_per_shader_stage".into(), "stage '".into(), "segments of 65536 bytes".into(), format!("is {have}")]
        } else {
            vec!["max_buffer_size".into(), "choose a smaller --particles".into()]
        };
        assert!(msg.contains(ctx.info.name.as_str()), "the adapter's name missing from: {msg}");
        for part in &parts {
            assert!(msg.contains(part.as_str()), "'{part}' missing from: {msg}");
        }
    }
}

#[test]
fn segment_sizes_outside_the_allowed_range_are_refused() {
    for ctx in common::contexts() {
        for bytes in [1000, SMALL_SEGMENT / 2, 3 * SMALL_SEGMENT, 1 << 40] {
            let msg = format!("{:#}", ctx.clone().with_storage_segment_bytes(bytes).err().expect("refused"));
            assert!(msg.contains(&bytes.to_string()) && msg.contains("power of two from 65536"), "{msg}");
        }
        assert_eq!(ctx.clone().with_storage_segment_bytes(SMALL_SEGMENT).unwrap().storage_segment_bytes(), SMALL_SEGMENT);
    }
}

#[test]
fn particles_too_many_for_the_adapter_exit_2_before_allocating() {
    let Ok(adapter) = wgsph::solver::gpu::device::choose_adapter() else {
        eprintln!("SKIPPED: no GPU adapter with compute shaders");
        return;
    };
    let fit = adapter.limits().max_buffer_size / 16;
    let n = fit + fit / 4;
    let scene = Scene::load("hydrostatic").unwrap().with_fluid_particles(n);
    if let Err(e) = scene.validate(&wgsph::model::scene::SceneOrigin::Text) {
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
    assert!(err.contains("max_buffer_size"), "{err}");
    assert!(!dir.path().join("o/snapshots/step_000000.csv").exists());
}

#[test]
fn streamed_csv_snapshots_equal_the_whole_array_ones_byte_for_byte() {
    use wgsph::solver::Backend;
    for ctx in common::contexts() {
        let scene = Scene::load("dam_break").unwrap().with_fluid_particles(700);
        let mut solver = common::gpu(ctx.clone(), &scene);
        solver.step(5).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let whole = dir.path().join("whole.csv");
        let snapshot = solver.snapshot().unwrap();
        wgsph::io::snapshot::csv::write_snapshot_csv(&whole, &snapshot).unwrap();
        let expected = std::fs::read(&whole).unwrap();
        // 7: pieces that split every array unevenly and more than MAX_PASSES passes' worth of
        // pieces; 1 << 20: one piece, one pass.
        for chunk in [1, 7, 64, wgsph::solver::gpu::buffers::STREAM_CHUNK] {
            let path = dir.path().join(format!("streamed_{chunk}.csv"));
            let files = [(wgsph::io::snapshot::format::SnapshotFormat::Csv, path.clone())];
            let (n, step, time) = (solver.fluid_count() as u64, solver.steps_done(), solver.time());
            let s = wgsph::io::snapshot::write_rows(&files, n, step, time, |v| solver.visit_rows_in_pieces(chunk, v)).unwrap();
            assert_eq!(std::fs::read(&path).unwrap(), expected, "chunk {chunk} on {}", ctx.describe());
            assert_eq!((s.step, s.particles), (5, snapshot.len() as u64));
            assert_eq!(s.extremes, snapshot.extremes());
        }
    }
}

#[test]
fn the_state_in_place_steps_bit_for_bit_like_the_fused_ping_pong_pair_with_less_memory() {
    use wgsph::solver::gpu::GpuOptions;
    use wgsph::solver::Backend;
    for ctx in common::contexts() {
        let scene = TestScene::small_tank().kernel(Kernel::CubicSpline).clamp_negative_pressure(false).build();
        let initial = scene.initial_state();
        let option = |fuse| GpuOptions { fuse_forces_and_integration: Some(fuse), ..Default::default() };
        let mut fused = common::gpu_with(ctx.clone(), &scene, None, option(true)).unwrap();
        let mut two_pass = common::gpu_with(ctx.clone(), &scene, None, option(false)).unwrap();
        assert!(fused.fused() && !two_pass.fused());
        // By default the state is held in place (two passes), on every adapter.
        let default = common::gpu(ctx.clone(), &scene);
        assert!(!default.fused(), "{}", ctx.describe());
        // Three 16-byte buffers instead of two pairs of them: 16 bytes per fluid particle less
        // (besides the neighbour lists the two passes keep on an adapter with subgroup tiles).
        let n = initial.fluid_positions.len() as u64;
        let lists = two_pass.neighbour_list_capacity().map_or(0, |slots| n * (slots as u64 * 4 + 4));
        assert_eq!(fused.memory_bytes() + lists - two_pass.memory_bytes(), 16 * n);
        for solver in [&mut fused, &mut two_pass] {
            solver.step(30).unwrap();
        }
        // The accelerations of the fused step, evaluated again on request, are the two-pass ones.
        let (fa, fb) = (fused.step_fields().unwrap(), two_pass.step_fields().unwrap());
        assert!(fa == fb, "{}: step fields differ", ctx.describe());
        let (a, b) = (fused.snapshot().unwrap(), two_pass.snapshot().unwrap());
        assert!(a.positions == b.positions && a.velocities == b.velocities, "{}: states differ", ctx.describe());
        assert!(a.positions != initial.fluid_positions);
    }
}

#[test]
fn a_coarsened_scene_grows_its_domain_to_hold_thicker_walls() {
    let fine = Scene::load("dam_break").unwrap();
    let coarse = fine.with_fluid_particles(300);
    coarse.validate(&wgsph::model::scene::SceneOrigin::Text).unwrap();
    let (lo, hi) = coarse.wall_span(&coarse.boundary[0]).unwrap();
    for a in 0..3 {
        assert!(coarse.domain.min[a] <= lo[a] && hi[a] <= coarse.domain.max[a]);
        assert!(coarse.domain.min[a] < fine.domain.min[a] && coarse.domain.max[a] > fine.domain.max[a], "axis {a}");
    }
    // Refined, the thinner walls fit: the domain stays as written.
    let refined = fine.with_fluid_particles(100_000);
    assert_eq!((refined.domain.min, refined.domain.max), (fine.domain.min, fine.domain.max));
}

#[test]
fn workgroup_sizes_per_stage_change_no_value_and_oversized_ones_are_refused() {
    use wgsph::solver::gpu::{GpuOptions, WorkgroupSizes};
    use wgsph::solver::Backend;
    for ctx in common::contexts() {
        // Adaptive dt too: its reduction of the largest speed and acceleration runs per workgroup.
        for scene in [TestScene::small_tank().build(), TestScene::small_tank().adaptive().build()] {
            let run = |sizes: WorkgroupSizes| {
                let options = GpuOptions { workgroup_sizes: sizes, ..Default::default() };
                let mut solver = common::gpu_with(ctx.clone(), &scene, None, options).unwrap();
                solver.step(20).unwrap();
                (solver.snapshot().unwrap(), solver.dt_stats().unwrap())
            };
            let reference = run(WorkgroupSizes::default());
            for sizes in ["32", "density=64,forces=256,integrate=32,reorder=256"] {
                let got = run(sizes.parse().unwrap());
                assert!(got == reference, "{} with {sizes} (adaptive dt: {}): another result", ctx.describe(), scene.time.adaptive);
            }
        }
        let l = ctx.device.limits();
        let too_many = 2 * l.max_compute_workgroup_size_x.min(l.max_compute_invocations_per_workgroup);
        let scene = Scene::load("dam_break").unwrap().with_fluid_particles(300);
        let options = GpuOptions { workgroup_sizes: WorkgroupSizes { density: too_many, ..Default::default() }, ..Default::default() };
        let e = common::gpu_with(ctx.clone(), &scene, None, options).err().expect("refused");
        let msg = format!("{e:#}");
        assert!(msg.contains("'density'") && msg.contains(&too_many.to_string()) && msg.contains(&ctx.info.name), "{msg}");
    }
}

#[test]
fn single_cell_stencils_and_steps_per_submission_change_no_value() {
    use wgsph::solver::gpu::GpuOptions;
    use wgsph::solver::Backend;
    for ctx in common::contexts() {
        let scene = TestScene::small_tank().kernel(Kernel::CubicSpline).equation_of_state(EquationOfState::Linear).clamp_negative_pressure(false).build();
        let initial = scene.initial_state();
        let run = |options: GpuOptions| {
            let mut solver = common::gpu_with(ctx.clone(), &scene, None, options).unwrap();
            solver.step(40).unwrap();
            (solver.snapshot().unwrap(), solver.step_fields().unwrap())
        };
        let reference = run(GpuOptions::default());
        assert!(reference.0.positions != initial.fluid_positions);
        for options in [
            GpuOptions { single_cells: true, ..Default::default() },
            GpuOptions { steps_per_submit: 1, ..Default::default() },
            GpuOptions { steps_per_submit: 7, single_cells: true, ..Default::default() },
        ] {
            assert!(run(options) == reference, "{} with {options:?}: another result", ctx.describe());
        }
    }
}

#[test]
fn run_tuning_flags_change_no_output_and_bad_sizes_exit_2() {
    if common::contexts().is_empty() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let run = |out: &str, extra: &[&str]| {
        let mut args = vec!["run", "dam_break", "--particles", "500", "--steps", "6", "--snapshot-every", "6", "--backend", "gpu", "--quiet", "--out", out];
        args.extend_from_slice(extra);
        let o = Command::new(env!("CARGO_BIN_EXE_wgsph")).args(&args).current_dir(dir.path()).output().unwrap();
        (o.status.code(), String::from_utf8_lossy(&o.stderr).into_owned())
    };
    assert_eq!(run("plain", &[]).0, Some(0));
    for (i, flags) in [&["--fused", "--workgroup-size", "64", "--steps-per-submit", "2"][..], &["--unfused", "--workgroup-size", "density=32,forces=256"][..], &["--no-subgroup-tiles"][..]]
        .into_iter()
        .enumerate()
    {
        let out = format!("tuned{i}");
        assert_eq!(run(&out, flags).0, Some(0), "{flags:?}");
        let file = "snapshots/step_000006.csv";
        assert!(std::fs::read(dir.path().join("plain").join(file)).unwrap() == std::fs::read(dir.path().join(&out).join(file)).unwrap(), "{flags:?}");
    }
    for (flags, names) in [
        (&["--workgroup-size", "pressure=64"][..], "'pressure'"),
        (&["--workgroup-size", "0"][..], "'0'"),
        (&["--fused", "--unfused"][..], "--unfused"),
        (&["--subgroup-tiles", "--no-subgroup-tiles"][..], "--no-subgroup-tiles"),
        // Tiles asked for where they cannot run: forces workgroups that are not whole subgroups
        // (or, on an adapter without subgroups of 8, for that reason).
        (&["--subgroup-tiles", "--workgroup-size", "forces=100"][..], "--subgroup-tiles"),
    ] {
        let (code, err) = run("bad", flags);
        assert_eq!(code, Some(2), "{flags:?}: {err}");
        assert!(err.contains(names), "{flags:?}: {err}");
    }
}

#[test]
fn an_error_the_device_reports_later_is_an_error_not_a_panic() {
    // wgpu reports some errors after the call that caused them (a shader a driver rejects, a
    // buffer the device has no memory for), by default with a panic. Here a buffer made with
    // usages that cannot go together: the next check of the device, and every readback after
    // it, is an error naming the adapter; a device opened afresh is unaffected.
    for ctx in common::contexts() {
        let name = ctx.describe();
        ctx.check_device().unwrap();
        let good = ctx.device.create_buffer(&wgpu::BufferDescriptor { label: Some("good"), size: 16, usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC, mapped_at_creation: false });
        assert!(wgsph::solver::gpu::readback::read_buffers(&ctx, &[(&good, 16)]).is_ok(), "{name}");
        let _bad = ctx.device.create_buffer(&wgpu::BufferDescriptor { label: Some("bad"), size: 16, usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::STORAGE, mapped_at_creation: false });
        let e = format!("{:#}", ctx.check_device().unwrap_err());
        assert!(e.contains("reported an error") && e.contains(&name), "{name}: {e}");
        let e = format!("{:#}", wgsph::solver::gpu::readback::read_buffers(&ctx, &[(&good, 16)]).unwrap_err());
        assert!(e.contains("reported an error"), "{name}: {e}");
        let fresh = wgsph::solver::gpu::GpuContext::from_adapter(ctx.adapter.clone()).unwrap();
        fresh.check_device().unwrap();
    }
}
