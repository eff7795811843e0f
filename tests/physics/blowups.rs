//! Blow-ups caught and explained: the health of a run describes its first bad step, however long
//! after it the host reads it; a run stops when the fluid leaves the weakly compressible regime
//! (too dense, too fast); and the diagnosis names the cause the figures of the failing step and
//! the state show (fluid inside a solid, torn, or out of the domain and by which face, a surface
//! tension that crushes it), or says that the cause is unknown. On the f64 CPU reference and on
//! every GPU adapter found.

use crate::common;
use crate::common::TestScene;

use wgsph::app::run::{run, RunOptions};
use wgsph::io::summary::Summary;
use wgsph::model::initial::InitialState;
use wgsph::model::scene::{EquationOfState, Scene};
use wgsph::solver::Backend;

/// The f64 CPU reference and one GPU solver per adapter, from the same particles.
fn backends(scene: &Scene, initial: &InitialState) -> Vec<Box<dyn Backend>> {
    let mut list: Vec<Box<dyn Backend>> = vec![Box::new(common::cpu_from::<f64>(scene, initial))];
    for ctx in common::contexts() {
        list.push(Box::new(common::gpu_from(ctx, scene, initial)));
    }
    list
}

/// Runs up to `steps` steps through the run loop, reading the health every `check_every` steps
/// (snapshots only at the start and the end), and returns the summary.
fn run_checked(backend: &mut dyn Backend, scene: &Scene, steps: u64, check_every: u64) -> Summary {
    let dir = tempfile::tempdir().unwrap();
    let opts = RunOptions { steps, out: dir.path().to_path_buf(), snapshot_every: 0, check_every, ..Default::default() };
    run(backend, scene, &opts).unwrap()
}

/// A block of 4 x 4 x 3 particles thrown at 50 m/s against the floor of the tank (backed by a
/// plane, so that nothing leaves it), whose speed of sound is 40 m/s; dt = 1e-4 keeps the CFL
/// number at 0.23 at that speed.
fn impact() -> TestScene {
    tank()
        .speed_of_sound(40.0)
        .dt(0.0001)
        .without_fluid()
        .fluid([0.06, 0.06, 0.02], [0.14, 0.14, 0.08])
        .moving_at([0.0, -50.0, 0.0])
        .plane([0.0; 3], [0.0, 1.0, 0.0], 0.0)
}

/// The failure of a run that must fail.
fn failure(backend: &mut dyn Backend, scene: &Scene, steps: u64, check_every: u64) -> String {
    let who = backend.adapter();
    run_checked(backend, scene, steps, check_every).failure.unwrap_or_else(|| panic!("{who}: the run did not stop"))
}

/// A closed tank of wall particles, 0.24 m x 0.24 m x 0.12 m, with a block of 6 x 8 x 4 fluid
/// particles in its corner: h = 0.04, c0 = 20 m/s, dt = 2e-4 (CFL number 0.1), no planes.
fn tank() -> TestScene {
    TestScene::new()
        .named("tank")
        .domain([-0.06; 3], [0.30, 0.30, 0.18])
        .equation_of_state(EquationOfState::Tait)
        .speed_of_sound(20.0)
        .clamp_negative_pressure(true)
        .viscosity(0.001)
        .boundary_friction(0.0)
        .dt(0.0002)
        .fluid([0.0; 3], [0.12, 0.16, 0.08])
        .closed_container([0.0; 3], [0.24, 0.24, 0.12])
}

