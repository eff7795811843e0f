//! Adaptive time stepping and the neighbour-grid rebuild interval: the formula, the GPU against
//! the f64 CPU path, the run loop and the scene checks.

use crate::common;
use crate::common::TestScene;

use wgsph::solver::compare::step_and_compare;
use wgsph::solver::compare::MANY_STEPS;
use wgsph::solver::compare::ONE_STEP;
use wgsph::app::run::run;
use wgsph::app::run::RunOptions;
use wgsph::model::params::AdaptiveDt;
use wgsph::model::params::TimeSum;
use wgsph::solver::Backend;

/// The GPU against the CPU after one step (to the one-step bounds), then after 99 more (to the
/// many-step bounds).
fn one_step_then_a_hundred_agree(gpu: &mut dyn Backend, cpu: &mut dyn Backend, who: &str) {
    let c = step_and_compare(gpu, cpu, 1, &ONE_STEP).unwrap();
    assert!(c.passed(), "{who}\n{}", c.table());
    let c = step_and_compare(gpu, cpu, 99, &MANY_STEPS).unwrap();
    assert!(c.passed(), "{who}\n{}", c.table());
}

#[test]
fn each_condition_of_the_adaptive_step_governs_in_its_regime_and_dt_is_clamped() {
    let a = AdaptiveDt { cfl_number: 0.25, force_number: 0.25, viscous_number: 0.125, dt_min: 1e-6, dt_max: 1.0 };
    let (h, c0) = (0.04, 20.0);
    // At rest without forces or viscosity: the CFL condition on the speed of sound.
    assert_eq!(a.dt(h, c0, 0.0, 0.0, 0.0), 0.25 * h / c0);
    // A fast particle adds its speed.
    assert_eq!(a.dt(h, c0, 20.0, 0.0, 0.0), 0.25 * h / 40.0);
    // A large acceleration: the force condition.
    assert_eq!(a.dt(h, c0, 0.0, 1e6, 0.0), 0.25 * (h / 1e6f64).sqrt());
    // A large viscosity: the viscous condition.
    assert_eq!(a.dt(h, c0, 0.0, 0.0, 10.0), 0.125 * h * h / 10.0);
    // Clamped to [dt_min, dt_max], and a NaN maximum falls to dt_min.
    let tight = AdaptiveDt { dt_min: 1e-4, dt_max: 2e-4, ..a };
    assert_eq!(tight.dt(h, c0, 0.0, 0.0, 0.0), 2e-4);
    assert_eq!(tight.dt(h, c0, 0.0, 0.0, 1e3), 1e-4);
    assert_eq!(tight.dt(h, c0, f64::NAN, 0.0, 0.0), 1e-4);
}

