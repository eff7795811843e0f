//! The probe stage (wgsl/sim/probes.wgsl) against its CPU twin, for every probe type, on every
//! adapter; and probes that change nothing: a scene runs the same trajectory with and without
//! them.

use crate::common;
use crate::common::TestScene;
use wgsph::model::probes::ProbeSample;
use wgsph::model::scene::{ProbeSpec, ProbeType};
use wgsph::model::scene::Scene;
use wgsph::solver::Backend;

/// The small tank (a block moving towards a plane, in an open container, viscosity, walls with
/// friction) with a probe of every type, sampled every 5 steps: points in the fluid and on the
/// container's floor, a gauge through the block, the force on the whole container and on its
/// -x wall alone, and the front along +x and along a slanted direction.
fn probed_tank() -> Scene {
    probed(TestScene::small_tank(), true)
}

/// `tank` with the probes of [`probed_tank`] (without the force probes where `forces` is
/// false).
fn probed(tank: TestScene, forces: bool) -> Scene {
    let every = |mut p: ProbeSpec| {
        p.every_steps = Some(5);
        p
    };
    let gauge = ProbeSpec { position: Some([0.1, 0.0, 0.1]), ..ProbeSpec::of("gauge", ProbeType::Gauge) };
    let force = ProbeSpec { boundary: Some(0), ..ProbeSpec::of("container", ProbeType::Force) };
    let back_wall = ProbeSpec { boundary: Some(0), max: Some([0.0, 1.0, 1.0]), moment_about: Some([0.0; 3]), ..ProbeSpec::of("back_wall", ProbeType::Force) };
    let front = ProbeSpec::of("front", ProbeType::Front);
    let slanted = ProbeSpec { direction: Some([1.0, 0.0, 1.0]), height: Some(0.1), ..ProbeSpec::of("slanted", ProbeType::Front) };
    let probes = [ProbeSpec::point("inside", [0.1, 0.1, 0.1], 5), ProbeSpec::point("floor", [0.1, 0.0, 0.1], 5), every(gauge), every(force), every(back_wall), every(front), every(slanted)];
    probes.into_iter().filter(|p| forces || p.kind != ProbeType::Force).fold(tank, |tank, p| tank.probe(p)).build()
}

/// The probes of [`probed_tank`] under DFSPH.
fn probed_dfsph_tank() -> Scene {
    probed(TestScene::small_tank().dfsph(), true)
}

fn samples(backend: &mut dyn Backend, steps: u64) -> Vec<ProbeSample> {
    backend.step(steps).unwrap();
    backend.take_probe_samples().unwrap()
}

#[test]
fn every_probe_type_agrees_with_its_cpu_twin() {
    every_probe_type_agrees_on(probed_tank());
}

#[test]
fn every_probe_type_agrees_with_its_cpu_twin_on_adami_walls() {
    // A point on a wall reads the walls' extrapolation, and a force probe the wall particles'
    // own pressures (with artificial viscosity and adhesion, whose wall terms a force probe
    // takes too).
    let mut scene = probed_tank();
    scene.physics.boundary_pressure = wgsph::model::scene::BoundaryPressure::Adami;
    scene.physics.artificial_viscosity = 0.05;
    scene.physics.wall_adhesion = 2.0;
    every_probe_type_agrees_on(scene);
}

#[test]
fn every_probe_type_agrees_with_its_cpu_twin_under_dfsph() {
    // DFSPH's points and gauges read the factors' density and output pressure (the last step's
    // stiffness as a pressure) on the state the step starts from; its force probes the step's
    // wall push, after the solves.
    every_probe_type_agrees_on(probed_dfsph_tank());
}