#[test]
fn a_blow_up_read_steps_after_it_happened_reports_the_counts_of_its_first_bad_step() {
    // The case: dam_break at dt = 0.0025 (CFL number 2.5), without the density and Mach
    // limits, so that particles leaving the domain are what stops it (at step 4). The health is
    // read at step 8, when that step's counters may have gone back to zero; what is reported
    // must be step 4's, and the same as when the health is read after every step.
    let scene = TestScene::from(Scene::builtin("dam_break").unwrap()).dt(0.0025).without_limits().build();
    let initial = scene.initial_state();
    for (mut late, mut early) in backends(&scene, &initial).into_iter().zip(backends(&scene, &initial)) {
        let who = late.adapter();
        let summary = run_checked(late.as_mut(), &scene, 400, 8);
        let health = late.health().unwrap();
        let bad = health.bad_step.unwrap_or_else(|| panic!("{who}: no bad step recorded"));
        assert_eq!(health.first_bad_step, Some(bad.step), "{who}");
        assert!(bad.step < late.steps_done() || who.starts_with("cpu"), "{who}: the GPU ran past the bad step ({} steps)", late.steps_done());
        // The summary ends where the run failed, not where the batch stopped.
        assert_eq!((summary.steps, summary.sim_time), (bad.step, bad.measured.time), "{who}");
        assert!(summary.nan_count + summary.escaped > 0, "{who}: the summary shows no bad particle: {summary:?}");
        assert_eq!((summary.nan_count, summary.escaped), (bad.measured.non_finite, bad.measured.escaped), "{who}");
        let failure = summary.failure.unwrap();
        assert!(failure.starts_with(&format!("step {} (t = ", bad.step)), "{who}: {failure}");
        if bad.measured.escaped > 0 {
            assert!(failure.contains(&format!("{} particles left the domain", bad.measured.escaped)), "{who}: {failure}");
        }
        // Read after every step: the same step, the same counts.
        run_checked(early.as_mut(), &scene, 400, 1);
        let h1 = early.health().unwrap();
        assert_eq!(h1.bad_step, health.bad_step, "{who}: read after every step");
    }
}

#[test]
fn a_time_step_ten_times_too_large_stops_within_steps_and_names_the_cfl_condition() {
    // dam_break at 10x its dt ran 20 steps to 275 rho0 and exited 0: now the speed and density
    // limits stop it within its first steps, and the diagnosis names the CFL condition (2.5).
    let scene = TestScene::from(Scene::builtin("dam_break").unwrap()).dt(0.0025).build();
    for mut b in backends(&scene, &scene.initial_state()) {
        let who = b.adapter();
        let f = failure(b.as_mut(), &scene, 20, 20);
        let bad = b.health().unwrap().bad_step.unwrap();
        assert!(bad.step <= 4 && (bad.too_dense || bad.too_fast), "{who}: {bad:?}");
        assert!(bad.measured.max_density < 10.0 * 1000.0, "{who}: {bad:?}");
        assert!(f.contains("Cause: the CFL condition: dt c0 / h = 2.5 is over 0.4"), "{who}: {f}");
    }
}

#[test]
fn a_50_m_per_s_impact_stops_on_its_mach_number() {
    // A block thrown at 50 m/s against the floor of a tank whose speed of sound is 40 m/s used to
    // "succeed" at 9 rho0; it is Mach 1.25 from the first step, and stops there.
    let scene = impact().build();
    for mut b in backends(&scene, &scene.initial_state()) {
        let who = b.adapter();
        let f = failure(b.as_mut(), &scene, 20, 20);
        let bad = b.health().unwrap().bad_step.unwrap();
        assert_eq!(bad.step, 1, "{who}");
        assert!(bad.too_fast && (bad.measured.max_speed - 50.0).abs() < 0.1, "{who}: {bad:?}");
        assert!(f.contains("Mach 1.25") && f.contains("over limits.max_mach"), "{who}: {f}");
        assert!(f.contains("Cause: ") && f.contains("the flow reached Mach 1.25"), "{who}: {f}");
        assert!(f.contains("raise physics.speed_of_sound to at least 10 times the largest speed (c0 = 40 now, 50"), "{who}: {f}");
    }
    // The same speed of sound given by the linear equation of state's stiffness, k = rho0 c0^2
    // = 1.6e6: the remedy names the field the scene sets, and the k that c0 = 500 needs.
    let scene = impact().equation_of_state(EquationOfState::Linear).stiffness(1.6e6).build();
    let mut b = common::cpu::<f64>(&scene);
    let f = failure(&mut b, &scene, 20, 20);
    assert!(f.contains("raise physics.stiffness (k = 1600000 gives c0 = 40; c0 = 50") && f.contains("10 times the largest speed, needs k = 2.5"), "{f}");
}

