//! The CPU reference's physics: conservation, the seed scene's stability, hydrostatics.

use crate::common;
use crate::common::TestScene;
use wgsph::model::scene::EquationOfState;
use wgsph::model::scene::Kernel;
use wgsph::model::scene::Scene;

/// Two jittered blocks of fluid moving against each other, no gravity, no walls or planes.
fn colliding_blocks(kernel: Kernel, eos: EquationOfState) -> Scene {
    TestScene::new()
        .domain([-1.0; 3], [2.0; 3])
        .smoothing_length(0.1)
        .particle_spacing(0.05)
        .kernel(kernel)
        .equation_of_state(eos)
        .speed_of_sound(20.0)
        .viscosity(0.01)
        .gravity([0.0; 3])
        .dt(0.0005)
        .fluid([0.0; 3], [0.4; 3])
        .jitter(0.2)
        .moving_at([1.0, 0.5, 0.0])
        .fluid([0.4, 0.0, 0.0], [0.8, 0.3, 0.4])
        .jitter(0.2)
        .moving_at([-1.0, 0.0, 0.25])
        .build()
}

#[test]
fn pressure_and_viscosity_conserve_momentum_in_a_closed_box_without_gravity() {
    for kernel in Kernel::ALL {
        for eos in [EquationOfState::Linear, EquationOfState::Tait] {
            let s = colliding_blocks(kernel, eos);
            let p = s.params();
            let mut cpu = common::cpu::<f64>(&s);
            cpu.step(1);
            let f = cpu.step_fields();
            let mut total = [0.0f64; 3];
            let mut magnitude = 0.0;
            for a in &f.accelerations {
                for k in 0..3 {
                    total[k] += p.fluid_mass * a[k];
                }
                magnitude += p.fluid_mass * (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
            }
            assert!(magnitude > 0.0);
            let net = (total[0] * total[0] + total[1] * total[1] + total[2] * total[2]).sqrt();
            assert!(net < 1e-12 * magnitude, "{kernel:?}/{eos:?}: net force {net:e} against {magnitude:e}");
            // Momentum after many steps is unchanged to rounding.
            let before = momentum(&cpu.snapshot(), p.fluid_mass);
            cpu.step(50);
            let after = momentum(&cpu.snapshot(), p.fluid_mass);
            for k in 0..3 {
                assert!((after[k] - before[k]).abs() < 1e-10 * magnitude.max(1.0), "{kernel:?}/{eos:?}: {before:?} -> {after:?}");
            }
        }
    }
}

fn momentum(s: &wgsph::Snapshot, m: f64) -> [f64; 3] {
    let mut p = [0.0; 3];
    for v in &s.velocities {
        for k in 0..3 {
            p[k] += m * v[k];
        }
    }
    p
}

#[test]
fn seed_scene_is_stable_for_60_simulated_seconds() {
    let s = Scene::builtin("seed").unwrap();
    let p = s.params();
    let mut cpu = common::cpu::<f64>(&s);
    let steps = (60.0 / p.dt).round() as u64;
    cpu.step(steps);
    let h = cpu.health();
    assert_eq!(cpu.steps_done(), steps, "stopped early: {h:?}");
    assert!(h.is_ok(), "{h:?}");
    let snap = cpu.snapshot();
    assert_eq!(snap.non_finite_count(), 0);
    // Inside the container (the planes sit on its inner faces).
    for x in &snap.positions {
        assert!(x[0] >= 0.0 && x[0] <= 2.0 && x[1] >= 0.0 && x[1] < 4.0 && x[2] >= 0.0 && x[2] <= 1.5, "{x:?}");
    }
    let ratio = h.max_density / p.rest_density;
    assert!(ratio > 1.0 && ratio < 50.0, "max density ratio {ratio}");
}

#[test]
fn hydrostatic_scene_settles_with_pressure_increasing_with_depth() {
    // The built-in tank at half its width (the same depth and resolution): the pressure over
    // the depth is what is checked, and half the particles settle in half the time.
    let mut s = Scene::builtin("hydrostatic").unwrap();
    s.fluid[0].max[0] = 0.2;
    s.domain.max[0] = 0.3;
    match &mut s.boundary[0] {
        wgsph::model::scene::Boundary::Container { max, .. } => max[0] = 0.2,
        other => panic!("the hydrostatic tank is a container, not {other:?}"),
    }
    let s = TestScene::from(s).build();
    let p = s.params();
    let mut cpu = common::cpu::<f64>(&s);
    cpu.step((1.5 / p.dt).round() as u64);
    assert!(cpu.health().is_ok(), "{:?}", cpu.health());
    let snap = cpu.snapshot();
    // Nearly at rest.
    let vmax = snap.max_speed();
    assert!(vmax < 0.15, "max speed {vmax}");
    // Mean pressure of horizontal layers, top to bottom: it grows with depth.
    let layer = 0.05;
    let mut sums = vec![(0.0, 0usize); 8];
    for (x, pr) in snap.positions.iter().zip(&snap.pressures) {
        let k = ((x[1] / layer).floor().max(0.0) as usize).min(7);
        sums[k].0 += pr;
        sums[k].1 += 1;
    }
    let means: Vec<f64> = sums.iter().filter(|s| s.1 > 0).map(|s| s.0 / s.1 as f64).collect();
    assert!(means.len() >= 6, "{means:?}");
    for w in means.windows(2) {
        assert!(w[0] > w[1], "pressure must decrease upwards: {means:?}");
    }
    // The bottom layer's mean pressure against rho g (H - y) at its centre.
    let height = snap.positions.iter().map(|x| x[1]).fold(0.0, f64::max);
    let expected = p.rest_density * 9.81 * (height - 0.5 * layer);
    assert!((means[0] - expected).abs() < 0.25 * expected, "bottom pressure {} against {expected}", means[0]);
}
