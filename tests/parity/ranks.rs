//! One simulation across several ranks (threads of one process here, connected by channels)
//! against the same scene on one rank: bit for bit, through migration, ghosts, load balance,
//! empty ranks and restarts on another rank count. The runs over MPI processes are in
//! tests/cli/ranks.rs.

use super::common::{self, TestScene};
use std::sync::Arc;
use wgsph::model::scene::{BoundaryPressure, Scene};
use wgsph::model::state::{BackendState, Snapshot};
use wgsph::solver::gpu::{GpuContext, GpuOptions};
use wgsph::solver::{open, Backend, BackendChoice, LocalGroup, Precision, Ranks};

/// What a test does with each rank's backend; every rank runs it, rank 0's result is returned
/// (with every rank's, for the checks that they agree).
type Work<'a, T> = dyn Fn(&mut dyn Backend) -> anyhow::Result<T> + Sync + 'a;

fn on_ranks<T: Send>(scene: &Scene, ranks: usize, balance_every: u64, precision: Precision, work: &Work<'_, T>) -> Vec<T> {
    std::thread::scope(|scope| {
        let handles: Vec<_> = LocalGroup::new(ranks)
            .into_iter()
            .map(|comm| {
                scope.spawn(move || {
                    let rank = Ranks { comm: Arc::new(comm), balance_every };
                    let mut sim = open(scene, &BackendChoice::cpu(precision).on_ranks(rank)).expect("opens");
                    work(sim.backend()).expect("runs")
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().expect("rank thread")).collect()
    })
}

fn snapshot_after(scene: &Scene, ranks: usize, steps: u64, balance_every: u64) -> Snapshot {
    let all = on_ranks(scene, ranks, balance_every, Precision::F64, &|b: &mut dyn Backend| {
        b.step(steps)?;
        b.snapshot()
    });
    for s in &all[1..] {
        assert!(s.len() == 0 && s.step == all[0].step && s.time == all[0].time, "rank 0 gathers the snapshot, the others get its step and time");
    }
    all.into_iter().next().expect("one rank at least")
}

fn one_rank(scene: &Scene, steps: u64) -> Snapshot {
    let mut sim = open(scene, &BackendChoice::cpu(Precision::F64)).expect("opens");
    sim.step(steps).expect("steps");
    let health = sim.health().expect("health");
    assert!(health.is_ok() && sim.steps_done() == steps, "the run of {} stays healthy: {health:?} at step {}", scene.name, sim.steps_done());
    sim.snapshot().expect("snapshot")
}

fn dam_break(particles: u64) -> Scene {
    Scene::builtin("dam_break").expect("built in").with_fluid_particles(particles)
}

/// The largest relative difference of positions and densities.
fn largest_difference(a: &Snapshot, b: &Snapshot) -> (f64, f64) {
    assert_eq!(a.len(), b.len());
    let mut position: f64 = 0.0;
    let mut density: f64 = 0.0;
    for i in 0..a.len() {
        for k in 0..3 {
            position = position.max((a.positions[i][k] - b.positions[i][k]).abs() / a.positions[i][k].abs().max(1e-3));
        }
        density = density.max((a.densities[i] - b.densities[i]).abs() / a.densities[i].abs());
    }
    (position, density)
}

#[test]
fn several_ranks_compute_bit_for_bit_what_one_rank_computes() {
    let scene = dam_break(1500);
    assert!(scene.grid().dims[0] >= 8, "the dam break's long axis has room for 4 slabs");
    let one = one_rank(&scene, 1);
    for ranks in [2, 3, 4] {
        let many = snapshot_after(&scene, ranks, 1, 0);
        let (dx, drho) = largest_difference(&one, &many);
        assert!(dx <= 1e-6 && drho <= 1e-6, "{ranks} ranks after one step: position {dx:e}, density {drho:e}");
        assert!(one == many, "{ranks} ranks after one step, bit for bit");
    }
}

#[test]
fn two_hundred_steps_of_the_dam_break_on_one_two_and_four_ranks_agree() {
    let scene = dam_break(1000);
    let one = one_rank(&scene, 200);
    for ranks in [2, 4] {
        // Slabs move every 20 steps; migration and ghosts change every step.
        let many = snapshot_after(&scene, ranks, 200, 20);
        let tolerances = wgsph::solver::compare::many_steps(&scene.params());
        let (dx, drho) = largest_difference(&one, &many);
        assert!(dx <= tolerances.position && drho <= tolerances.density, "{ranks} ranks: position {dx:e}, density {drho:e}");
        assert!(one == many, "{ranks} ranks after 200 steps, bit for bit");
    }
}

#[test]
fn continuity_density_in_f32_adaptive_dt_and_adami_walls_agree_bit_for_bit() {
    let continuity = TestScene::small_tank().continuity().density_diffusion(0.1).build();
    let adaptive = TestScene::small_tank().adaptive().build();
    let adami = TestScene::small_tank().boundary_pressure(BoundaryPressure::Adami).build();
    for (scene, precision) in [(continuity, Precision::F32), (adaptive, Precision::F64), (adami, Precision::F64)] {
        let mut single = open(&scene, &BackendChoice::cpu(precision)).expect("opens");
        single.step(30).expect("steps");
        let one = single.snapshot().expect("snapshot");
        let dt = single.backend().dt_stats().expect("dt").last;
        let all = on_ranks(&scene, 2, 10, precision, &|b: &mut dyn Backend| {
            b.step(30)?;
            Ok((b.snapshot()?, b.dt_stats()?.last))
        });
        assert!(all[0].0 == one, "2 ranks against 1, {precision:?}, {:?}, {:?}", scene.physics.density, scene.physics.boundary_pressure);
        assert_eq!(all[0].1, dt);
    }
}

/// A block at the low end of a long closed box (along z), moving up it at 0.5 m/s without
/// gravity.
fn moving_block() -> Scene {
    TestScene::new()
        .named("block")
        .domain([-0.1, -0.1, -0.1], [0.3, 0.3, 1.3])
        .container([0.0; 3], [0.2, 0.2, 1.2])
        .gravity([0.0; 3])
        .fluid([0.0; 3], [0.2, 0.2, 0.16])
        .moving_at([0.0, 0.0, 0.5])
        .clamp_negative_pressure(true)
        .build()
}

#[test]
fn particles_migrate_across_faces_and_slabs_follow_the_counts() {
    let scene = moving_block();
    let one = one_rank(&scene, 100);
    let reports = on_ranks(&scene, 3, 10, Precision::F64, &|b: &mut dyn Backend| {
        b.step(100)?;
        Ok((b.rank_report().expect("across ranks"), b.snapshot()?))
    });
    let first = &reports[0].0;
    assert_eq!(first.axis, 2, "the box is cut along its length");
    let migrated: u64 = reports.iter().map(|r| r.0.stats.migrated).sum();
    assert!(migrated > 0, "the moving block crosses the slab faces: {:?}", reports.iter().map(|r| &r.0).collect::<Vec<_>>());
    assert!(reports.iter().any(|r| r.0.stats.ghosts > 0), "ranks hold ghosts of their neighbours");
    assert!(first.stats.rebalances > 0, "the bounds followed the block: {:?}", first.bounds);
    assert!(first.stats.max_imbalance >= 1.0);
    assert_eq!(reports.iter().map(|r| r.0.own_particles).sum::<usize>(), scene.fluid_particle_count() as usize);
    assert!(reports[0].1 == one, "3 ranks with migration and moving slabs against one rank");
}

#[test]
fn every_rank_writes_its_piece_of_the_one_snapshot_file_one_process_writes() {
    use wgsph::io::snapshot::format::SnapshotFormat;
    let scene = moving_block();
    let dir = tempfile::tempdir().unwrap();
    let files = |stem: &str| [SnapshotFormat::Csv, SnapshotFormat::Vtk, SnapshotFormat::Ply].map(|f| (f, dir.path().join(format!("{stem}.{}", f.extension()))));
    let one = one_rank(&scene, 40);
    for (f, path) in files("one") {
        wgsph::io::snapshot::write_snapshot(&path, f, &one).unwrap();
    }
    let held = on_ranks(&scene, 3, 10, Precision::F64, &|b: &mut dyn Backend| {
        b.step(40)?;
        let piece = b.snapshot_piece().expect("across ranks")?;
        wgsph::io::snapshot::pieces::write_pieces(&files("ranks"), &piece)?;
        Ok(piece.rows.len())
    });
    assert_eq!(held.iter().sum::<usize>(), one.len());
    assert!(held.iter().all(|&n| n < one.len()), "no rank holds every particle: {held:?}");
    for ((f, a), (_, b)) in files("one").iter().zip(&files("ranks")) {
        assert!(std::fs::read(a).unwrap() == std::fs::read(b).unwrap(), "{f:?}: the pieces of 3 ranks against one process's file");
    }
}

/// The moving block with Akinci's volumes (a wall's mass from its wall neighbours), Adami's
/// wall pressure (from the fluid near the wall, one ghost layer more) and Akinci's adhesion:
/// all read the walls a rank holds, which follow the slab.
fn moving_block_akinci_adami() -> Scene {
    let mut scene = moving_block();
    scene.physics.boundary_volume = wgsph::model::scene::BoundaryVolume::Akinci;
    scene.physics.boundary_pressure = BoundaryPressure::Adami;
    scene.physics.wall_adhesion = 2.0;
    scene
}

#[test]
fn each_rank_holds_the_walls_near_its_slab_and_takes_new_ones_when_the_bounds_move() {
    let scene = moving_block_akinci_adami();
    let one = one_rank(&scene, 100);
    let total_walls = scene.initial_walls().wall_positions.len();
    let runs = on_ranks(&scene, 3, 10, Precision::F64, &|b: &mut dyn Backend| {
        let first = b.rank_report().expect("across ranks").walls;
        b.step(100)?;
        Ok((first, b.rank_report().expect("across ranks"), b.wall_count(), b.snapshot()?))
    });
    for (first, report, count, _) in &runs {
        assert_eq!(*count, total_walls, "a rank reports the simulation's walls");
        assert!(*first < total_walls && report.walls < total_walls, "rank {} holds {first}, then {} of {total_walls} walls", report.rank, report.walls);
    }
    assert!(runs[0].1.stats.rebalances > 0, "the bounds moved");
    assert!(runs.iter().any(|r| r.0 != r.1.walls), "a rank whose bounds moved took other walls: {:?}", runs.iter().map(|r| (r.0, r.1.walls)).collect::<Vec<_>>());
    assert!(runs[0].3 == one, "3 ranks with walls per rank, Akinci volumes, Adami pressure and adhesion against one rank");
    let mut dry = scene.clone();
    dry.physics.wall_adhesion = 0.0;
    assert!(one_rank(&dry, 100) != one, "the adhesion took part");
}

#[test]
fn a_checkpoint_streams_from_every_rank_in_pieces_to_the_bytes_one_rank_writes() {
    use wgsph::io::checkpoint::write_state_in_pieces;
    // The moving block (migration, moving bounds), DFSPH's warm starts, continuity density;
    // before the first step (the initial order) and after steps (the cell order); pieces of 7
    // particles, so every rank's particles spread over many pieces.
    let continuity = TestScene::small_tank().continuity().build();
    for (scene, steps) in [(moving_block(), 40), (moving_block(), 0), (moving_block_dfsph(), 30), (continuity, 20)] {
        let mut single = open(&scene, &BackendChoice::cpu(Precision::F64)).expect("opens");
        single.step(steps).expect("steps");
        let mut one = Vec::new();
        write_state_in_pieces(single.backend(), &mut one, 7).expect("writes");
        let streamed = on_ranks(&scene, 3, 10, Precision::F64, &|b: &mut dyn Backend| {
            b.step(steps)?;
            let mut bytes = Vec::new();
            write_state_in_pieces(b, &mut bytes, 7)?;
            Ok(bytes)
        });
        assert!(streamed[0] == one, "{} after {steps} steps: the checkpoint streamed from 3 ranks against one rank's", scene.name);
        assert!(streamed[1].len() < one.len() / 2, "the other ranks receive no particle");
    }
}

#[test]
fn a_rank_without_particles_takes_part_in_every_step() {
    // 4 ranks on the moving block: the upper ones start empty.
    let scene = moving_block();
    let one = one_rank(&scene, 60);
    let runs = on_ranks(&scene, 4, 0, Precision::F64, &|b: &mut dyn Backend| {
        let before = b.rank_report().expect("across ranks").own_particles;
        b.step(60)?;
        Ok((before, b.snapshot()?))
    });
    assert!(runs.iter().any(|r| r.0 == 0), "a rank starts empty: {:?}", runs.iter().map(|r| r.0).collect::<Vec<_>>());
    assert!(runs[0].1 == one, "4 ranks, some empty, against one rank");
}

#[test]
fn a_state_saved_on_some_ranks_continues_on_another_count() {
    let scene = dam_break(800);
    let uninterrupted = one_rank(&scene, 60);
    // Saved at step 30 on 3 ranks: the state is the one one rank saves.
    let saved: Vec<BackendState> = on_ranks(&scene, 3, 10, Precision::F64, &|b: &mut dyn Backend| {
        b.step(30)?;
        b.save_state()
    });
    let mut single = open(&scene, &BackendChoice::cpu(Precision::F64)).expect("opens");
    single.step(30).expect("steps");
    assert!(saved[0] == single.backend().save_state().expect("state"), "the state saved on 3 ranks is the one one rank saves");
    for ranks in [1, 2, 4] {
        let state = saved[0].clone();
        let resumed = on_ranks(&scene, ranks, 10, Precision::F64, &move |b: &mut dyn Backend| {
            b.restore_state(&state)?;
            b.step(30)?;
            b.snapshot()
        });
        assert!(resumed[0] == uninterrupted, "saved on 3 ranks, continued on {ranks}");
    }
}

#[test]
fn what_does_not_run_across_ranks_yet_is_refused_by_name() {
    let every2 = TestScene::small_tank().dfsph().neighbour_rebuild_every(2).build();
    let [comm, _other]: [_; 2] = LocalGroup::new(2).try_into().ok().expect("two ranks");
    let ranks = Ranks::new(Arc::new(comm));
    for choice in [BackendChoice::cpu(Precision::F64), BackendChoice::gpu()] {
        let e = open(&every2, &choice.on_ranks(ranks.clone())).err().expect("refused").to_string();
        assert!(e.contains("time.neighbour_rebuild_every") && e.contains("must be 1"), "{e}");
    }
}

/// DFSPH across ranks: the ghosts take their owners' velocities after every velocity change
/// of the solves, the error sums and the adaptive step's maxima are the ranks' together, and
/// the warm starts travel with the particles; so N ranks run the same iterations with the same
/// dt and compute one rank's bits, through migration, moving bounds and a restart on another
/// rank count.
fn dfsph_tank() -> TestScene {
    TestScene::small_tank().dfsph().dt(0.001)
}

/// The DFSPH scenes run on ranks, with their rank counts: the still tank (2), with adaptive dt
/// (3), the dam break (3) and the moving block with migration and moving bounds (3).
fn dfsph_scenes() -> [(Scene, usize); 4] {
    let fixed = dfsph_tank().build();
    let adaptive = dfsph_tank().adaptive().dt_max(0.004).build();
    let mut dam = dam_break(1000);
    dam.physics.solver = wgsph::model::scene::PressureSolver::Dfsph;
    dam.physics.stiffness = None;
    dam.physics.speed_of_sound = None;
    dam.time.dt = 0.001;
    [(fixed, 2), (adaptive, 3), (dam, 3), (moving_block_dfsph(), 3)]
}

/// 40 DFSPH steps of `sim` (one process): its snapshot, iterations and dt, checked healthy and
/// iterating.
fn forty_dfsph_steps(sim: &mut wgsph::solver::Simulation, name: &str) -> (Snapshot, wgsph::model::state::IterationStats, wgsph::model::state::DtStats) {
    sim.step(40).expect("steps");
    let health = sim.health().expect("health");
    assert!(health.is_ok(), "{name}: one process stays healthy: {health:?}");
    let iterations = health.iterations.expect("DFSPH counts its iterations");
    assert!(iterations.pressure.total > 40, "{name}: the solves iterate ({iterations:?})");
    (sim.snapshot().expect("snapshot"), iterations, sim.backend().dt_stats().expect("dt"))
}

#[test]
fn dfsph_on_ranks_computes_bit_for_bit_what_one_rank_computes() {
    let precisions = [Precision::F64, Precision::F64, Precision::F32, Precision::F64];
    for ((scene, ranks), precision) in dfsph_scenes().into_iter().zip(precisions) {
        let mut single = open(&scene, &BackendChoice::cpu(precision)).expect("opens");
        let (one, iterations, dt) = forty_dfsph_steps(&mut single, &scene.name);
        let all = on_ranks(&scene, ranks, 10, precision, &|b: &mut dyn Backend| {
            b.step(40)?;
            Ok((b.snapshot()?, b.health()?, b.dt_stats()?, b.rank_report().expect("across ranks")))
        });
        for (rank, (_, h, d, _)) in all.iter().enumerate() {
            assert_eq!(h.iterations, Some(iterations), "{}: rank {rank} of {ranks} iterates as one rank", scene.name);
            assert_eq!((d.min, d.max, d.last), (dt.min, dt.max, dt.last), "{}: rank {rank} of {ranks} steps with one rank's dt", scene.name);
        }
        assert!(all.iter().any(|r| r.3.stats.ghosts > 0), "{}: ranks hold ghosts", scene.name);
        assert!(all[0].0 == one, "{}: {ranks} ranks against one, {precision:?}, bit for bit", scene.name);
    }
}

/// The moving block of the migration tests, with DFSPH.
fn moving_block_dfsph() -> Scene {
    let mut scene = moving_block();
    scene.physics.solver = wgsph::model::scene::PressureSolver::Dfsph;
    scene.physics.stiffness = None;
    scene.physics.speed_of_sound = None;
    scene.time.dt = 0.002;
    scene
}

/// The moving block with Akinci's surface tension, whose curvature term reads each fluid
/// neighbour's normal (summed over that neighbour's neighbours: one ghost layer more), with
/// WCSPH and with DFSPH (60 steps: the block crosses the faces of 3 slabs).
fn moving_blocks_with_surface_tension() -> [Scene; 2] {
    [moving_block(), moving_block_dfsph()].map(|mut scene| {
        scene.physics.surface_tension = 0.2;
        scene
    })
}

#[test]
fn surface_tension_across_ranks_computes_what_one_rank_computes() {
    for scene in moving_blocks_with_surface_tension() {
        let name = format!("{:?}", scene.physics.solver);
        let one = one_rank(&scene, 60);
        let runs = on_ranks(&scene, 3, 10, Precision::F64, &|b: &mut dyn Backend| {
            b.step(60)?;
            Ok((b.rank_report().expect("across ranks"), b.snapshot()?))
        });
        assert!(runs.iter().map(|r| r.0.stats.migrated).sum::<u64>() > 0, "{name}: particles crossed the faces");
        assert!(runs[0].1 == one, "{name}: 3 ranks with surface tension against one rank, bit for bit");
        let mut dry = scene.clone();
        dry.physics.surface_tension = 0.0;
        assert!(one_rank(&dry, 60) != one, "{name}: the surface tension took part");
    }
}

#[test]
fn a_dfsph_state_saved_on_some_ranks_continues_on_another_count() {
    let scene = dfsph_tank().build();
    let uninterrupted = one_rank(&scene, 40);
    let saved: Vec<BackendState> = on_ranks(&scene, 3, 10, Precision::F64, &|b: &mut dyn Backend| {
        b.step(20)?;
        b.save_state()
    });
    let mut single = open(&scene, &BackendChoice::cpu(Precision::F64)).expect("opens");
    single.step(20).expect("steps");
    assert!(saved[0] == single.backend().save_state().expect("state"), "the DFSPH state saved on 3 ranks (warm starts included) is the one one rank saves");
    for ranks in [1, 2] {
        let state = saved[0].clone();
        let resumed = on_ranks(&scene, ranks, 10, Precision::F64, &move |b: &mut dyn Backend| {
            b.restore_state(&state)?;
            b.step(20)?;
            b.snapshot()
        });
        assert!(resumed[0] == uninterrupted, "DFSPH saved on 3 ranks, continued on {ranks}");
    }
}

/// Each rank on its own device of `ctx`'s adapter, like the ranks of one machine sharing a
/// software adapter.
fn gpu_on_ranks<T: Send>(ctx: &GpuContext, scene: &Scene, ranks: usize, balance_every: u64, work: &Work<'_, T>) -> Vec<T> {
    gpu_on_ranks_with(ctx, scene, ranks, balance_every, GpuOptions::default(), work)
}

fn gpu_on_ranks_with<T: Send>(ctx: &GpuContext, scene: &Scene, ranks: usize, balance_every: u64, options: GpuOptions, work: &Work<'_, T>) -> Vec<T> {
    std::thread::scope(|scope| {
        let handles: Vec<_> = LocalGroup::new(ranks)
            .into_iter()
            .map(|comm| {
                let device = GpuContext::from_adapter(ctx.adapter.clone()).expect("a device per rank");
                scope.spawn(move || {
                    let rank = Ranks { comm: Arc::new(comm), balance_every };
                    let mut sim = open(scene, &BackendChoice::gpu_on(device).with_gpu_options(options).on_ranks(rank)).expect("opens");
                    work(sim.backend()).expect("runs")
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().expect("rank thread")).collect()
    })
}

fn gpu_snapshot_after(ctx: &GpuContext, scene: &Scene, ranks: usize, steps: u64, balance_every: u64) -> Snapshot {
    let all = gpu_on_ranks(ctx, scene, ranks, balance_every, &|b: &mut dyn Backend| {
        b.step(steps)?;
        assert!(b.health()?.is_ok(), "rank healthy after {steps} steps: {:?}", b.health()?);
        b.snapshot()
    });
    all.into_iter().next().expect("one rank at least")
}

fn one_gpu(ctx: &GpuContext, scene: &Scene, steps: u64) -> Snapshot {
    let device = GpuContext::from_adapter(ctx.adapter.clone()).expect("device");
    let mut sim = open(scene, &BackendChoice::gpu_on(device)).expect("opens");
    sim.step(steps).expect("steps");
    sim.snapshot().expect("snapshot")
}

#[test]
fn several_gpu_ranks_compute_bit_for_bit_what_one_gpu_computes_after_one_step_and_over_200_steps() {
    let Some(ctx) = common::contexts().into_iter().next() else { return };
    let scene = dam_break(1000);
    let one = one_gpu(&ctx, &scene, 1);
    for ranks in [2, 3] {
        let many = gpu_snapshot_after(&ctx, &scene, ranks, 1, 0);
        let (dx, drho) = largest_difference(&one, &many);
        assert!(dx <= 1e-6 && drho <= 1e-6, "{ranks} GPU ranks after one step: position {dx:e}, density {drho:e}");
        // The GPU's binning is stable, so the exchange's one-process order gives the same sums.
        assert!(one == many, "{ranks} GPU ranks after one step, bit for bit");
    }
    let one = one_gpu(&ctx, &scene, 200);
    let tolerances = wgsph::solver::compare::many_steps(&scene.params());
    let many = gpu_snapshot_after(&ctx, &scene, 2, 200, 20);
    let (dx, drho) = largest_difference(&one, &many);
    assert!(dx <= tolerances.position && drho <= tolerances.density, "2 GPU ranks over 200 steps: position {dx:e}, density {drho:e}");
    assert!(one == many, "2 GPU ranks over 200 steps with moving bounds, bit for bit");
}

/// Adaptive dt on GPU ranks: each rank's device reduces its own particles' largest speed and
/// acceleration (its ghosts left out), the host takes the largest over the ranks, and every
/// rank's device chooses from it the dt one GPU chooses. On the still tank the slabs cut the
/// vertical, in the dam break the length; the bounds move every 10 steps.
#[test]
fn adaptive_dt_on_gpu_ranks_chooses_what_one_gpu_chooses() {
    let Some(ctx) = common::contexts().into_iter().next() else { return };
    let tank = TestScene::small_tank().adaptive().dt_max(0.002).build();
    let mut dam = dam_break(1000);
    dam.time.adaptive = true;
    dam.time.dt_max = Some(10.0 * dam.time.dt);
    for (mut scene, ranks) in [(tank, 2), (dam, 3)] {
        // The force condition binds (the ghosts of the outer layer, whose neighbours are
        // missing on one side, feel forces that would lower dt).
        scene.time.force_number = 0.02;
        let device = GpuContext::from_adapter(ctx.adapter.clone()).expect("device");
        let mut single = open(&scene, &BackendChoice::gpu_on(device)).expect("opens");
        single.step(40).expect("steps");
        let one = single.snapshot().expect("snapshot");
        let stats = single.backend().dt_stats().expect("dt");
        assert!(stats.min < stats.max, "{}: dt changes over the run ({stats:?})", scene.name);
        let all = gpu_on_ranks(&ctx, &scene, ranks, 10, &|b: &mut dyn Backend| {
            b.step(40)?;
            Ok((b.snapshot()?, b.dt_stats()?))
        });
        for (rank, (_, dt)) in all.iter().enumerate() {
            assert_eq!((dt.last, dt.min, dt.max), (stats.last, stats.min, stats.max), "{}: rank {rank} of {ranks} steps with one GPU's dt", scene.name);
        }
        // The time is the steps' dt summed on the host in f64 across ranks, a compensated f32
        // sum on one GPU: the same to rounding.
        let many = &all[0].0;
        assert!((many.time - one.time).abs() <= 1e-6 * one.time, "{}: time {} against {}", scene.name, many.time, one.time);
        let many = Snapshot { time: one.time, ..many.clone() };
        assert!(many == one, "{}: {ranks} GPU ranks with adaptive dt against one GPU, bit for bit", scene.name);
    }
}

#[test]
fn gpu_ranks_are_bitwise_reproducible_through_migration() {
    let Some(ctx) = common::contexts().into_iter().next() else { return };
    let scene = moving_block();
    let run = || {
        gpu_on_ranks(&ctx, &scene, 3, 10, &|b: &mut dyn Backend| {
            b.step(40)?;
            Ok((b.rank_report().expect("across ranks"), b.snapshot()?))
        })
    };
    let (first, second) = (run(), run());
    assert!(first.iter().map(|r| r.0.stats.migrated).sum::<u64>() > 0, "particles crossed faces");
    assert!(first[0].1 == second[0].1, "3 GPU ranks, twice: the same bits");
}

/// Probes across ranks: every rank holds the one-rank run's sample; points, gauges and fronts
/// bit for bit (each point and gauge level is evaluated by one rank), the force probe's sums to
/// rounding (the ranks add their own particles' shares). In the still tank the slabs cut the
/// vertical, so the gauges' lines cross ranks; in the dam break they cut the length.
/// `scene` with two point probes, two gauges, a force probe on the tank and a front, each
/// sampled every `every` steps.
fn with_probes(mut scene: Scene, every: u64, points: [[f64; 3]; 2], gauges: [[f64; 3]; 2]) -> Scene {
    use wgsph::model::scene::{ProbeSpec, ProbeType};
    scene.probe.push(ProbeSpec::point("point_a", points[0], every));
    scene.probe.push(ProbeSpec::point("point_b", points[1], every));
    for (name, at) in [("gauge_a", gauges[0]), ("gauge_b", gauges[1])] {
        scene.probe.push(ProbeSpec { position: Some(at), every_steps: Some(every), ..ProbeSpec::of(name, ProbeType::Gauge) });
    }
    scene.probe.push(ProbeSpec { boundary: Some(0), every_steps: Some(every), ..ProbeSpec::of("tank", ProbeType::Force) });
    scene.probe.push(ProbeSpec { every_steps: Some(every), ..ProbeSpec::of("front", ProbeType::Front) });
    scene.validate(&wgsph::model::scene::SceneOrigin::Text).expect("a valid scene");
    scene
}

/// The column names of a scene's probe samples, "force" for every column of the force probe.
fn probe_columns(scene: &Scene) -> Vec<&'static str> {
    scene.params().probes.probes.iter().flat_map(|p| p.geometry.columns().iter().map(move |c| if p.name == "tank" { "force" } else { *c })).collect()
}

#[test]
fn probes_across_ranks_read_what_one_rank_reads() {
    let every = 20;
    let with_probes = |scene: Scene, points: [[f64; 3]; 2], gauges: [[f64; 3]; 2]| with_probes(scene, every, points, gauges);
    let tank = with_probes(Scene::builtin("hydrostatic").expect("built in").with_fluid_particles(2000), [[0.2, 0.2, 0.05], [0.1, 0.05, 0.05]], [[0.1, 0.0, 0.05], [0.3, 0.0, 0.05]]);
    let dam = with_probes(dam_break(1500), [[0.2, 0.2, 0.05], [0.38, 0.1, 0.05]], [[0.1, 0.0, 0.05], [0.3, 0.0, 0.05]]);
    assert_eq!(tank.grid().dims.iter().enumerate().max_by_key(|(_, d)| **d).unwrap().0, 1, "the tank's slabs cut the vertical");
    // DFSPH's probes: the points on the step's first state, the forces its wall push.
    let mut dfsph_tank = tank.clone();
    dfsph_tank.name = "hydrostatic, DFSPH".into();
    dfsph_tank.physics.solver = wgsph::model::scene::PressureSolver::Dfsph;
    dfsph_tank.physics.stiffness = None;
    dfsph_tank.physics.speed_of_sound = None;
    dfsph_tank.time.dt = 0.001;
    let steps = 120;
    for scene in [tank, dam, dfsph_tank] {
        let mut sim = open(&scene, &BackendChoice::cpu(Precision::F64)).expect("opens");
        sim.step(steps).expect("steps");
        let one = sim.backend().take_probe_samples().expect("samples");
        assert_eq!(one.len(), 6, "the states of steps 0, 20, ..., 100");
        let columns = probe_columns(&scene);
        if scene.name == "hydrostatic" {
            let last = &one.last().unwrap().values;
            assert!(last[6] > 100.0 && last[6] > last[0], "{}: the deeper point reads the higher pressure: {last:?}", scene.name);
            assert!(last.iter().zip(&columns).any(|(v, c)| *c == "force" && v.abs() > 1.0), "{}: the tank carries the fluid: {last:?}", scene.name);
        }
        for ranks in [2, 3] {
            let all = on_ranks(&scene, ranks, 0, Precision::F64, &|b: &mut dyn Backend| {
                b.step(steps)?;
                b.take_probe_samples()
            });
            for (rank, samples) in all.iter().enumerate() {
                assert_eq!(samples.len(), one.len(), "{ranks} ranks, rank {rank}");
                for (a, b) in one.iter().zip(samples) {
                    assert_eq!((a.step, a.time), (b.step, b.time));
                    for ((x, y), c) in a.values.iter().zip(&b.values).zip(&columns) {
                        let who = format!("{}, {ranks} ranks, rank {rank}, step {}, {c}: {x} against {y}", scene.name, a.step);
                        if *c == "force" {
                            assert!((x - y).abs() <= 1e-9 * x.abs().max(1.0), "{who}");
                        } else {
                            assert!(x == y, "{who}");
                        }
                    }
                }
            }
        }
    }
}

#[test]
fn gpu_ranks_with_empty_ones_compute_what_one_gpu_computes() {
    let Some(ctx) = common::contexts().into_iter().next() else { return };
    // 4 ranks on the moving block: the upper ones start with no particle (and no ghost); with
    // DFSPH an empty rank takes part in every solve's messages and checks.
    for scene in [moving_block(), moving_block_dfsph()] {
        let one = one_gpu(&ctx, &scene, 60);
        let runs = gpu_on_ranks(&ctx, &scene, 4, 0, &|b: &mut dyn Backend| {
            let before = b.rank_report().expect("across ranks").own_particles;
            b.step(60)?;
            Ok((before, b.snapshot()?))
        });
        assert!(runs.iter().any(|r| r.0 == 0), "{}: a rank starts empty: {:?}", scene.name, runs.iter().map(|r| r.0).collect::<Vec<_>>());
        assert!(runs[0].1 == one, "{}: 4 GPU ranks, some empty, against one GPU, bit for bit", scene.name);
    }
}

#[test]
fn gpu_ranks_with_walls_near_their_slabs_and_adami_pressure_compute_what_one_gpu_computes() {
    let Some(ctx) = common::contexts().into_iter().next() else { return };
    let scene = moving_block_akinci_adami();
    let one = one_gpu(&ctx, &scene, 100);
    let runs = gpu_on_ranks(&ctx, &scene, 3, 10, &|b: &mut dyn Backend| {
        b.step(100)?;
        Ok((b.rank_report().expect("across ranks"), b.snapshot()?))
    });
    assert!(runs[0].0.stats.rebalances > 0, "the bounds moved");
    assert!(runs.iter().all(|r| r.0.walls < total_walls(&scene)), "every rank holds only the walls near its slab");
    assert!(runs[0].1 == one, "3 GPU ranks, walls per rank, Akinci volumes, Adami pressure and adhesion, against one GPU, bit for bit");
}

#[test]
fn surface_tension_on_gpu_ranks_computes_what_one_gpu_computes() {
    let Some(ctx) = common::contexts().into_iter().next() else { return };
    for scene in moving_blocks_with_surface_tension() {
        let one = one_gpu(&ctx, &scene, 60);
        let runs = gpu_on_ranks(&ctx, &scene, 3, 10, &|b: &mut dyn Backend| {
            for _ in 0..6 {
                b.step(10)?;
            }
            Ok((b.rank_report().expect("across ranks"), b.snapshot()?))
        });
        let name = format!("{:?}", scene.physics.solver);
        assert!(runs.iter().map(|r| r.0.stats.migrated).sum::<u64>() > 0, "{name}: particles crossed the faces");
        // With adaptive dt off the time is the same sum of the same dt.
        assert!(runs[0].1 == one, "{name}: 3 GPU ranks with surface tension against one GPU, bit for bit");
    }
}

fn total_walls(scene: &Scene) -> usize {
    scene.initial_walls().wall_positions.len()
}

/// Probes on GPU ranks. Each rank's device samples them within its step (wgsl/sim/probes.wgsl
/// on its held particles, the ghosts left out of forces and fronts; with DFSPH the points after
/// the factors, the rest after the solves) and the host adds the ranks' rows (src/solver/cpu/
/// exchange.rs, `sample_probes_from_device`), so the points, gauges and fronts are one GPU's
/// bits, the forces one GPU's sums added in another grouping, and the steps that sample stay
/// resident. Where a gauge's line crosses the slabs (the tank's cut the vertical) each rank
/// samples on the host what its device's binning and density stage or factors give
/// (`step_on_device`), one GPU's samples up to the arithmetic of the probe stage itself (the
/// WGSL stage on one GPU, the CPU twin in f32 across ranks). Sampling leaves the steps' bits
/// alone.
#[test]
fn probes_on_gpu_ranks_read_what_one_gpu_reads() {
    let Some(ctx) = common::contexts().into_iter().next() else { return };
    let (every, steps) = (20, 120);
    let dam = with_probes(dam_break(1500), every, [[0.2, 0.2, 0.05], [0.38, 0.1, 0.05]], [[0.1, 0.0, 0.05], [0.3, 0.0, 0.05]]);
    // DFSPH: the points on the step's first state, the rest after the solves (the force from the
    // wall push of the solves' stiffness sums, which the device gives back), in a tank whose
    // slabs cut the vertical and whose floor carries the water.
    let tank = with_probes(Scene::builtin("hydrostatic").expect("built in").with_fluid_particles(2000), every, [[0.2, 0.2, 0.05], [0.1, 0.05, 0.05]], [[0.1, 0.0, 0.05], [0.3, 0.0, 0.05]]);
    // Weakly compressible in that tank: its gauges' lines cross the slabs, so the host samples.
    let mut weakly_compressible_tank = tank.clone();
    weakly_compressible_tank.name = "hydrostatic, slabs across the gauges".into();
    let dfsph = |mut scene: Scene, name: &str| {
        scene.name = name.into();
        scene.physics.solver = wgsph::model::scene::PressureSolver::Dfsph;
        scene.physics.stiffness = None;
        scene.physics.speed_of_sound = None;
        scene.time.dt = 0.001;
        scene
    };
    let dfsph_dam = dfsph(dam.clone(), "dam_break, DFSPH");
    let tank = dfsph(tank, "hydrostatic, DFSPH");
    for (scene, on_device) in [(dam, true), (dfsph_dam, true), (tank, false), (weakly_compressible_tank, false)] {
        probes_on_gpu_ranks_against_one_gpu(&ctx, &scene, steps, on_device);
    }
}

/// `on_device`: whether the ranks' devices sample the probes (else the host does).
fn probes_on_gpu_ranks_against_one_gpu(ctx: &GpuContext, scene: &Scene, steps: u64, on_device: bool) {
    let columns = probe_columns(scene);
    let device = GpuContext::from_adapter(ctx.adapter.clone()).expect("device");
    let mut sim = open(scene, &BackendChoice::gpu_on(device)).expect("opens");
    sim.step(steps).expect("steps");
    let one = sim.backend().take_probe_samples().expect("samples");
    let one_state = sim.snapshot().expect("snapshot");
    assert_eq!(one.len(), 6, "the states of steps 0, 20, ..., 100");
    let all = gpu_on_ranks(ctx, scene, 2, 0, &|b: &mut dyn Backend| {
        b.step(steps)?;
        Ok((b.take_probe_samples()?, b.snapshot()?, b.rank_report().expect("across ranks")))
    });
    if on_device {
        // The first step (and at most one whose band or merge outgrows its room) take the
        // full path.
        for (rank, (.., report)) in all.iter().enumerate() {
            assert!(report.stats.resident_steps + 2 >= steps, "{}: rank {rank} ran {} resident steps of {steps}, the probes sampled on the device", scene.name, report.stats.resident_steps);
        }
    }
    let (_, state, _) = &all[0];
    assert_eq!(largest_difference(&one_state, state), (0.0, 0.0), "{}: sampling probes leaves the steps' bits alone", scene.name);
    let last = &one.last().expect("samples").values;
    if scene.name.starts_with("hydrostatic") {
        assert!(last.iter().zip(&columns).any(|(v, c)| *c == "force" && v.abs() > 1.0), "{}: the tank carries the fluid: {last:?}", scene.name);
    }
    let mut largest: f64 = 0.0;
    for (rank, (samples, ..)) in all.iter().enumerate() {
        assert_eq!(samples.len(), one.len(), "{}: rank {rank}", scene.name);
        for (a, b) in one.iter().zip(samples) {
            assert_eq!((a.step, a.time), (b.step, b.time));
            // A force's components against the largest of them (a small one is a difference of
            // large terms).
            let force = a.values.iter().zip(&columns).filter(|(_, c)| **c == "force").map(|(v, _)| v.abs()).fold(1.0, f64::max);
            for ((x, y), c) in a.values.iter().zip(&b.values).zip(&columns) {
                // f32 rounding of the probes' sums, relative to the column's size (a pressure or
                // density near zero is compared at the scale of rho0 and rho0 g times 0.1 m).
                let scale = match *c { "pressure_Pa" | "density_kg_m3" => 1000.0, "force" => force, _ => 1.0 };
                largest = largest.max((x - y).abs() / x.abs().max(scale));
                if on_device && *c != "force" {
                    assert!(x.to_bits() == y.to_bits(), "{}: rank {rank}, step {}, {c}: one GPU {x}, GPU ranks {y}, bit for bit", scene.name, a.step);
                }
                assert!((x - y).abs() <= 1e-5 * x.abs().max(scale), "{}: rank {rank}, step {}, {c}: one GPU {x}, GPU ranks {y}", scene.name, a.step);
            }
        }
    }
    eprintln!("{}: probes on GPU ranks against one GPU: largest relative difference {largest:.2e}", scene.name);
}

/// DFSPH on GPU ranks: the host runs each solve's loop, the ghosts take their owners' velocities
/// after every velocity change (read back, exchanged, written again), the shaders leave the
/// ghosts out of the error sums and the adaptive step's maxima, which the ranks add or compare,
/// and the warm starts travel with the particles, also through the resident steps' band and
/// merge; so N ranks run one GPU's iterations with its dt and compute its bits, through
/// migration and moving bounds.
#[test]
fn dfsph_on_gpu_ranks_computes_bit_for_bit_what_one_gpu_computes() {
    let Some(ctx) = common::contexts().into_iter().next() else { return };
    for (scene, ranks) in dfsph_scenes() {
        let device = GpuContext::from_adapter(ctx.adapter.clone()).expect("device");
        let mut single = open(&scene, &BackendChoice::gpu_on(device)).expect("opens");
        let (one, iterations, dt) = forty_dfsph_steps(&mut single, &scene.name);
        let all = gpu_on_ranks(&ctx, &scene, ranks, 10, &|b: &mut dyn Backend| {
            // In batches, as a run's health checks cut them: the particles and their warm
            // starts stay on the device from one to the next.
            for _ in 0..4 {
                b.step(10)?;
            }
            Ok((b.snapshot()?, b.health()?, b.dt_stats()?, b.rank_report().expect("across ranks")))
        });
        // The counts, not the average error, which one GPU divides in f32 and the host in f64.
        let counts = |s: &wgsph::model::state::SolveStats| (s.total, s.max, s.last, s.unconverged);
        for (rank, (_, h, d, _)) in all.iter().enumerate() {
            assert!(h.is_ok(), "{}: rank {rank} healthy: {h:?}", scene.name);
            let its = h.iterations.expect("DFSPH counts its iterations");
            assert_eq!((counts(&its.pressure), counts(&its.divergence)), (counts(&iterations.pressure), counts(&iterations.divergence)), "{}: rank {rank} of {ranks} iterates as one GPU", scene.name);
            assert_eq!((d.min, d.max, d.last), (dt.min, dt.max, dt.last), "{}: rank {rank} of {ranks} steps with one GPU's dt", scene.name);
        }
        assert!(all.iter().any(|r| r.3.stats.ghosts > 0), "{}: ranks hold ghosts", scene.name);
        // Resident steps: the band and the received particles carry the warm starts, and the
        // device makes the solves' link from its binning. On the dam break, against the same 40
        // steps on the full path (every held particle up and down with its warm starts and id,
        // and the cell starts): fewer bytes on every rank.
        for (rank, (.., report)) in all.iter().enumerate() {
            assert!(report.stats.resident_steps > 0, "{}: rank {rank} of {ranks} ran no resident step", scene.name);
        }
        if scene.name == "dam_break" {
            let full_exchange = GpuOptions { full_exchange: true, ..GpuOptions::default() };
            let full = gpu_on_ranks_with(&ctx, &scene, ranks, 10, full_exchange, &|b: &mut dyn Backend| {
                b.step(40)?;
                Ok(b.rank_report().expect("across ranks"))
            });
            for (rank, ((.., report), full)) in all.iter().zip(&full).enumerate() {
                assert_eq!(full.stats.resident_steps, 0, "{}: rank {rank} of {ranks} without batches", scene.name);
                assert!(report.stats.bus_bytes < full.stats.bus_bytes, "{}: rank {rank} moved {} bytes with resident steps, {} without", scene.name, report.stats.bus_bytes, full.stats.bus_bytes);
            }
        }
        // With adaptive dt the time is summed on the host in f64 across ranks, a compensated
        // f32 sum on one GPU: the same to rounding.
        let many = &all[0].0;
        assert!((many.time - one.time).abs() <= 1e-6 * one.time.max(1e-30), "{}: time {} against {}", scene.name, many.time, one.time);
        let many = Snapshot { time: one.time, ..many.clone() };
        let (dx, drho) = largest_difference(&one, &many);
        assert!(many == one, "{}: {ranks} GPU ranks against one GPU, bit for bit (largest differences: position {dx:e}, density {drho:e})", scene.name);
    }
}

/// The ghost velocities stage (wgsl/sim/ghost_velocities.wgsl), with which DFSPH's solves on
/// GPU ranks exchange only the face layers, against its CPU twin: the velocities of some slots
/// gathered (one slot twice, as a particle of a thin slab goes to both neighbours), others
/// replaced by given values.
#[test]
fn the_ghost_velocities_stage_agrees_with_its_cpu_twin() {
    use wgsph::model::real::V3;
    use wgsph::solver::cpu::ghost_velocities::{gather_ghost_velocities, scatter_ghost_velocities};
    for ctx in common::contexts() {
        let scene = TestScene::small_tank().dfsph().build();
        let mut gpu = common::gpu(GpuContext::from_adapter(ctx.adapter.clone()).unwrap(), &scene);
        gpu.step(3).unwrap();
        let n = Backend::fluid_count(&gpu) as u32;
        let mut sent: Vec<u32> = (0..n).step_by(7).collect();
        sent.push(sent[1]);
        let received: Vec<u32> = (3..n).step_by(11).collect();
        let values: Vec<[f32; 3]> = received.iter().map(|&i| [i as f32, -0.5 * i as f32, 0.25]).collect();
        let (before, gathered, after) = gpu.ghost_velocities_alone(&sent, &received, &values).unwrap();
        let xyz = |v: &[[f32; 4]]| v.iter().map(|v| V3([v[0], v[1], v[2]])).collect::<Vec<V3<f32>>>();
        let mut twin = xyz(&before);
        assert!(twin.iter().any(|v| v.0 != [0.0; 3]), "the tank moves after 3 steps");
        let slots = |s: &[u32]| s.iter().map(|&i| i as usize).collect::<Vec<usize>>();
        assert!(xyz(&gathered) == gather_ghost_velocities(&twin, &slots(&sent)), "{}: gathered", ctx.describe());
        scatter_ghost_velocities(&mut twin, &slots(&received), &values.iter().map(|&v| V3(v)).collect::<Vec<_>>());
        assert!(xyz(&after) == twin, "{}: scattered", ctx.describe());
    }
}

/// The ghost link stage (wgsl/sim/ghost_link.wgsl), with which DFSPH's solves on GPU ranks make
/// their link from the device's binning, against its CPU twin: the link's cells' bounds in the
/// cell starts; and the lists joined from them are the slots whose particles lie in each list's
/// layers (what the host's rule gives from the positions). On a dam break, slabs across x and
/// z with a face inside the fluid, one with both neighbours and one thinner than its ghost
/// layers.
#[test]
fn the_ghost_link_stage_agrees_with_its_cpu_twin() {
    use wgsph::solver::cpu::ghost_link::{link_cell_bounds, link_cells, link_slots};
    use wgsph::solver::cpu::resident_exchange::SlabFaces;
    for ctx in common::contexts() {
        let scene = dam_break(1000);
        let mut gpu = common::gpu(ctx.clone(), &scene);
        gpu.step(3).expect("steps");
        let grid = scene.params().grid.cast::<f32>();
        let end = grid.cell_coords(wgsph::model::real::V3(scene.fluid[0].max.map(|x| x as f32)));
        let mid = grid.cell_coords(wgsph::model::real::V3(scene.fluid[0].min.map(|x| x as f32)));
        for faces in [
            SlabFaces { axis: 0, slab: mid[0] + 2..end[0], halo: 2, lower: true, upper: true },
            SlabFaces { axis: 2, slab: mid[2] + 1..mid[2] + 2, halo: 2, lower: true, upper: true },
            SlabFaces { axis: 0, slab: 0..end[0] - 1, halo: 1, lower: false, upper: true },
        ] {
            let who = format!("{faces:?} on {}", ctx.describe());
            let (positions, starts, bounds) = gpu.ghost_link_alone(&faces).expect("the stage runs");
            let lists = link_cells(grid.dims, &faces);
            assert_eq!(bounds, link_cell_bounds(&starts, &lists.concat()), "{who}: the cells' bounds");
            // The rule on the positions: own particles (in the slab) within halo layers of a face
            // with a neighbour, and the particles in the halo layers beyond each such face.
            let layer = |p: &[f32; 4]| grid.cell_coords(wgsph::model::real::V3([p[0], p[1], p[2]]))[faces.axis];
            let (s, e, h) = (faces.slab.start, faces.slab.end, faces.halo);
            let rules: [&dyn Fn(u32) -> bool; 4] = [
                &|l| faces.lower && l >= s && l < e && l < s + h,
                &|l| faces.upper && l >= s && l < e && l + h >= e,
                &|l| faces.lower && l + h >= s && l < s,
                &|l| faces.upper && l >= e && l < e + h,
            ];
            let expected = rules.map(|rule| (0..positions.len()).filter(|&i| rule(layer(&positions[i]))).collect::<Vec<usize>>());
            assert_eq!(link_slots(&lists, &bounds), expected, "{who}: the lists");
            assert!(expected[1].len() + expected[3].len() > 0, "{who}: the face lies in the fluid");
        }
    }
}

/// The resident exchange's stage (wgsl/sim/resident_exchange.wgsl), with which a GPU rank keeps
/// its particles on the device between steps, against its CPU twin on the same state: the
/// slots dropped (ghosts and particles outside the slab) and the band listed (with their places
/// in the one-process order), the own particles' health and their counts per cell layer, and
/// the merge of the kept particles with received ones, which must put every particle where the
/// twin puts it. On the dam break
/// (summed density in the velocities' w), a tank with continuity density (its own array) and a
/// DFSPH tank (positions holding places, whose ids and warm starts the band carries and the
/// merge moves to the new slots), a slab that ends inside the fluid, every seventh slot marked a
/// ghost.
#[test]
fn the_resident_exchange_stage_agrees_with_its_cpu_twin() {
    use wgsph::solver::cpu::resident_exchange::{at_place, count_layers, merge_kept, own_health, place_inserts, place_w, select_band, SlabFaces};
    let bits = |v: &[[f32; 4]]| v.iter().map(|x| x.map(f32::to_bits)).collect::<Vec<_>>();
    for ctx in common::contexts() {
        for scene in [dam_break(1000), TestScene::small_tank().continuity().build(), TestScene::small_tank().dfsph().build()] {
            let dfsph = scene.params().dfsph.is_some();
            let mut gpu = common::gpu(ctx.clone(), &scene);
            gpu.step(5).expect("steps");
            let params = scene.params();
            let grid = params.grid.cast::<f32>();
            let dims = grid.dims;
            // The slab ends at the layer of the fluid's far end: the particles beyond leave, those
            // of the layer before it are the upper neighbour's ghosts.
            let end = grid.cell_coords(wgsph::model::real::V3(scene.fluid[0].max.map(|x| x as f32)))[0];
            let faces = SlabFaces { axis: 0, slab: 1..end, halo: 1, lower: true, upper: true };
            let n = gpu.fluid_count() as u32;
            let ghosts: Vec<u32> = (0..n).filter(|i| i % 7 == 3).collect();
            // Received particles in cells outside the slab (which hold only dropped slots), at
            // places inside and past each cell's particles, sorted by place (with DFSPH, warm
            // starts in the velocity's w and beside it).
            let mut received = Vec::new();
            for (k, x) in [faces.slab.start - 1, faces.slab.end].into_iter().enumerate() {
                for y in [0, dims[1] / 4] {
                    for place in [0u64, 1, 40] {
                        let cell = (x + dims[0] * (y + dims[1])) as u64;
                        let id = 100_000 + received.len() as u32;
                        received.push(([0.1 * k as f32, y as f32, place as f32, f32::from_bits(id | 0x8000_0000)], [1.0, 2.0, 3.0, 1000.0 + place as f32], cell << 32 | place, -(id as f32)));
                    }
                }
            }
            received.sort_by_key(|r| r.2);
            // With DFSPH one GPU's positions hold ids 0..n, taken as places whose ids are these.
            let place_ids: Vec<u32> = (0..n).map(|p| 50_000 + 3 * p).collect();
            let run = gpu.resident_exchange_alone(&faces, &ghosts, &received, dfsph.then_some(&place_ids[..])).expect("the stage runs");
            let who = format!("{} on {}", scene.name, ctx.describe());
            assert_eq!(run.places.is_some(), dfsph, "{who}: the places' arrays");
            // The band and the dropped slots, in slot order (the device lists them in any order).
            let (dropped, band) = select_band(&run.positions, &run.starts, &grid, &faces);
            let mut device_dropped = run.band.dropped.clone();
            device_dropped.sort_unstable();
            assert_eq!(device_dropped, dropped, "{who}: dropped slots");
            assert!(dropped.len() > ghosts.len() && !band.is_empty(), "{who}: the slab leaves particles outside it and near its faces");
            let mut device_band: Vec<(u32, u64)> = (0..run.band.entries.len()).map(|k| (run.band.slot(k), run.band.key(k))).collect();
            device_band.sort_unstable();
            assert_eq!(device_band, band, "{who}: the band's slots and places");
            for (k, &[position, velocity, key]) in run.band.entries.iter().enumerate() {
                let slot = run.band.slot(k);
                let (mut p, mut v) = (run.positions[slot as usize], run.velocities[slot as usize]);
                if let Some([before, _]) = &run.places {
                    // The id in the position's w, the warm starts in the velocity's w and beside it.
                    let [pressure, divergence, id] = at_place(p[3], &[0, 1, 2].map(|a| before.iter().map(|e| e[a]).collect()));
                    (p[3], v[3]) = (f32::from_bits(id), f32::from_bits(pressure));
                    assert_eq!(key[3].to_bits(), divergence, "{who}: band slot {slot}'s divergence warm start");
                    assert!(id >= 50_000, "{who}: band slot {slot} carries an id of the places");
                }
                assert_eq!(bits(&[position, velocity]), bits(&[p, v]), "{who}: band slot {slot}");
            }
            // The health of the own particles.
            let domain = (params.domain_min.map(|x| x as f32), params.domain_max.map(|x| x as f32));
            assert_eq!(run.health, own_health(&run.positions, &run.velocities, run.densities.as_deref(), domain), "{who}: health");
            assert!(run.health.max_density > 900.0 && run.health.max_speed2 > 0.0, "{who}: {:?}", run.health);
            // The own particles per cell layer of the slab axis.
            let layers = count_layers(&run.positions, &grid, faces.axis);
            assert_eq!(run.layer_counts, layers, "{who}: layer counts");
            assert_eq!(layers.iter().sum::<u32>() as usize, run.positions.len() - ghosts.len(), "{who}: every own particle counted once");
            // The merge: every kept particle and every received one where the twin puts it.
            let keys: Vec<u64> = received.iter().map(|r| r.2).collect();
            let (places, slots) = place_inserts(&run.starts, &dropped, &keys);
            let kept = merge_kept(n as usize, &dropped, &places);
            let total = n as usize - dropped.len() + received.len();
            let (mut positions, mut velocities) = (vec![[f32::NAN; 4]; total], vec![[f32::NAN; 4]; total]);
            let mut merged_places = vec![[u32::MAX; 3]; total];
            for (i, slot) in kept.iter().enumerate() {
                if let Some(slot) = slot {
                    let (s, mut p) = (*slot as usize, run.positions[i]);
                    if let Some([before, _]) = &run.places {
                        merged_places[s] = at_place(p[3], &[0, 1, 2].map(|a| before.iter().map(|e| e[a]).collect()));
                        p[3] = place_w(*slot, p[3]);
                    }
                    positions[s] = p;
                    velocities[s] = run.velocities[i];
                }
            }
            for (j, &slot) in slots.iter().enumerate() {
                let (s, (mut p, mut v, _, divergence)) = (slot as usize, received[j]);
                if dfsph {
                    merged_places[s] = [v[3].to_bits(), divergence.to_bits(), p[3].to_bits() & !0x8000_0000];
                    (p[3], v[3]) = (place_w(slot, p[3]), 0.0);
                }
                positions[s] = p;
                velocities[s] = v;
            }
            assert!(positions.iter().all(|p| !p[0].is_nan()), "{who}: the twin fills every slot once");
            assert_eq!(bits(&run.merged_positions), bits(&positions), "{who}: merged positions");
            assert_eq!(bits(&run.merged_velocities), bits(&velocities), "{who}: merged velocities");
            if let Some([_, after]) = &run.places {
                assert_eq!(after, &merged_places, "{who}: each new place's warm starts and id");
                assert!(merged_places.iter().any(|m| m[0] != 0), "{who}: the tank's warm starts are not all zero");
            }
        }
    }
}

/// The steps of a GPU rank that keep its particles on the device (only the band next to the
/// faces read back, the neighbours' particles merged in on the device: src/solver/cpu/
/// resident_steps.rs) compute what one GPU computes, bit for bit: with summed and with
/// continuity density, fixed and adaptive dt, bounds moving every 10 steps, in batches of 5
/// steps with a snapshot after the fifth batch. The particles stay on the device from one batch
/// to the next, and the steps that move the bounds count the particles per layer on the device:
/// only the first step, the step after the snapshot and at most two steps whose band or merge
/// outgrows the room (which then grows) take the full path, where the first step of each batch
/// would add four more and the full path's balance four. The bounds move as the full path
/// moves them. Between batches each rank counts its own particles, which the
/// host's arrays do not hold then, as the full path (every held particle read back after every
/// step) counts them. Every rank moves fewer bytes over the bus than the full path would.
#[test]
fn resident_gpu_rank_steps_compute_what_one_gpu_computes() {
    let Some(ctx) = common::contexts().into_iter().next() else { return };
    let mut adaptive = dam_break(4000);
    adaptive.time.adaptive = true;
    for (scene, ranks) in [(dam_break(4000), 2), (TestScene::small_tank().continuity().density_diffusion(0.1).build(), 2), (adaptive, 3), (moving_block_akinci_adami(), 3)] {
        // The block moves the bounds after some 50 steps.
        let (batch, batches, snapshot_after) = if scene.name == "block" { (10, 10, 5) } else { (5, 9, 5) };
        let steps = batch * batches;
        let (one_at_snapshot, one) = (one_gpu(&ctx, &scene, batch * snapshot_after), one_gpu(&ctx, &scene, steps));
        let work = |b: &mut dyn Backend| {
            let (mut own, mut at_snapshot) = (Vec::new(), None);
            for k in 1..=batches {
                b.step(batch)?;
                own.push(b.rank_report().expect("across ranks").own_particles);
                if k == snapshot_after {
                    at_snapshot = Some(b.snapshot()?);
                    own.push(b.rank_report().expect("across ranks").own_particles);
                }
            }
            Ok((b.rank_report().expect("across ranks"), b.snapshot()?, own, at_snapshot.expect("taken")))
        };
        let runs = gpu_on_ranks(&ctx, &scene, ranks, 10, &work);
        let full = gpu_on_ranks_with(&ctx, &scene, ranks, 10, GpuOptions { full_exchange: true, ..GpuOptions::default() }, &work);
        let many = Snapshot { time: one_at_snapshot.time, ..runs[0].3.clone() };
        assert!(many == one_at_snapshot, "{}: {ranks} GPU ranks with resident steps against one GPU at the snapshot between batches, bit for bit", scene.name);
        let many = Snapshot { time: one.time, ..runs[0].1.clone() };
        assert!(many == one, "{}: {ranks} GPU ranks with resident steps against one GPU, bit for bit", scene.name);
        assert!(full[0].1 == runs[0].1, "{}: the full path's last snapshot", scene.name);
        for (rank, (resident, full)) in runs.iter().zip(&full).enumerate() {
            assert_eq!(resident.2, full.2, "{}: rank {rank}'s own particles after each batch (and the snapshot), resident and full path", scene.name);
            assert_eq!(full.0.stats.resident_steps, 0, "{}: rank {rank} on the full path", scene.name);
            assert_eq!((&resident.0.bounds, resident.0.stats.rebalances), (&full.0.bounds, full.0.stats.rebalances), "{}: rank {rank}'s slab bounds and their moves, resident and full path", scene.name);
        }
        if scene.name == "block" {
            assert!(runs[0].0.stats.rebalances > 0, "{}: the bounds moved", scene.name);
        }
        for k in 0..runs[0].2.len() {
            let own: Vec<usize> = runs.iter().map(|r| r.2[k]).collect();
            assert_eq!(own.iter().sum::<usize>(), one.positions.len(), "{}: the ranks' own particles at count {k}: {own:?}", scene.name);
        }
        // The full path moves per step 32 bytes per held particle up, 48 (80 with the densities
        // read from the velocities' w) down, and the cell starts.
        let cells = scene.params().grid.cell_count() as u64 + 1;
        for (rank, (report, ..)) in runs.iter().enumerate() {
            let stats = &report.stats;
            let held = (report.own_particles + stats.ghosts) as u64;
            let full = steps * (112 * held + 4 * cells);
            assert!(stats.resident_steps + 4 >= steps, "{}: rank {rank} ran {} resident steps of {steps}: the full path but for the first, the step after the snapshot and two bands or merges that outgrew their room", scene.name, stats.resident_steps);
            assert!(stats.bus_bytes < full, "{}: rank {rank} moved {} bytes, the full path's {full} for {held} held particles", scene.name, stats.bus_bytes);
        }
    }
}
