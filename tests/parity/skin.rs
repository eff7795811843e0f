//! The neighbour skin (wgsl/sim/neighbour_skin.wgsl): the grid, the particles' order and the
//! neighbour lists kept between rebuilds, rebuilt once they may miss a neighbour (the check
//! decides as its twin does). With a skin the tiled density walking the lists, the tiles alone
//! and one particle per invocation give the same bits; the run follows the one without a skin
//! to the rounding of its sums; snapshots leave its bits as they were, and a run resumed from a
//! saved state keeps the bits of the run that saved it; a scene it cannot serve is refused by
//! name.

use crate::common;
use crate::common::TestScene;

use wgsph::model::scene::{BoundaryPressure, EquationOfState, Kernel, Scene};
use wgsph::solver::gpu::{GpuError, GpuOptions};
use wgsph::solver::Backend;

const SKIN: f64 = 0.1;

fn skin(options: GpuOptions) -> GpuOptions {
    GpuOptions { neighbour_skin: Some(SKIN), ..options }
}

/// `scene` on `ctx` with the skin and the other options' defaults.
fn skinned(ctx: &wgsph::solver::gpu::GpuContext, scene: &Scene) -> wgsph::solver::gpu::GpuSolver {
    common::gpu_with(ctx.clone(), scene, None, skin(GpuOptions::default())).unwrap()
}

/// The rebuilds a skinned solver has made so far.
fn rebuilds(solver: &wgsph::solver::gpu::GpuSolver) -> u64 {
    solver.neighbour_skin().expect("a skin").1
}

fn scenes() -> Vec<(&'static str, Scene)> {
    let tank = || TestScene::small_tank();
    vec![
        ("small tank (walls, plane, viscosity)", tank().build()),
        ("cubic spline, linear, unclamped", tank().kernel(Kernel::CubicSpline).equation_of_state(EquationOfState::Linear).clamp_negative_pressure(false).build()),
        ("Adami wall pressure, artificial viscosity, surface tension, adhesion", tank().boundary_pressure(BoundaryPressure::Adami).viscosity(0.0).artificial_viscosity(0.1).surface_tension(0.5).wall_adhesion(2.0).build()),
        ("continuity, diffusion, hydrostatic start", tank().continuity().density_diffusion(0.1).hydrostatic_start().build()),
        ("continuity, Adami wall pressure", tank().continuity().boundary_pressure(BoundaryPressure::Adami).build()),
        ("planes only", tank().without_walls().plane([0.0; 3], [0.0, 1.0, 0.0], 0.5).build()),
        ("solid box", tank().solid_box([0.3, 0.0, 0.05], [0.4, 0.1, 0.15]).build()),
        ("dam break", Scene::load("dam_break").unwrap().with_fluid_particles(2000)),
    ]
}

/// The scenes (indices into `scenes`) on which a skin's walks are compared with each other, and
/// the ones an adapter after the first runs: Adami's wall pressure with artificial viscosity,
/// surface tension and adhesion,
/// continuity density with diffusion, and the dam break (its walls and viscosity).
const WALKS_COMPARED_ON: [usize; 3] = [2, 3, 7];

