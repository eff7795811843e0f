//! Blocks that are not whole numbers of particle spacings: fluid fills its stated size to the
//! nearest whole layer (never pressed against a wall) and one warning line says by how much and
//! why; solid boxes and tank walls fill theirs exactly, with the stated number of layers on
//! every side.

use crate::common::TestScene;
use std::path::Path;
use std::process::{Command, Output};
use wgsph::model::scene::{Boundary, WallParticles};

fn wgsph(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_wgsph")).args(args).current_dir(dir).output().unwrap()
}

/// A 0.55 m column, 0.2 m wide and 0.08 m deep, at 0.04 m spacing in the corner of a closed
/// 1 m x 1 m x 0.08 m tank (the column fills the tank's depth).
fn column() -> TestScene {
    TestScene::new()
        .domain([-0.2; 3], [1.2, 1.2, 0.3])
        .smoothing_length(0.08)
        .particle_spacing(0.04)
        .fluid([0.0; 3], [0.2, 0.55, 0.08])
        .jitter(0.0)
        .closed_container([0.0; 3], [1.0, 1.0, 0.08])
}

fn extent(points: &[[f64; 3]], axis: usize) -> (f64, f64) {
    points.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| (lo.min(p[axis]), hi.max(p[axis])))
}

#[test]
fn a_column_not_a_whole_number_of_spacings_high_is_filled_to_the_nearest_layer() {
    // 0.55 / 0.04 = 13.75 layers: 14, on the floor (a wall), so 0.56 high, not 13 (0.52).
    let scene = column().build();
    let fluid = scene.initial_state().fluid_positions;
    assert_eq!(fluid.len(), 5 * 14 * 2);
    let (lo, hi) = extent(&fluid, 1);
    assert!((lo - 0.02).abs() < 1e-12 && (hi - 0.54).abs() < 1e-12, "y from {lo} to {hi}");
    let changes = scene.lattice_changes();
    assert_eq!(changes.len(), 1, "{changes:?}");
    assert!(changes[0].starts_with("fluid[0] is 0.2 x 0.55 x 0.08") && changes[0].contains("filled as 0.2 x 0.56 x 0.08 (y +1.8 %"), "{}", changes[0]);
    // A block of whole spacings says nothing.
    assert!(column().without_fluid().fluid([0.0; 3], [0.2, 0.56, 0.08]).build().lattice_changes().is_empty());
}

#[test]
fn fluid_keeps_half_a_spacing_from_walls_and_is_centred_where_free() {
    // Between two walls 0.41 m apart (10.25 spacings): the 10 that fit, centred, so that no
    // particle is nearer than half a spacing to either wall.
    let between = TestScene::new().smoothing_length(0.08).particle_spacing(0.04).fluid([0.0; 3], [0.41, 0.2, 0.08]).jitter(0.0).closed_container([0.0; 3], [0.41, 0.5, 0.08]).build();
    let fluid = between.initial_state().fluid_positions;
    assert_eq!(fluid.len(), 10 * 5 * 2);
    let (lo, hi) = extent(&fluid, 0);
    assert!(lo >= 0.02 - 1e-12 && hi <= 0.41 - 0.02 + 1e-12, "x from {lo} to {hi}");
    assert!((lo - (0.41 - hi)).abs() < 1e-12, "not centred: {lo} {hi}");
    // Free on both sides (a block in mid-air, 0.23 = 5.75 spacings wide): 6 spacings, centred.
    let free = column().without_fluid().fluid([0.4, 0.4, 0.0], [0.63, 0.6, 0.08]).jitter(0.0).build();
    let (lo, hi) = extent(&free.initial_state().fluid_positions, 0);
    assert!((lo - (0.4 - 0.005 + 0.02)).abs() < 1e-12 && (hi - (0.63 + 0.005 - 0.02)).abs() < 1e-12, "x from {lo} to {hi}");
}

