//! Surface tension and adhesion (Akinci et al. 2013): a cube of water without gravity pulls
//! itself into a ball, a drop on a floor stays on it and spreads with adhesion and leaves it
//! without, and the values they cannot take are refused; both with either solver.

use crate::common;
use crate::common::TestScene;

use std::path::Path;
use wgsph::model::scene::{EquationOfState, PressureSolver, Scene};
use wgsph::model::state::Snapshot;

/// Water without gravity, 1 cm particles (h = 2 cm), c0 = 10 m/s, Tait with clamped negative
/// pressure (a free surface's density deficit must not pull it in), a little viscosity.
fn weightless() -> TestScene {
    TestScene::new()
        .domain([-0.2; 3], [0.3; 3])
        .smoothing_length(0.02)
        .particle_spacing(0.01)
        .speed_of_sound(10.0)
        .equation_of_state(EquationOfState::Tait)
        .clamp_negative_pressure(true)
        .viscosity(0.0005)
        .gravity([0.0; 3])
        .dt(0.0004)
}

fn centre(s: &Snapshot) -> [f64; 3] {
    let n = s.len() as f64;
    std::array::from_fn(|a| s.positions.iter().map(|p| p[a]).sum::<f64>() / n)
}

/// The fluid's extent from its centre: the largest distance along an axis, along a cube's
/// diagonal, and in any direction. A cube's diagonal reaches sqrt(3) times as far as its axes; a
/// ball's the same.
fn extents(s: &Snapshot) -> (f64, f64, f64) {
    let c = centre(s);
    let d: Vec<[f64; 3]> = s.positions.iter().map(|p| [p[0] - c[0], p[1] - c[1], p[2] - c[2]]).collect();
    let axis = d.iter().flat_map(|v| v.iter().map(|x| x.abs())).fold(0.0, f64::max);
    let mut diagonal: f64 = 0.0;
    for sx in [-1.0, 1.0] {
        for sy in [-1.0, 1.0] {
            for sz in [-1.0, 1.0] {
                let along = d.iter().map(|v| (v[0] * sx + v[1] * sy + v[2] * sz) / 3f64.sqrt()).fold(0.0, f64::max);
                diagonal = diagonal.max(along);
            }
        }
    }
    let radius = d.iter().map(|v| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()).fold(0.0, f64::max);
    (axis, diagonal, radius)
}

/// The example scene scenes/weightless_cube.toml: a 10 cm cube of 1,000 particles without
/// gravity, surface tension 0.3.
fn weightless_cube() -> Scene {
    Scene::load(Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/weightless_cube.toml").to_str().unwrap()).unwrap()
}

#[test]
fn a_weightless_cube_pulls_itself_into_a_ball_and_without_surface_tension_flies_apart() {
    // A ball of the cube's volume has the radius (3 V / 4 pi)^(1/3).
    let ball = (3.0 * 0.1f64.powi(3) / (4.0 * std::f64::consts::PI)).cbrt();
    let cube = weightless_cube();
    assert_eq!((cube.physics.surface_tension, cube.fluid_particle_count()), (0.3, 1000));
    let steps = 750; // 0.3 s
    let mut round = common::cpu::<f32>(&cube);
    let (axis, diagonal, _) = extents(&round.snapshot());
    assert!(diagonal / axis > 1.6, "a cube at the start: diagonal {diagonal} / axis {axis}");
    round.step(steps);
    assert!(round.health().is_ok(), "{:?}", round.health());
    let (axis, diagonal, radius) = extents(&round.snapshot());
    assert!((0.9..1.1).contains(&(diagonal / axis)), "round after 0.3 s: diagonal {diagonal} / axis {axis}");
    assert!(radius > 0.8 * ball && radius < 1.05 * ball, "a ball of the cube's volume has the radius {ball}; the fluid reaches {radius}");
    // Without surface tension nothing holds the surface particles: the cube's pressure pushes
    // them apart.
    let mut free = cube.clone();
    free.physics.surface_tension = 0.0;
    let mut apart = common::cpu::<f32>(&free);
    apart.step(steps);
    let (_, _, radius) = extents(&apart.snapshot());
    assert!(radius > 1.3 * ball, "without surface tension the fluid reaches only {radius}");
    // DFSPH holds the density at rest instead of an equation of state: the same ball, at 2 ms
    // steps.
    let mut incompressible = cube;
    incompressible.physics.solver = PressureSolver::Dfsph;
    incompressible.physics.speed_of_sound = None;
    incompressible.time.dt = 0.002;
    let mut round = common::cpu::<f32>(&incompressible);
    round.step(150);
    assert!(round.health().is_ok(), "{:?}", round.health());
    let (axis, diagonal, radius) = extents(&round.snapshot());
    assert!((0.9..1.1).contains(&(diagonal / axis)), "DFSPH, round after 0.3 s: diagonal {diagonal} / axis {axis}");
    assert!(radius > 0.8 * ball && radius < 1.05 * ball, "DFSPH: a ball of the cube's volume has the radius {ball}; the fluid reaches {radius}");
}

/// A block of water 10 x 8 x 10 particles on the floor of a closed tank, without gravity, held
/// together by surface tension, after 0.6 s with adhesion `beta`: how many particles lie
/// within a spacing of the floor, and how wide the fluid is along x.
fn drop_on_floor(beta: f64) -> (usize, f64) {
    let scene = weightless()
        .domain([-0.1; 3], [0.3; 3])
        .fluid([0.05, 0.0, 0.05], [0.15, 0.08, 0.15])
        .closed_container([0.0; 3], [0.2; 3])
        .surface_tension(0.3)
        .wall_adhesion(beta)
        .build();
    let mut cpu = common::cpu::<f32>(&scene);
    assert_eq!(cpu.snapshot().positions.iter().filter(|p| p[1] < 0.01).count(), 100, "the bottom layer starts on the floor");
    cpu.step(1500);
    assert!(cpu.health().is_ok(), "beta {beta}: {:?}", cpu.health());
    let s = cpu.snapshot();
    let near = s.positions.iter().filter(|p| p[1] < 0.01).count();
    let (lo, hi) = s.positions.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| (lo.min(p[0]), hi.max(p[0])));
    (near, hi - lo)
}

#[test]
fn adhesion_wets_the_floor_and_without_it_a_weightless_drop_leaves_it() {
    let (near, width) = drop_on_floor(0.0);
    assert!(near < 20, "without adhesion the drop balls up and leaves the floor: {near} particles still on it");
    assert!(width < 0.11, "without adhesion the drop does not spread: {width} m wide");
    let (near, width) = drop_on_floor(5.0);
    assert!(near > 125, "adhesion spreads the drop over the floor: {near} particles on it (100 at the start)");
    assert!(width > 0.125, "adhesion spreads the drop: {width} m wide (0.09 m at the start)");
}

#[test]
fn surface_tension_and_adhesion_outside_their_range_or_use_are_refused_by_name() {
    for (gamma, beta) in [(-0.1, 0.0), (f64::NAN, 0.0), (1e3, 0.0), (0.0, -1.0), (0.0, f64::INFINITY)] {
        let e = TestScene::small_tank().surface_tension(gamma).wall_adhesion(beta).validation_error();
        let field = if gamma != 0.0 { "physics.surface_tension" } else { "physics.wall_adhesion" };
        assert!(e.contains(field) && e.contains("must be between 0 (off) and 100"), "{e}");
    }
    let e = weightless().fluid([0.0; 3], [0.1; 3]).wall_adhesion(0.01).validation_error();
    assert!(e.contains("physics.wall_adhesion") && e.contains("no"), "{e}");
}