/// A Mach limit the scene set far below 0.3 stops a calm flow: the diagnosis says the limit
/// stopped the run, and does not ask for a higher speed of sound the flow does not need.
#[test]
fn a_strict_mach_limit_is_named_as_the_cause_not_the_speed_of_sound() {
    let scene = TestScene::small_tank().stop_levels(2.0, 0.001).build();
    let mut b = common::cpu::<f64>(&scene);
    let f = failure(&mut b, &scene, 20, 5);
    assert!(f.contains("over limits.max_mach = 0.001"), "{f}");
    assert!(f.contains("the scene's limits.max_mach = 0.001 is below the Mach 0.3") && f.contains("the limit stopped the run, not the flow"), "{f}");
    assert!(!f.contains("raise physics.speed_of_sound"), "{f}");
}

#[test]
fn the_limits_are_the_scenes_and_inf_turns_them_off() {
    // The same impact with the Mach limit off: it runs on, over the density limit, which the
    // scene raised to 20: it ends without stopping, and its summary warns of both.
    let scene = impact().stop_levels(20.0, f64::INFINITY).warn_levels(1.1, 0.3).build();
    for mut b in backends(&scene, &scene.initial_state()) {
        let who = b.adapter();
        let summary = run_checked(b.as_mut(), &scene, 20, 20);
        assert!(summary.failure.is_none(), "{who}: {:?}", summary.failure);
        assert!(summary.max_mach.is_some_and(|m| m > 1.2), "{who}: {:?}", summary.max_mach);
        assert_eq!(summary.warnings.len(), 2, "{who}: {:?}", summary.warnings);
        assert!(summary.warnings[0].contains("over limits.warn_density_ratio = 1.1"), "{who}: {:?}", summary.warnings);
        assert!(summary.warnings[1].contains("over limits.warn_mach = 0.3"), "{who}: {:?}", summary.warnings);
    }
}

#[test]
fn the_viscous_limit_is_named_when_viscosity_is_what_is_too_large() {
    // nu = 10 m^2/s at dt = 2e-4, ten times over dt <= 0.125 h^2 / nu = 2e-5; the CFL number is 0.1.
    let scene = tank().viscosity(10.0).fluid([0.12, 0.0, 0.0], [0.2, 0.16, 0.08]).moving_at([1.0, 0.0, 0.0]).build();
    for mut b in backends(&scene, &scene.initial_state()) {
        let who = b.adapter();
        let f = failure(b.as_mut(), &scene, 2000, 10);
        assert!(f.contains("the viscous condition: dt = 0.0002 is over 0.125 h^2 / nu = 2e-5"), "{who}: {f}");
        assert!(!f.contains("the CFL condition"), "{who}: {f}");
    }
}

#[test]
fn the_force_condition_is_named_when_gravity_is_what_is_too_large() {
    // |g| = 1e5 m/s^2: dt sqrt(|g| / h) = 0.32, over 0.25; the CFL number is 0.1.
    let scene = tank().gravity([0.0, -1e5, 0.0]).build();
    for mut b in backends(&scene, &scene.initial_state()) {
        let who = b.adapter();
        let f = failure(b.as_mut(), &scene, 2000, 10);
        assert!(f.contains("the force condition: dt sqrt(|g| / h) = 0.316228 is over 0.25"), "{who}: {f}");
        assert!(!f.contains("the viscous condition"), "{who}: {f}");
    }
}

#[test]
fn a_fluid_too_soft_for_its_weight_is_stopped_and_named_by_its_density() {
    // c0 = 0.5 m/s: the column's weight compresses it far beyond 1.5 rho0 (its Mach number is
    // large too, but this scene turns that limit off: the density is what stops it).
    let scene = tank().speed_of_sound(0.5).stop_levels(1.5, f64::INFINITY).build();
    for mut b in backends(&scene, &scene.initial_state()) {
        let who = b.adapter();
        let f = failure(b.as_mut(), &scene, 5000, 50);
        assert!(f.contains("Cause: the fluid was compressed to"), "{who}: {f}");
        assert!(!f.contains("the CFL condition") && !f.contains("the flow reached Mach"), "{who}: {f}");
    }
}