#[test]
fn the_cpu_step_follows_the_formula_and_accumulates_time() {
    let s = TestScene::small_tank().adaptive().dt_max(0.01).build();
    let p = s.params();
    let a = p.adaptive.unwrap();
    let mut cpu = common::cpu::<f64>(&s);
    let mut time = 0.0;
    for _ in 0..20 {
        let before = cpu.snapshot();
        cpu.step(1);
        let accel = cpu.step_fields().accelerations.iter().map(|a| (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()).fold(0.0, f64::max);
        let expected = a.dt(p.h, p.speed_of_sound(), before.max_speed(), accel, 0.005);
        let stats = cpu.dt_stats();
        assert!((stats.last - expected).abs() < 1e-15, "{} against {expected}", stats.last);
        time += expected;
    }
    assert!((Backend::time(&cpu) - time).abs() < 1e-12);
    let stats = cpu.dt_stats();
    assert!(stats.min <= stats.mean && stats.mean <= stats.max && stats.max <= a.dt_max);
}

#[test]
fn gpu_with_adaptive_dt_agrees_with_the_f64_cpu_path() {
    for rebuild in [1, 2] {
        let s = TestScene::small_tank().adaptive().dt_max(0.002).neighbour_rebuild_every(rebuild).build();
        for ctx in common::contexts() {
            let who = format!("{} rebuild every {rebuild}", ctx.describe());
            let mut gpu = common::gpu(ctx, &s);
            let mut cpu = common::cpu::<f64>(&s);
            one_step_then_a_hundred_agree(&mut gpu, &mut cpu, &who);
            // The time and the steps taken, read back from the GPU in a few bytes.
            let (tg, tc) = (gpu.time(), Backend::time(&cpu));
            assert!((tg - tc).abs() < 1e-5 * tc, "{who}: time {tg} against {tc}");
            let (sg, sc) = (gpu.dt_stats().unwrap(), cpu.dt_stats());
            for (g, c) in [(sg.min, sc.min), (sg.max, sc.max), (sg.mean, sc.mean), (sg.last, sc.last)] {
                assert!((g - c).abs() < 1e-3 * c, "{who}: {sg:?} against {sc:?}");
            }
            assert!(sc.min < sc.max, "{who}: the step never changed: {sc:?}");
        }
    }
}

#[test]
fn rebuilding_the_grid_every_second_step_agrees_between_gpu_and_cpu_and_stays_close() {
    let every2 = TestScene::small_tank().neighbour_rebuild_every(2).build();
    let (p, init) = (every2.params(), every2.initial_state());
    for ctx in common::contexts() {
        let mut gpu = common::gpu(ctx, &every2);
        let mut cpu = common::cpu::<f64>(&every2);
        let c = step_and_compare(&mut gpu, &mut cpu, 100, &MANY_STEPS).unwrap();
        assert!(c.passed(), "{}", c.table());
    }
    // Against rebuilding every step: the same flow to well within a particle spacing.
    let every1 = TestScene::small_tank().build();
    let mut a = common::cpu_from::<f64>(&every1, &init);
    let mut b = common::cpu::<f64>(&every2);
    a.step(100);
    b.step(100);
    let (sa, sb) = (a.snapshot(), b.snapshot());
    let worst = (0..sa.len())
        .map(|i| (0..3).map(|k| (sa.positions[i][k] - sb.positions[i][k]).powi(2)).sum::<f64>().sqrt())
        .fold(0.0, f64::max);
    assert!(worst > 0.0 && worst < 0.1 * p.h, "largest position difference {worst}");
}

#[test]
fn adaptive_dt_handles_a_fixed_step_far_over_the_cfl_limit() {
    // dt = 0.01 is 50x over the CFL limit as a fixed step (tests/physics/extremes.rs); as dt_max of an
    // adaptive step the run is stable and its steps obey the CFL condition.
    let s = TestScene::small_tank().adaptive().dt_max(0.01).build();
    let p = s.params();
    let mut list: Vec<Box<dyn Backend>> = vec![Box::new(common::cpu::<f64>(&s))];
    for ctx in common::contexts() {
        list.push(Box::new(common::gpu(ctx, &s)));
    }
    for mut b in list {
        b.step(300).unwrap();
        assert!(b.health().unwrap().is_ok(), "{}", b.adapter());
        assert_eq!(b.snapshot().unwrap().non_finite_count(), 0);
        let stats = b.dt_stats().unwrap();
        assert!(stats.max <= 0.25 * p.h / p.speed_of_sound() * (1.0 + 1e-6), "{}: {stats:?}", b.adapter());
    }
}

#[test]
fn a_run_to_a_time_with_adaptive_dt_ends_at_the_first_step_reaching_it() {
    let s = TestScene::small_tank().adaptive().dt_max(0.002).build();
    let mut list: Vec<Box<dyn Backend>> = vec![Box::new(common::cpu::<f64>(&s))];
    for ctx in common::contexts() {
        list.push(Box::new(common::gpu(ctx, &s)));
    }
    for mut b in list {
        let dir = tempfile::tempdir().unwrap();
        let opts = RunOptions { steps: u64::MAX / 4, out: dir.path().into(), snapshot_every: 0, check_every: 50, progress: false, end_time: Some(0.05), ..Default::default() };
        let summary = run(b.as_mut(), &s, &opts).unwrap();
        assert!(summary.failure.is_none());
        assert!(summary.sim_time >= 0.05 && summary.sim_time < 0.05 + summary.dt_max, "{}: {summary:?}", b.adapter());
        assert!(summary.dt_min <= summary.dt_mean && summary.dt_mean <= summary.dt_max && summary.dt_min > 0.0);
        assert!((summary.sim_time - summary.dt_mean * summary.steps as f64).abs() < 1e-4 * summary.sim_time);
        let last = wgsph::io::snapshot::csv::read_snapshot_csv(std::path::Path::new(summary.last_snapshot.as_ref().unwrap())).unwrap();
        assert_eq!(last.len(), b.fluid_count());
    }
}

#[test]
fn time_options_are_checked() {
    let tank = TestScene::small_tank;
    for (scene, field) in [
        (tank().neighbour_rebuild_every(3), "time.neighbour_rebuild_every"),
        (tank().adaptive().cfl_number(0.0), "time.cfl_number"),
        (tank().adaptive().force_number(2.0), "time.force_number"),
        (tank().adaptive().dt_min(0.01).dt_max(0.001), "time.dt_min"),
        // dt_min and dt_max bound adaptive steps only.
        (tank().dt_min(0.001), "time.dt_min"),
    ] {
        let e = scene.validation_error();
        assert!(e.contains(field), "{field}: {e}");
    }
    let e = tank().adaptive().viscosity_change(0.5, 0.001).validation_error();
    assert!(e.contains("physics.viscosity_schedule") && e.contains("adaptive"), "{e}");
}

#[test]
fn a_continuity_density_advances_by_the_last_steps_dt_and_before_any_by_the_cfl_step_at_rest() {
    let a = AdaptiveDt { cfl_number: 0.25, force_number: 0.25, viscous_number: 0.125, dt_min: 1e-6, dt_max: 1.0 };
    let (h, c0) = (0.04, 20.0);
    assert_eq!(a.continuity_dt(h, c0, 0.0), 0.25 * h / c0);
    assert_eq!(a.continuity_dt(h, c0, 3e-4), 3e-4);
    let tight = AdaptiveDt { dt_min: 1e-4, dt_max: 2e-4, ..a };
    assert_eq!(tight.continuity_dt(h, c0, 0.0), 2e-4);
}

/// With dt_max far below every condition, each adaptive step is dt_max, so continuity density
/// with adaptive dt must give the fixed-dt run's bits, on the CPU and on every adapter: the
/// density stage advances by the step's dt from the first step on.
#[test]
fn continuity_density_with_adaptive_dt_held_at_dt_max_is_the_fixed_dt_run() {
    let dt = 1e-4;
    let fixed = TestScene::small_tank().continuity().density_diffusion(0.1).dt(dt).build();
    let adaptive = TestScene::small_tank().continuity().density_diffusion(0.1).dt(dt).adaptive().build();
    assert!(dt < 0.25 * fixed.params().h / fixed.params().speed_of_sound() / 2.0, "dt_max must bind");
    let mut pairs: Vec<(Box<dyn Backend>, Box<dyn Backend>)> = vec![(Box::new(common::cpu::<f32>(&fixed)), Box::new(common::cpu::<f32>(&adaptive)))];
    for ctx in common::contexts() {
        pairs.push((Box::new(common::gpu(ctx.clone(), &fixed)), Box::new(common::gpu(ctx, &adaptive))));
    }
    for (mut f, mut a) in pairs {
        f.step(40).unwrap();
        a.step(40).unwrap();
        let stats = a.dt_stats().unwrap();
        // dt_max as the GPU's f32 holds it.
        assert!((stats.min - dt).abs() <= 1e-7 * dt && (stats.max - dt).abs() <= 1e-7 * dt, "{}: {stats:?}", a.adapter());
        let (sf, sa) = (f.snapshot().unwrap(), a.snapshot().unwrap());
        assert!(sf.densities.iter().any(|d| (d - 1000.0).abs() > 1e-3), "{}: the density never moved", f.adapter());
        assert_eq!(sf.positions, sa.positions, "{}", f.adapter());
        assert_eq!(sf.velocities, sa.velocities, "{}", f.adapter());
        assert_eq!(sf.densities, sa.densities, "{}", f.adapter());
    }
}

#[test]
fn continuity_density_with_adaptive_dt_agrees_between_gpu_and_the_f64_cpu_path() {
    let s = TestScene::small_tank().continuity().density_diffusion(0.1).adaptive().dt_max(0.002).build();
    for ctx in common::contexts() {
        let who = ctx.describe();
        let mut gpu = common::gpu(ctx, &s);
        let mut cpu = common::cpu::<f64>(&s);
        one_step_then_a_hundred_agree(&mut gpu, &mut cpu, &who);
        let (sg, sc) = (gpu.dt_stats().unwrap(), cpu.dt_stats());
        assert!((sg.mean - sc.mean).abs() < 1e-3 * sc.mean && sc.min < sc.max, "{who}: {sg:?} against {sc:?}");
    }
}

/// The GPU sums the adaptive steps' dt exactly (a 64-bit integer significand, wgsl/shared/
/// adaptive_dt.wgsl): 1,000 steps held at dt_max give 1,000 times dt_max as f32 holds it, to the
/// last bit of an f64, on every adapter. A plain f32 sum is off after a few steps, and a Kahan
/// sum's compensation is optimised away by compilers that reassociate (lavapipe: 5,000 steps
/// gave 0.999941 s for 0.99999997 s).
#[test]
fn the_gpu_sums_adaptive_time_exactly() {
    let dt = 2e-4;
    let s = TestScene::small_tank().dt(dt).adaptive().build();
    let exact = (dt as f32) as f64 * 1000.0;
    for ctx in common::contexts() {
        let mut gpu = common::gpu(ctx, &s);
        gpu.step(1000).unwrap();
        let health = gpu.health().unwrap();
        assert!(health.is_ok(), "{}: {health:?}", gpu.adapter());
        assert_eq!(gpu.time(), exact, "{}", gpu.adapter());
        assert_eq!(gpu.dt_stats().unwrap().mean, exact / 1000.0, "{}", gpu.adapter());
    }
}

/// A varying dt (dt_max far above the CFL step): the GPU's time words are its twin's sum
/// (TimeSum) of the dts it chose, step by step, on every adapter.
#[test]
fn the_gpu_time_is_its_twins_sum_of_the_dts_it_chose() {
    let s = TestScene::small_tank().adaptive().dt_max(0.002).build();
    for ctx in common::contexts() {
        let mut gpu = common::gpu(ctx, &s);
        let mut twin = TimeSum::ZERO;
        let mut seen = Vec::new();
        for _ in 0..60 {
            gpu.step(1).unwrap();
            let dt = gpu.dt_stats().unwrap().last as f32;
            twin.add(dt);
            seen.push(dt);
            assert_eq!(gpu.time(), twin.seconds(), "{} after {} steps", gpu.adapter(), seen.len());
        }
        seen.dedup();
        assert!(seen.len() > 10, "{}: the step hardly changed: {seen:?}", gpu.adapter());
    }
}

/// Every backend reports the steps it took alike: none before the first step (0, as a run of
/// `--steps 0` writes in its summary), the scene's dt after a fixed step, with or without
/// adaptive dt.
#[test]
fn every_backend_reports_no_step_before_the_first_and_the_steps_after() {
    for adaptive in [false, true] {
        let mut s = TestScene::small_tank();
        if adaptive {
            s = s.adaptive().dt_max(0.002);
        }
        let s = s.build();
        let mut list: Vec<Box<dyn Backend>> = vec![Box::new(common::cpu::<f64>(&s)), Box::new(common::cpu::<f32>(&s))];
        for ctx in common::contexts() {
            list.push(Box::new(common::gpu(ctx, &s)));
        }
        for mut b in list {
            let who = format!("{} {}, adaptive {adaptive}", b.kind(), b.adapter());
            let none = b.dt_stats().unwrap();
            assert_eq!([none.min, none.max, none.mean, none.last], [0.0; 4], "{who}: {none:?}");
            b.step(3).unwrap();
            let taken = b.dt_stats().unwrap();
            assert!(taken.min > 0.0 && taken.min <= taken.mean && taken.mean <= taken.max, "{who}: {taken:?}");
            if !adaptive {
                let dt = s.params().dt;
                assert_eq!([taken.min, taken.max, taken.last], [dt; 3], "{who}: {taken:?}");
                assert!((taken.mean - dt).abs() <= 1e-12 * dt, "{who}: {taken:?}");
            }
        }
    }
}
