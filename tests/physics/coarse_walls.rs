//! Walls hold at every resolution `--particles` accepts: the built-in scenes at the fewest
//! particles they allow, and the hydrostatic tank at the 500 particles that lost one through a
//! corner, run long on the f32 CPU path (the GPU's arithmetic; cheap at these sizes), with no
//! particle leaving the domain or getting past the first layer of a wall.

use crate::common;

use wgsph::model::diagnosis::SolidIntrusions;
use wgsph::model::scene::Scene;
use wgsph::solver::Backend;

/// Runs `scene` for `steps` steps in pieces of `every`, checking after each that the run is
/// healthy and that no fluid particle is inside a solid.
fn holds(scene: &Scene, steps: u64, every: u64) {
    let mut cpu = common::cpu::<f32>(scene);
    let mut done = 0;
    while done < steps {
        cpu.step(every.min(steps - done));
        done = cpu.steps_done();
        let health = cpu.health();
        assert!(health.is_ok(), "{} ({} particles): bad at step {done}: {health:?}", scene.name, cpu.fluid_len());
        let mut inside = SolidIntrusions::new(scene);
        for x in cpu.snapshot().positions {
            inside.add(x);
        }
        assert!(inside.found().is_empty(), "{} ({} particles), step {done}: {:?}", scene.name, cpu.fluid_len(), inside.found());
    }
}

#[test]
fn every_built_in_scene_holds_its_fluid_at_the_fewest_particles_it_allows() {
    // (scene, steps): the hydrostatic tank for 15 s of simulated time at its coarsest dt
    // (2.5 times its own), the dam break for three times its 1.5 s, the seed for its 60 s.
    for (name, steps) in [("hydrostatic", 20_000), ("dam_break", 7_200), ("seed", 240)] {
        let scene = Scene::builtin(name).unwrap();
        let fewest = scene.fewest_fluid_particles();
        let coarsest = scene.at_fluid_particles(fewest).unwrap();
        assert_eq!(coarsest.fluid_particle_count(), fewest, "{name}");
        assert!(scene.at_fluid_particles(fewest - 1).is_err(), "{name}: fewer than the fewest accepted");
        holds(&coarsest, steps, 1000);
    }
}

#[test]
fn the_hydrostatic_tank_at_500_particles_keeps_every_particle_with_wall_particles_alone() {
    // It lost one through a tank corner at about step 16,600: the walls beyond the tank's far
    // faces were one layer thick where the tank was not a whole number of spacings. Without
    // the planes the scene now has, the wall particles alone must hold it.
    let scene = Scene::builtin("hydrostatic").unwrap().at_fluid_particles(500).unwrap();
    let walls_alone = common::TestScene::from(scene).without_planes().build();
    holds(&walls_alone, 20_000, 2000);
}

#[test]
fn a_hard_impact_on_a_solid_box_loses_no_particle_into_it() {
    // A block thrown at 6 m/s (Mach 0.3 at c0 = 20 m/s) without gravity, in a closed tank, at a
    // box obstacle one wall layer thick standing on the floor: the impact drives particles through the layer of wall particles, and the
    // box's faces put each back on the face it crossed. Checked every 5 steps through the
    // impact and the splash, on the f32 CPU path and the GPU.
    let (lo, hi) = ([0.3, 0.0, 0.0], [0.36, 0.3, 0.2]);
    let scene = common::TestScene::new()
        .gravity([0.0; 3])
        .fluid([0.0, 0.06, 0.04], [0.12, 0.24, 0.16])
        .jitter(0.0)
        .moving_at([6.0, 0.0, 0.0])
        .dt(0.0002)
        .solid_box(lo, hi)
        .wall_layers(1)
        // A closed tank around it keeps the splash in the domain.
        .closed_container([0.0; 3], [0.6, 0.8, 0.2])
        .without_limits()
        .end_time(0.05)
        .build();
    // Deeper inside than the f32 rounding of a particle put back on a face (1e-3 spacings, as the
    // validation cases count).
    let margin = 1e-3 * 0.02;
    let inside = |positions: &[[f64; 3]]| positions.iter().filter(|x| (0..3).all(|k| x[k] > lo[k] + margin && x[k] < hi[k] - margin)).count();
    // Deepest a particle reached past the box's -x face.
    let depth = |positions: &[[f64; 3]]| positions.iter().filter(|x| x[1] > lo[1] && x[1] < hi[1] && x[2] > lo[2] && x[2] < hi[2]).map(|x| (x[0] - lo[0]).min(hi[0] - x[0])).fold(f64::MIN, f64::max);
    let steps = (0.05 / scene.time.dt) as u64;
    let mut cpu = common::cpu::<f32>(&scene);
    let mut reached = f64::MIN;
    for _ in 0..steps / 5 {
        cpu.step(5);
        let s = cpu.snapshot();
        assert_eq!(inside(&s.positions), 0, "cpu f32, step {}: fluid particles inside the box", s.step);
        reached = reached.max(depth(&s.positions));
    }
    // The splash is violent (a few particles leave the tank at tens of m/s); none is lost to NaN.
    assert_eq!(cpu.health().non_finite, 0, "{:?}", cpu.health());
    // The impact reached the box (particles on its face), so the test pushed at it.
    assert!(reached >= -0.25 * scene.physics.particle_spacing, "the block came no closer than {} m to the box", -reached);
    for ctx in common::contexts() {
        let who = ctx.describe();
        let mut gpu = common::gpu(ctx, &scene);
        for _ in 0..steps / 5 {
            gpu.step(5).unwrap();
            let s = gpu.snapshot().unwrap();
            assert_eq!(inside(&s.positions), 0, "{who}, step {}: fluid particles inside the box", s.step);
        }
        assert_eq!(gpu.health().unwrap().non_finite, 0, "{who}");
    }
}

#[test]
fn more_solid_boxes_than_the_parameter_block_holds_are_refused_with_the_count() {
    let mut scene = common::TestScene::new().fluid([0.0; 3], [0.1, 0.1, 0.1]);
    for k in 0..9 {
        let x = 0.2 + 0.05 * k as f64;
        scene = scene.solid_box([x, 0.0, 0.0], [x + 0.02, 0.1, 0.1]);
    }
    let e = scene.validation_error();
    assert!(e.contains("boundary") && e.contains("9 boxes") && e.contains("at most 8"), "{e}");
}