/// The largest distance between the same particle's positions in two snapshots.
fn largest_gap(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter().zip(b).map(|(p, q)| (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f64>().sqrt()).fold(0.0, f64::max)
}

#[test]
fn a_skin_keeps_every_neighbour() {
    for (k, ctx) in common::contexts().into_iter().enumerate() {
        let tiles = ctx.subgroup_tiles_unavailable().is_none();
        for (i, (name, scene)) in scenes().into_iter().enumerate() {
            // The first adapter runs every scene, another (the same WGSL through another
            // driver) those of `WALKS_COMPARED_ON` (docs/testing.md: the suite's time budget).
            if k > 0 && !WALKS_COMPARED_ON.contains(&i) {
                continue;
            }
            let steps = 60;
            let run = |options: GpuOptions| {
                let mut solver = common::gpu_with(ctx.clone(), &scene, None, options).unwrap();
                solver.step(steps).unwrap();
                let rebuilds = solver.neighbour_skin().map(|(_, r)| r);
                (rebuilds, solver.snapshot().unwrap(), solver.step_fields().unwrap())
            };
            let (rebuilds, state, fields) = run(skin(GpuOptions::default()));
            let rebuilds = rebuilds.expect("a skin was asked for");
            // The first step rebuilds; the particles move, so some later ones do, but not all.
            assert!(rebuilds >= 1 && rebuilds < steps, "{name} on {}: {rebuilds} rebuilds in {steps} steps", ctx.describe());
            // The lists of the last rebuild, the tiles on its cells and one particle per
            // invocation on them: the same neighbours in the same order, the same bits. The
            // walks are the same code for every scene, so they are compared on the scenes whose
            // terms cover the others'; each walk against the others on every term without a
            // skin is tests/parity/tiles.rs's.
            let mut others = vec![];
            if WALKS_COMPARED_ON.contains(&i) {
                others.push((skin(GpuOptions { subgroup_tiles: Some(false), ..GpuOptions::default() }), "one particle per invocation"));
                if tiles {
                    others.push((skin(GpuOptions { neighbour_lists: Some(false), ..GpuOptions::default() }), "tiles without lists"));
                    others.push((skin(GpuOptions { neighbour_list_capacity: Some(4), ..GpuOptions::default() }), "lists of 4 slots"));
                }
            }
            for (options, what) in others {
                let (r, other_state, other_fields) = run(options);
                assert_eq!(r, Some(rebuilds), "{name} on {}: {what} rebuilt at other steps", ctx.describe());
                assert!(other_state == state && other_fields == fields, "{name} on {}: {what} changed a value", ctx.describe());
            }
            // Without a skin: the same neighbours, summed with the particles in another order.
            let (_, plain, _) = run(GpuOptions::default());
            assert!(plain.positions != scene.initial_state().fluid_positions, "{name}: the particles moved");
            let h = scene.physics.smoothing_length;
            let gap = largest_gap(&plain.positions, &state.positions);
            assert!(gap < 1e-3 * h, "{name} on {}: with the skin a particle ends {gap} m from its place without (h = {h})", ctx.describe());
        }
    }
}

/// The GPU's check (wgsl/sim/neighbour_skin.wgsl) and its twin decide alike after every step:
/// the twin, given the positions after each step and those of the last rebuild, says whether
/// the next step rebuilds, and the GPU's rebuilds follow it (a snapshot makes the rebuild that
/// is due, so the count after it tells the GPU's decision).
#[test]
fn the_check_decides_as_its_twin() {
    use wgsph::solver::cpu::neighbour_skin::{check_skin, skin_reach};
    use wgsph::model::real::V3;
    let scene = Scene::load("dam_break").unwrap().with_fluid_particles(2000);
    let reach = skin_reach::<f32>(SKIN, scene.physics.smoothing_length);
    let as_f32 = |p: &[[f64; 3]]| p.iter().map(|x| V3(x.map(|v| v as f32))).collect::<Vec<_>>();
    for ctx in common::contexts() {
        let mut solver = skinned(&ctx, &scene);
        let mut rebuild_positions = as_f32(&solver.snapshot().unwrap().positions);
        assert_eq!(rebuilds(&solver), 1, "on {}: the first snapshot rebuilds", ctx.describe());
        let (mut due_count, mut kept_count) = (0, 0);
        for step in 1..=80 {
            solver.step(1).unwrap();
            let before = rebuilds(&solver);
            let positions = as_f32(&solver.snapshot().unwrap().positions);
            let gpu_due = rebuilds(&solver) > before;
            let twin_due = check_skin(&positions, &rebuild_positions, reach).rebuild_due(reach);
            assert_eq!(gpu_due, twin_due, "on {}: after step {step} the GPU's check and its twin disagree", ctx.describe());
            if twin_due {
                rebuild_positions = positions;
                due_count += 1;
            } else {
                kept_count += 1;
            }
        }
        assert!(due_count > 0 && kept_count > 0, "on {}: {due_count} rebuilds and {kept_count} steps without", ctx.describe());
    }
}

#[test]
fn snapshots_leave_a_skinned_run_as_it_was() {
    // A snapshot evaluates the fields of the state it reads; with a skin it rebuilds only where
    // the next step would have, so a run read every few steps keeps the bits of one read once.
    let scene = Scene::load("dam_break").unwrap().with_fluid_particles(2000);
    for ctx in common::contexts() {
        let mut read_often = skinned(&ctx, &scene);
        for _ in 0..10 {
            read_often.step(7).unwrap();
            read_often.snapshot().unwrap();
        }
        let mut read_once = skinned(&ctx, &scene);
        read_once.step(70).unwrap();
        assert!(read_often.snapshot().unwrap() == read_once.snapshot().unwrap(), "on {}: snapshots changed the run's bits", ctx.describe());
        assert_eq!(rebuilds(&read_often), rebuilds(&read_once), "on {}", ctx.describe());
    }
}

#[test]
fn a_run_resumed_with_a_skin_keeps_the_bits() {
    let scene = Scene::load("dam_break").unwrap().with_fluid_particles(2000);
    for ctx in common::contexts() {
        let mut first = skinned(&ctx, &scene);
        first.step(25).unwrap();
        let saved = first.save_state().unwrap();
        first.step(25).unwrap();
        let mut resumed = skinned(&ctx, &scene);
        resumed.restore_state(&saved).unwrap();
        resumed.step(25).unwrap();
        assert_eq!(first.neighbour_skin().map(|s| s.0), resumed.neighbour_skin().map(|s| s.0));
        assert!(first.snapshot().unwrap() == resumed.snapshot().unwrap(), "on {}: the resumed run left the bits of the run that saved the state", ctx.describe());
    }
}

#[test]
fn a_skin_is_refused_where_it_cannot_serve() {
    let tank = || TestScene::small_tank();
    for ctx in common::contexts() {
        let mut every_2nd_step = tank().build();
        every_2nd_step.time.neighbour_rebuild_every = 2;
        for (scene, named) in [(tank().dfsph().build(), "physics.solver = \"dfsph\""), (every_2nd_step, "time.neighbour_rebuild_every = 2")] {
            let e = common::gpu_with(ctx.clone(), &scene, None, skin(GpuOptions::default())).err().expect("refused");
            assert!(matches!(e.downcast_ref::<GpuError>(), Some(GpuError::NoNeighbourSkin(_))), "{e:#}");
            let msg = format!("{e:#}");
            assert!(msg.contains("--neighbour-skin 0.1") && msg.contains(named), "{msg}");
        }
        for bad in [0.0, -0.1, 1.5, f64::NAN] {
            let e = common::gpu_with(ctx.clone(), &tank().build(), None, GpuOptions { neighbour_skin: Some(bad), ..GpuOptions::default() }).err().expect("refused");
            assert!(format!("{e:#}").contains("must be above 0 and at most 1"), "{bad}: {e:#}");
        }
    }
}