fn every_probe_type_agrees_on(scene: Scene) {
    let probes = scene.params().probes;
    let mut cpu = common::cpu::<f64>(&scene);
    let expected = samples(&mut cpu, 21);
    assert_eq!(expected.iter().map(|s| s.step).collect::<Vec<_>>(), vec![0, 5, 10, 15, 20]);
    // The force on the container holds the block up: about its weight, upwards (DFSPH pushes
    // in the steps its solve needs to, which at this dt are not every step: its weight is
    // checked on a still tank, in tests/physics).
    let dfsph = scene.physics.solver == wgsph::model::scene::PressureSolver::Dfsph;
    if let Some(container) = probes.probes.iter().position(|p| p.name == "container" && !dfsph) {
        let weight = cpu.fluid_count() as f64 * scene.params().fluid_mass * 9.81;
        let up = expected[4].values[probes.offsets()[container] + 1];
        assert!(up < 0.0 && (up.abs() - weight).abs() < 0.5 * weight, "the container carries {up} N; the water weighs {weight} N");
    }
    for ctx in common::contexts() {
        let name = ctx.describe();
        let mut gpu = common::gpu(ctx, &scene);
        let got = samples(&mut gpu, 21);
        assert_eq!(got.len(), expected.len(), "{name}");
        for (g, c) in got.iter().zip(&expected) {
            assert_eq!((g.step, g.time, g.previous_time), (c.step, c.time, c.previous_time), "{name}");
            for (probe, at) in probes.probes.iter().zip(probes.offsets()) {
                for (k, column) in probe.geometry.columns().iter().enumerate() {
                    let (a, b) = (g.values[at + k], c.values[at + k]);
                    // The column's scale over the run: f32 rounding of the state and of the
                    // sums, which grows over the steps like the state's own difference.
                    let scale = expected.iter().map(|s| s.values[at + k].abs()).fold(0.0, f64::max).max(1e-6);
                    let tolerance = match *column {
                        "particles" => 2.0,
                        _ => 2e-3 * scale,
                    };
                    assert!((a - b).abs() <= tolerance, "{name}: probe '{}' {column} at step {}: gpu {a}, cpu {b} (tolerance {tolerance})", probe.name, g.step);
                }
            }
        }
    }
}

/// With adaptive dt a row's time is the device's: each sample is stamped with the time its step
/// starts at (step 0 at 0) and the step before's, as the CPU path stamps it, under both
/// methods (a DFSPH step chooses its dt between its point probes and the rest of its sample).
#[test]
fn probe_times_with_adaptive_dt_are_those_of_the_cpu_path() {
    for (method, tank) in [("WCSPH", TestScene::small_tank()), ("DFSPH", TestScene::small_tank().dfsph())] {
        let scene = probed(tank.adaptive().dt_max(0.002), true);
        let mut cpu = common::cpu::<f64>(&scene);
        let expected = samples(&mut cpu, 21);
        assert_eq!(expected.iter().map(|s| s.step).collect::<Vec<_>>(), vec![0, 5, 10, 15, 20], "{method}");
        assert_eq!((expected[0].time, expected[0].previous_time), (0.0, 0.0), "{method}");
        for ctx in common::contexts() {
            let name = format!("{method} on {}", ctx.describe());
            let mut gpu = common::gpu(ctx, &scene);
            let got = samples(&mut gpu, 21);
            assert_eq!(got.iter().map(|s| s.step).collect::<Vec<_>>(), vec![0, 5, 10, 15, 20], "{name}");
            for (g, c) in got.iter().zip(&expected) {
                // The device chooses each dt in f32 from f32 maxima: the times agree to that.
                for (what, a, b) in [("time", g.time, c.time), ("previous time", g.previous_time, c.previous_time)] {
                    assert!((a - b).abs() <= 1e-4 * b.abs() + 1e-9, "{name}: the {what} of step {}'s sample: gpu {a}, cpu {b}", g.step);
                }
                // A step's time is its last step's end, not this one's.
                assert!(g.step == 0 || g.previous_time < g.time, "{name}: step {} at {} after {}", g.step, g.time, g.previous_time);
            }
        }
    }
}

#[test]
fn probes_change_no_trajectory() {
    probes_change_no_trajectory_of(probed_tank());
    probes_change_no_trajectory_of(probed_dfsph_tank());
}

fn probes_change_no_trajectory_of(with: Scene) {
    let mut without = with.clone();
    without.probe.clear();
    let mut a = common::cpu::<f64>(&with);
    let mut b = common::cpu::<f64>(&without);
    a.step(12);
    b.step(12);
    assert_eq!(a.snapshot().positions, b.snapshot().positions, "cpu");
    for ctx in common::contexts() {
        let name = ctx.describe();
        let mut a = common::gpu(ctx.clone(), &with);
        let mut b = common::gpu(ctx, &without);
        a.step(12).unwrap();
        b.step(12).unwrap();
        assert_eq!(a.snapshot().unwrap().positions, b.snapshot().unwrap().positions, "{name}");
        assert!(b.take_probe_samples().unwrap().is_empty(), "{name}");
    }
}
