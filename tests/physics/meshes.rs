//! Mesh walls in the solver: a round tank lined from a cylinder mesh holds still water within
//! DFSPH's tolerance, as a container of wall particles does.

use crate::common;
use crate::dfsph::still_tank;
use wgsph::model::scene::{Boundary, MeshWall, SceneOrigin, WallParticles};

/// Water in a round tank: the cylinder of scenes/meshes/cylinder.obj scaled to radius 0.1 m
/// and 0.3 m high, the fluid inside it; a block 0.2 m on a side is cut to the cylinder's
/// 0.2 m of depth. DFSPH with a fixed dt of 2 ms, as the still tank of the DFSPH tests.
#[test]
fn a_round_tank_from_a_mesh_holds_still_water() {
    // The DFSPH tests' still tank, its container replaced by the mesh.
    let mut scene = still_tank().named("round").domain([-0.06, -0.06, -0.06], [0.26, 0.36, 0.26]).build();
    scene.boundary.clear();
    scene.boundary.push(Boundary::Mesh(MeshWall {
        file: format!("{}/scenes/meshes/cylinder.obj", env!("CARGO_MANIFEST_DIR")),
        scale: [0.1, 0.3, 0.1],
        rotation_axis: [0.0, 1.0, 0.0],
        rotation_degrees: 0.0,
        translate: [0.1, 0.0, 0.1],
        fluid_inside: true,
        crc32: None,
        walls: WallParticles::default(),
        surface: Default::default(),
    }));
    scene.read_meshes(&SceneOrigin::Text).unwrap();
    scene.validate(&SceneOrigin::Text).unwrap();
    let radius = |x: &[f64; 3]| ((x[0] - 0.1).powi(2) + (x[2] - 0.1).powi(2)).sqrt();
    let start = scene.initial_state();
    // The block is cut to the cylinder, half a spacing clear of its wall (up to the flats of
    // its 32 sides).
    assert!(start.fluid_positions.iter().all(|x| radius(x) < 0.1 - 0.01 + 1e-9));
    let volume = std::f64::consts::PI * 0.1 * 0.1 * 0.2;
    let filled = start.fluid_positions.len() as f64 * 0.02f64.powi(3);
    assert!(filled > 0.6 * volume && filled < volume, "{filled} m^3 of fluid in a {volume} m^3 cylinder");

    let mut cpu = common::cpu::<f64>(&scene);
    // The fluid starts half a spacing clear of the stepped lattice of a curved wall and
    // settles into it: about 1 s (measured: mean speed 0.042 m/s at 0.6 s, 0.014 at 1.2 s).
    cpu.step(600);
    let h = cpu.health();
    assert!(h.is_ok(), "{h:?}");
    let s = cpu.snapshot();
    // At rest after 0.6 s, inside the tank, at about the rest density.
    let mean_speed = s.velocities.iter().map(|v| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()).sum::<f64>() / s.len() as f64;
    assert!(mean_speed < 0.03, "still moving at {mean_speed} m/s on average");
    // The lattice's steps along a curved wall hold the fluid up to half a spacing beyond the
    // mesh's surface (measured: 0.107 m at most), never through the walls' 0.04 m.
    let widest = s.positions.iter().map(radius).fold(0.0, f64::max);
    assert!(widest < 0.1 + 0.01 && s.positions.iter().all(|x| x[1] > 0.0), "a particle at r = {widest} left the round tank");
    // Within DFSPH's default tolerance (1e-4; measured 9e-5).
    let compression = s.densities.iter().map(|rho| (rho / 1000.0 - 1.0).max(0.0)).sum::<f64>() / s.len() as f64;
    assert!(compression <= 1.05e-4, "mean compression {compression:.3e}");
}
