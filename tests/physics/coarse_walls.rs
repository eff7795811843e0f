//! Walls hold at every resolution `--particles` accepts: the built-in scenes at the fewest
//! particles they allow, and the hydrostatic tank at the 500 particles that lost one through a
//! corner, run long on the f32 CPU path (the GPU's arithmetic; cheap at these sizes), with no
//! particle leaving the domain or getting past the first layer of a wall.

use crate::common;

use wgsph::model::diagnosis::SolidIntrusions;
use wgsph::model::scene::Scene;

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
