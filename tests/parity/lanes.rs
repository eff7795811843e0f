//! The CPU path's density and forces eight particles at a time (the default where the processor
//! has AVX2) against its scalar loops, each particle over its stencil as the GPU walks it: the
//! same state after many steps, bit for bit, in f32 and f64, for every term and kernel, with
//! and without walls, and with the grid rebuilt every second step (particles then sit outside
//! the cell they were sorted into). DFSPH's factors pass lists and sums eight particles at a
//! time the same way, and so do the surface normals and the surface tension and adhesion terms.

use crate::common;
use crate::common::TestScene;
use wgsph::model::real::Real;
use wgsph::model::scene::{BoundaryPressure, BoundaryVolume, EquationOfState, Kernel, Scene};
use wgsph::model::state::BackendState;

fn scenes() -> Vec<(&'static str, Scene)> {
    let tank = || TestScene::small_tank();
    vec![
        ("poly6/spiky, Tait, mirror walls, viscosity", tank().kernel(Kernel::Mueller).viscosity(0.005).boundary_pressure(BoundaryPressure::Mirror).build()),
        ("poly6/spiky, linear, no viscosity", tank().kernel(Kernel::Mueller).equation_of_state(EquationOfState::Linear).viscosity(0.0).build()),
        ("cubic, Tait, viscosity", tank().kernel(Kernel::CubicSpline).viscosity(0.005).boundary_pressure(BoundaryPressure::Consistent).build()),
        ("Wendland, Tait, viscosity, Adami walls", tank().kernel(Kernel::Wendland).viscosity(0.005).boundary_pressure(BoundaryPressure::Adami).build()),
        ("cubic, artificial viscosity, continuity", tank().viscosity(0.0).continuity().density_diffusion(0.1).artificial_viscosity(0.05).build()),
        ("cubic, grid rebuilt every 2nd step", tank().kernel(Kernel::CubicSpline).neighbour_rebuild_every(2).build()),
        ("planes only, no wall particles", tank().without_walls().build()),
        ("Adami wall pressure", tank().boundary_pressure(BoundaryPressure::Adami).build()),
        ("surface tension and adhesion, Adami walls", tank().surface_tension(0.5).wall_adhesion(2.0).boundary_pressure(BoundaryPressure::Adami).build()),
        ("surface tension and adhesion, cubic, grid rebuilt every 2nd step", tank().kernel(Kernel::CubicSpline).surface_tension(0.5).wall_adhesion(2.0).neighbour_rebuild_every(2).build()),
        ("DFSPH (the factors pass), cubic, viscosity", tank().kernel(Kernel::CubicSpline).viscosity(0.005).dfsph().build()),
        ("DFSPH, Akinci walls, grid rebuilt every 2nd step", tank().dfsph().boundary_volume(BoundaryVolume::Akinci).neighbour_rebuild_every(2).build()),
        ("DFSPH, planes only", tank().without_walls().dfsph().build()),
        ("DFSPH, surface tension and adhesion", tank().dfsph().surface_tension(0.5).wall_adhesion(2.0).build()),
    ]
}

fn run<R: Real>(scene: &Scene, lanes: bool, steps: u64) -> BackendState {
    let mut cpu = common::cpu::<R>(scene);
    cpu.use_lanes(lanes);
    cpu.step(steps);
    cpu.save_state()
}

fn same_bits<R: Real>(what: &str, steps: u64) {
    for (name, scene) in scenes() {
        let (lanes, scalar) = (run::<R>(&scene, true, steps), run::<R>(&scene, false, steps));
        let fields = [("position", &lanes.positions, &scalar.positions), ("velocity", &lanes.velocities, &scalar.velocities)];
        for (field, a, b) in fields {
            for (i, (x, y)) in a.iter().zip(b.iter()).enumerate() {
                assert!(x.iter().zip(y).all(|(p, q)| p.to_bits() == q.to_bits()), "{what} {name}: {field} of particle {i} after {steps} steps: lanes {x:?}, scalar loops {y:?}");
            }
        }
        assert_eq!(lanes.ids, scalar.ids, "{what} {name}: particle order");
        for (i, (x, y)) in lanes.densities.iter().zip(&scalar.densities).enumerate() {
            assert_eq!(x.to_bits(), y.to_bits(), "{what} {name}: carried density of particle {i}");
        }
    }
}

#[test]
fn eight_particles_at_a_time_give_the_scalar_loops_bits() {
    same_bits::<f32>("f32", 40);
    same_bits::<f64>("f64", 40);
}