/// A weightless 6 x 6 x 6 block with surface tension 60, far above the 0.05 to 1 that holds a
/// drop together: its cohesion crushes it beyond 1.5 rho0 within steps (at 0.3 it pulls itself
/// together below 1.1 rho0).
#[test]
fn a_surface_tension_that_crushes_the_fluid_is_named() {
    let block = |gamma: f64| {
        TestScene::new()
            .named("cube")
            .domain([-0.1; 3], [0.22; 3])
            .smoothing_length(0.04)
            .particle_spacing(0.02)
            .equation_of_state(EquationOfState::Tait)
            .speed_of_sound(10.0)
            .clamp_negative_pressure(true)
            .gravity([0.0; 3])
            .fluid([0.0; 3], [0.12; 3])
            .surface_tension(gamma)
            .build()
    };
    let crushing = block(60.0);
    for mut b in backends(&crushing, &crushing.initial_state()) {
        let who = b.adapter();
        let f = failure(b.as_mut(), &crushing, 400, 10);
        assert!(f.contains("over limits.max_density_ratio"), "{who}: {f}");
        assert!(f.contains("Cause: the surface tension: physics.surface_tension = 60 is above the 0.05 to 1 that holds a drop together"), "{who}: {f}");
        assert!(f.contains("whose collapse throws particles out: lower it;"), "{who}: {f}");
    }
    let holding = block(0.3);
    let mut cpu = common::cpu_from::<f64>(&holding, &holding.initial_state());
    let summary = run_checked(&mut cpu, &holding, 400, 10);
    assert!(summary.failure.is_none() && summary.max_density_ratio < 1.1, "{:?}, {}", summary.failure, summary.max_density_ratio);
}

/// A weightless block of 5 x 5 x 5 particles on the floor of a closed tank with wall adhesion
/// 20, four times what wets a wall: the adhesion draws the fluid into the floor, and the run
/// stops on a particle that went through it, naming the adhesion before the leak.
#[test]
fn a_wall_adhesion_that_draws_the_fluid_into_the_wall_is_named() {
    let scene = TestScene::new()
        .named("drop")
        .domain([-0.1; 3], [0.4, 0.3, 0.4])
        .equation_of_state(EquationOfState::Tait)
        .speed_of_sound(10.0)
        .clamp_negative_pressure(true)
        .gravity([0.0; 3])
        .fluid([0.1, 0.0, 0.1], [0.2, 0.1, 0.2])
        .closed_container([0.0; 3], [0.3, 0.2, 0.3])
        .surface_tension(0.3)
        .wall_adhesion(20.0)
        .build();
    for mut b in backends(&scene, &scene.initial_state()) {
        let who = b.adapter();
        let f = failure(b.as_mut(), &scene, 1500, 10);
        assert!(f.contains("Cause: the wall adhesion: physics.wall_adhesion = 20 is above the 0.01 to 5 that wets a wall"), "{who}: {f}");
        assert!(f.contains("fluid particles are inside boundary[0]"), "{who}: {f}");
    }
}

#[test]
fn fluid_leaking_through_a_wall_is_named_with_its_wall() {
    // The seed report's scene without the planes that back its walls: its fluid (k = 2 Pa,
    // far too soft for its weight) seeps through the floor of wall particles, and the run stops
    // when a particle leaves the domain below it. The diagnosis names the floor.
    let scene = TestScene::from(Scene::builtin("seed").unwrap()).without_planes().build();
    for mut b in backends(&scene, &scene.initial_state()) {
        let who = b.adapter();
        let f = failure(b.as_mut(), &scene, 1200, 10);
        assert!(f.contains("particles left the domain"), "{who}: {f}");
        assert!(f.contains("fluid particles are inside boundary[0] (the container's -y (floor) wall)"), "{who}: {f}");
        assert!(f.contains("beyond the domain's -y face (y < -0.3): they went through boundary[0] (the container's -y wall)"), "{who}: {f}");
    }
}