#[test]
fn one_warning_line_says_how_a_block_was_filled() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("column.toml"), column().build().to_toml()).unwrap();
    let out = wgsph(&["run", "column.toml", "--steps", "1", "--backend", "cpu", "--out", "o"], dir.path());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let err = String::from_utf8_lossy(&out.stderr);
    let warnings: Vec<&str> = err.lines().filter(|l| l.starts_with("warning:")).collect();
    assert_eq!(warnings.len(), 1, "{err}");
    assert!(warnings[0].contains("fluid[0]") && warnings[0].contains("+1.8 %") && warnings[0].contains("rest density"), "{err}");
}

#[test]
fn a_solid_box_is_filled_exactly_with_its_wall_density() {
    // 0.25 m = 6.25 spacings: 6 points 0.041667 m apart, the outer ones half of that inside.
    let mut scene = column().build();
    let (min, max) = ([0.5, 0.0, 0.0], [0.75, 0.25, 0.08]);
    scene.boundary.push(Boundary::Box { min, max, walls: WallParticles { layers: Some(10), spacing: None, rest_density: None } });
    let tank_walls = column().build().initial_state().wall_positions.len();
    let st = scene.initial_state();
    let (points, masses) = (&st.wall_positions[tank_walls..], &st.wall_masses[tank_walls..]);
    let s = 0.25 / 6.0;
    for axis in [0, 1] {
        let (lo, hi) = extent(points, axis);
        assert!((lo - (min[axis] + s / 2.0)).abs() < 1e-12 && (hi - (max[axis] - s / 2.0)).abs() < 1e-12, "axis {axis}: {lo}..{hi}");
    }
    // A full box: its mass is the rest density times its volume.
    let total: f64 = masses.iter().sum();
    assert!((total - 1000.0 * 0.25 * 0.25 * 0.08).abs() < 1e-9, "{total}");
}

#[test]
fn a_tank_not_a_whole_number_of_spacings_has_all_its_wall_layers_on_every_side() {
    // A tank 0.43 m long at 0.04 m spacing (10.75 spacings), two layers: the walls beyond
    // x = 0.43 lie at 0.45 and 0.49, as those before x = 0 at -0.02 and -0.06 (beyond it there
    // was one layer, at 0.46).
    let scene = TestScene::new().smoothing_length(0.08).particle_spacing(0.04).domain([-0.2; 3], [0.7, 0.7, 0.3]).fluid([0.0; 3], [0.2, 0.2, 0.08]).closed_container([0.0; 3], [0.43, 0.4, 0.08]).build();
    let walls = scene.initial_state().wall_positions;
    let mut beyond: Vec<f64> = walls.iter().map(|p| p[0]).filter(|&x| x > 0.43).collect();
    beyond.sort_by(f64::total_cmp);
    beyond.dedup_by(|a, b| (*a - *b).abs() < 1e-12);
    assert_eq!(beyond.len(), 2, "{beyond:?}");
    assert!((beyond[0] - 0.45).abs() < 1e-12 && (beyond[1] - 0.49).abs() < 1e-12, "{beyond:?}");
    let mut before: Vec<f64> = walls.iter().map(|p| p[0]).filter(|&x| x < 0.0).collect();
    before.sort_by(f64::total_cmp);
    before.dedup_by(|a, b| (*a - *b).abs() < 1e-12);
    assert!((before[0] + 0.06).abs() < 1e-12 && (before[1] + 0.02).abs() < 1e-12, "{before:?}");
}