#[test]
fn fluid_leaving_through_an_open_side_is_named_with_the_face_and_the_speed_of_the_failing_step() {
    // One particle rising at 1 m/s out through the top of a domain with no wall: every
    // stability condition holds and nothing is too dense or fast; what the state shows is a
    // particle beyond the domain's +y face, which nothing closes. Only step 0 was saved: the
    // |v|max the message gives is the failing step's (1 m/s), not the last snapshot's.
    let scene = TestScene::new().domain([-0.1; 3], [0.3, 0.1, 0.3]).gravity([0.0; 3]).fluid([0.0; 3], [0.02; 3]).jitter(0.0).moving_at([0.0, 1.0, 0.0]).build();
    for mut b in backends(&scene, &scene.initial_state()) {
        let who = b.adapter();
        let f = failure(b.as_mut(), &scene, 2000, 10);
        let bad = b.health().unwrap().bad_step.unwrap();
        assert!(bad.measured.escaped == 1 && (bad.measured.max_speed - 1.0).abs() < 1e-6, "{who}: {bad:?}");
        assert!(f.contains("Cause: 1 fluid particles are beyond the domain's +y face (y > 0.1), where nothing holds the fluid in"), "{who}: {f}");
        assert!(f.contains("move domain.max[1] out, or close that side"), "{who}: {f}");
        assert!(f.contains("|v|max = 1,"), "{who}: {f}");
    }
}

/// The diagnosis of a step at which one particle left the domain (|v|max = 3 m/s, nothing
/// else wrong), of `scene` with fluid particles found at `outside` (and one inside).
fn escape_diagnosis(scene: &Scene, outside: &[[f64; 3]]) -> String {
    use wgsph::model::diagnosis::{diagnose, FailureScan};
    use wgsph::model::state::{BadStep, Health, StepMeasures};
    let measured = StepMeasures { escaped: outside.len() as u64, max_density: 1000.0, max_speed: 3.0, dt: 0.0002, time: 0.1, ..Default::default() };
    let health = Health { first_bad_step: Some(500), bad_step: Some(BadStep { step: 500, measured, too_dense: false, too_fast: false }), ..Default::default() };
    let mut scan = FailureScan::new(scene);
    scan.add([0.05; 3], 1000.0, 0.0);
    for &x in outside {
        scan.add(x, 1000.0, 0.0);
    }
    diagnose(scene, &health, Some(&scan))
}

#[test]
fn fluid_out_of_the_domain_is_named_by_the_face_it_left_through_and_what_closes_it() {
    // The domain is [-0.06, 0.30]^2 x [-0.06, 0.18]; the tank's inside [0, 0.24]^2 x [0, 0.12].
    let open = tank().without_boundaries().container([0.0; 3], [0.24, 0.24, 0.12]).build();
    // Thrown out of the open top: the face, the open container, and how high 3 m/s rises.
    let f = escape_diagnosis(&open, &[[0.1, 0.35, 0.05], [0.1, 0.32, 0.05]]);
    assert!(f.contains("2 fluid particles are beyond the domain's +y face (y > 0.3), where nothing holds the fluid in"), "{f}");
    assert!(f.contains("boundary[0], the container, is open at the top"), "{f}");
    assert!(f.contains("rises |v|^2 / 2|g| = 0.458716 above where it was thrown"), "{f}");
    assert!(f.contains("move domain.max[1] out") && f.contains("open_top = false"), "{f}");
    // Farthest beyond the +x face (and just beyond +y): through the container's +x wall.
    let f = escape_diagnosis(&open, &[[0.4, 0.31, 0.05], [0.35, 0.1, 0.05], [0.1, -0.1, 0.05]]);
    assert!(f.contains("2 fluid particles are beyond the domain's +x face (x > 0.3) (1 more beyond its other faces): they went through boundary[0] (the container's +x wall)"), "{f}");
    assert!(f.contains("back the wall with a plane"), "{f}");
    assert!(!f.contains("rises"), "{f}");
    // Closed on top, the top face is a wall's.
    let closed = tank().build();
    let f = escape_diagnosis(&closed, &[[0.1, 0.35, 0.05]]);
    assert!(f.contains("went through boundary[0] (the container's +y wall)"), "{f}");
    // A plane facing the fluid from below the domain's floor (outside it), and a slanted one
    // that closes no face.
    let planes = tank().without_boundaries().plane([0.0, -0.2, 0.0], [0.0, 1.0, 0.0], 0.0).plane([0.0; 3], [1.0, 1.0, 0.0], 0.0).build();
    let f = escape_diagnosis(&planes, &[[0.1, -0.1, 0.05]]);
    assert!(f.contains("they got past boundary[0] (the plane through [0, -0.2, 0]); a plane holds the fluid"), "{f}");
    assert!(f.contains("check that it lies within the domain (domain.min[1] = -0.06)"), "{f}");
    let f = escape_diagnosis(&planes, &[[-0.1, 0.1, 0.05]]);
    assert!(f.contains("beyond the domain's -x face (x < -0.06), where nothing holds the fluid in"), "{f}");
    assert!(!f.contains("Cause unknown"), "{f}");
}