/// A block's `shape` cuts its box's lattice to the ellipsoid or cylinder inscribed in it: the
/// particles are exactly the lattice points inside, the count computed without creating them
/// is theirs, the volume is the shape's to within the lattice's steps, and the scene file
/// keeps the shape (a box says nothing). A shape too small to hold a lattice point is refused.
#[test]
fn a_shaped_block_holds_the_lattice_points_of_its_box_inside_the_shape() {
    use wgsph::model::lattice::points;
    use wgsph::model::scene::{FluidShape, Scene, SceneOrigin};
    let (min, max) = ([0.3, 0.3, 0.0], [0.5, 0.5, 0.2]);
    for (shape, volume) in [
        (FluidShape::Ellipsoid, 4.0 / 3.0 * std::f64::consts::PI * 0.1f64.powi(3)),
        (FluidShape::CylinderX, std::f64::consts::PI * 0.01 * 0.2),
        (FluidShape::CylinderY, std::f64::consts::PI * 0.01 * 0.2),
        (FluidShape::CylinderZ, std::f64::consts::PI * 0.01 * 0.2),
    ] {
        let mut scene = TestScene::new().domain([-0.2; 3], [1.2, 1.2, 0.4]).smoothing_length(0.02).particle_spacing(0.01).without_fluid().fluid(min, max).jitter(0.0).closed_container([0.0; 3], [1.0, 1.0, 0.2]).build();
        scene.fluid[0].shape = shape;
        let inside: Vec<[f64; 3]> = points(scene.fluid_lattice(0)).filter(|&q| shape.contains(min, max, q)).collect();
        let state = scene.initial_state();
        assert_eq!(state.fluid_positions, inside, "{shape:?}");
        assert_eq!(scene.fluid_particle_count(), inside.len() as u64, "{shape:?}");
        let filled = inside.len() as f64 * 0.01f64.powi(3);
        assert!((filled / volume - 1.0).abs() < 0.05, "{shape:?}: {filled} against {volume}");
        // Every particle inside the inscribed shape, none of the box's corners.
        assert!(inside.iter().all(|q| (0..3).all(|a| q[a] > min[a] && q[a] < max[a])));
        assert!(!inside.iter().any(|q| (q[0] - 0.305).abs() < 1e-9 && (q[1] - 0.305).abs() < 1e-9 && (q[2] - 0.005).abs() < 1e-9), "{shape:?}");
        let text = scene.to_toml();
        assert!(text.contains(&format!("shape = \"{}\"", shape.name())), "{text}");
        assert_eq!(Scene::from_toml_str(&text, &SceneOrigin::Text).unwrap(), scene);
    }
    let boxed = column().build();
    assert!(!boxed.to_toml().contains("shape"));
    // A box 1.6 spacings wide holds two points along each axis, 0.5 spacings from its centre:
    // outside the inscribed ellipsoid (3 (0.5 / 0.8)^2 > 1).
    let mut tiny = TestScene::new().domain([-0.2; 3], [1.2; 3]).smoothing_length(0.08).particle_spacing(0.04).fluid([0.4; 3], [0.464; 3]).closed_container([0.0; 3], [1.0; 3]).build();
    tiny.fluid[0].shape = FluidShape::Ellipsoid;
    let e = tiny.validate(&SceneOrigin::Text).unwrap_err().to_string();
    assert!(e.contains("fluid[0].shape") && e.contains("\"ellipsoid\"") && e.contains("no lattice point"), "{e}");
}

/// A drop (an ellipsoid block) falls into the tank from the command line, on the CPU path.
#[test]
fn a_drop_runs_from_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let o = wgsph(&["run", "hydrostatic", "--steps", "5", "--backend", "cpu", "--quiet", "--set", "fluid=[{min=[0.0,0.0,0.0],max=[0.4,0.3,0.1]},{min=[0.15,0.4,0.0],max=[0.25,0.5,0.1],shape=\"ellipsoid\"}]", "--out", "o"], dir.path());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.path().join("o/summary.json")).unwrap()).unwrap();
    let scene = wgsph::model::scene::Scene::load(dir.path().join("o/scene.toml").to_str().unwrap()).unwrap();
    assert_eq!(s["fluid_particles"].as_u64(), Some(scene.fluid_particle_count()));
    assert_eq!(scene.fluid[1].shape, wgsph::model::scene::FluidShape::Ellipsoid);
}