/// A block of 10 x 6 x 6 particles in no gravity and no tank, with a third too little mass per
/// particle: it starts at about 0.48 rho0, far below its rest density, so with negative
/// pressure kept the whole block is under the equation of state's tension.
fn stretched_block(clamp: bool) -> Scene {
    let mut scene = TestScene::new()
        .domain([-0.1; 3], [0.5, 0.22, 0.22])
        .gravity([0.0; 3])
        .speed_of_sound(20.0)
        .clamp_negative_pressure(clamp)
        .viscosity(0.0)
        .dt(0.0002)
        .fluid([0.2, 0.0, 0.0], [0.4, 0.12, 0.12])
        .jitter(0.0)
        .without_boundaries()
        .build();
    scene.physics.particle_mass = Some(0.3 * scene.physics.rest_density * scene.physics.particle_spacing.powi(3));
    scene
}

#[test]
fn fluid_torn_under_kept_negative_pressure_is_named_as_tension() {
    // The block pulls itself together at several times its speed of sound within a few steps;
    // the diagnosis names the tension (most of the block below 0.5 rho0 at negative pressure)
    // and what it leads to. With the negative pressure clamped nothing pulls and nothing fails.
    let scene = stretched_block(false);
    for mut b in backends(&scene, &scene.initial_state()) {
        let who = b.adapter();
        let f = failure(b.as_mut(), &scene, 200, 5);
        assert!(f.contains("the fluid was torn under tension: "), "{who}: {f}");
        assert!(f.contains("set physics.clamp_negative_pressure = true"), "{who}: {f}");
    }
    let clamped = stretched_block(true);
    for mut b in backends(&clamped, &clamped.initial_state()) {
        let who = b.adapter();
        assert_eq!(run_checked(b.as_mut(), &clamped, 200, 5).failure, None, "{who}");
    }
}

#[test]
fn only_fluid_below_half_its_rest_density_at_negative_pressure_counts_as_torn() {
    // The diagnosis alone, on a NaN whose step broke no condition: a particle is torn below
    // 0.5 rho0 with a negative or undefined pressure, where the scene keeps negative pressure;
    // not a thin particle at zero or positive pressure (a free surface's), nor one in a scene
    // that clamps, nor, with summation density, one within twice its own kernel's share (59
    // kg/m^3 here, a lone particle's density; 100 is a droplet of two or three); with continuity
    // density, which a lone particle keeps, it counts, and so does a density at or below zero
    // (no pressure).
    use wgsph::model::diagnosis::{diagnose, FailureScan};
    use wgsph::model::scene::DensityMethod;
    use wgsph::model::state::{BadStep, Health, StepMeasures};
    let measured = StepMeasures { non_finite: 1, max_density: 1000.0, max_speed: 1.0, dt: 0.0002, time: 0.1, ..Default::default() };
    let health = Health { first_bad_step: Some(500), bad_step: Some(BadStep { step: 500, measured, too_dense: false, too_fast: false }), ..Default::default() };
    for (clamp, continuity, density, pressure, torn) in [
        (false, false, 350.0, -57000.0, true),
        (false, false, 350.0, f64::NAN, true),
        (false, false, 100.0, -57000.0, false),
        (false, true, 100.0, -57000.0, true),
        (false, true, -20.0, f64::NAN, true),
        (false, false, 600.0, -30000.0, false),
        (false, false, 350.0, 0.0, false),
        (true, false, 350.0, 0.0, false),
        (false, false, f64::NAN, f64::NAN, false),
    ] {
        let mut scene = stretched_block(clamp);
        if continuity {
            scene.physics.density = DensityMethod::Continuity;
        }
        let mut scan = FailureScan::new(&scene);
        scan.add([0.3, 0.06, 0.06], 1000.0, 10.0);
        scan.add([0.3, 0.06, 0.06], density, pressure);
        let f = diagnose(&scene, &health, Some(&scan));
        let case = format!("clamp {clamp}, continuity {continuity}, density {density}, pressure {pressure}");
        assert_eq!(f.contains("torn under tension: 1 fluid particles"), torn, "{case}: {f}");
        assert_eq!(f.contains("Cause unknown"), !torn, "{case}: {f}");
    }
}

/// The dam break's column (0.4 m x 0.8 m x 0.1 m in a closed tank 1.6 m long, 1 m high) with
/// DFSPH and Wendland's kernel at 2 spacings, whose sum over the particle lattice starts the
/// fluid at 1.034 rho0; dt = 2 ms (CFL number 0.2 at 4 m/s).
fn dfsph_column_off_rest_density() -> Scene {
    TestScene::new()
        .named("column")
        .domain([-0.07; 3], [1.67, 1.07, 0.17])
        .kernel(wgsph::model::scene::Kernel::Wendland)
        .dfsph()
        .viscosity(0.01)
        .dt(0.002)
        .fluid([0.0; 3], [0.4, 0.8, 0.1])
        .jitter(0.02)
        .closed_container([0.0; 3], [1.6, 1.0, 0.1])
        .build()
}

#[test]
fn a_dfsph_fluid_started_off_its_rest_density_is_named_as_what_threw_it_apart() {
    // DFSPH's constant-density solve takes the 3.4 % excess out within the first steps: the
    // column's top moves 2.7 cm (0.68 h) at once, and the run stops within them on its density.
    // The diagnosis names the start and what starts the fluid at rest (the load warns of it
    // too); with the particle mass it names, the same column runs on.
    let scene = dfsph_column_off_rest_density();
    assert!(scene.rest_density_warning().is_some_and(|w| w.contains("DFSPH's constant-density solve does it within its first steps")));
    for mut b in backends(&scene, &scene.initial_state()) {
        let who = b.adapter();
        let f = failure(b.as_mut(), &scene, 40, 1);
        assert!(f.contains("Cause: the fluid started at 1.03384 rho0, not at rest"), "{who}: {f}");
        assert!(f.contains("or set physics.particle_mass = 0.00773812 to start at rho0"), "{who}: {f}");
    }
    let mut at_rest = scene.clone();
    at_rest.physics.particle_mass = Some(0.00773812);
    assert_eq!(at_rest.start_off_rest_density(), None);
    let mut cpu = common::cpu::<f64>(&at_rest);
    let summary = run_checked(&mut cpu, &at_rest, 40, 1);
    assert_eq!(summary.failure, None);
    assert!(summary.max_density_ratio < 1.1, "{}", summary.max_density_ratio);
}

#[test]
fn a_dfsph_run_too_dense_is_told_of_its_solve_not_of_a_speed_of_sound() {
    // DFSPH has no equation of state: its density warning speaks of its solve's tolerance and
    // limits (and of a start off rest density), the weakly compressible one of c0.
    use wgsph::model::diagnosis::regime_warnings;
    use wgsph::model::state::Health;
    let health = Health { max_density: 1300.0, ..Default::default() };
    let dfsph = regime_warnings(&dfsph_column_off_rest_density(), &health);
    assert_eq!(dfsph.len(), 1, "{dfsph:?}");
    assert!(dfsph[0].contains("DFSPH's constant-density solve holds the average density error within physics.dfsph.density_error = 0.0001"), "{dfsph:?}");
    assert!(dfsph[0].contains("the fluid also started at 1.03384 rho0") && !dfsph[0].contains("speed_of_sound"), "{dfsph:?}");
    let wcsph = regime_warnings(&tank().build(), &health);
    assert!(wcsph[0].contains("a higher speed of sound keeps density closer to rho0: raise physics.speed_of_sound (c0 = 20)"), "{wcsph:?}");
}
