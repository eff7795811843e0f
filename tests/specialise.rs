//! Terms a scene does not use are neither computed nor allocated: the specialised GPU pipelines
//! and the CPU path agree for every combination, and a scene without walls allocates no wall
//! arrays.

mod common;

use wgsph::compare::{step_and_compare, MANY_STEPS, ONE_STEP};
use wgsph::cpu::CpuSolver;
use wgsph::gpu::GpuSolver;
use wgsph::scene::{Boundary, Scene};

/// dam_break at about 1000 particles with the chosen terms switched off.
fn variant(viscosity: bool, walls: bool, planes: bool, gravity: bool) -> Scene {
    let mut s = Scene::builtin("dam_break").unwrap().with_fluid_particles(1000);
    if !viscosity {
        s.physics.viscosity = 0.0;
    }
    if !gravity {
        s.physics.gravity = [0.0; 3];
    }
    s.boundary.retain(|b| match b {
        Boundary::Plane { .. } => planes,
        _ => walls,
    });
    s
}

#[test]
fn every_combination_of_terms_agrees_with_the_f64_cpu_path() {
    for ctx in common::contexts() {
        for mask in 0..16u32 {
            let on = |bit: u32| mask & (1 << bit) == 0;
            let s = variant(on(0), on(1), on(2), on(3));
            let (p, init) = (s.params(), s.initial_state());
            let mut gpu = GpuSolver::new(wgsph::gpu::GpuContext::from_adapter(ctx.adapter.clone()).unwrap(), &p, &init).unwrap();
            let mut cpu = CpuSolver::<f64>::new(&p, &init);
            let who = format!("{} viscosity {} walls {} planes {} gravity {}", ctx.describe(), on(0), on(1), on(2), on(3));
            let c = step_and_compare(&mut gpu, &mut cpu, 1, &ONE_STEP).unwrap();
            assert!(c.passed(), "{who}\n{}", c.table());
            let c = step_and_compare(&mut gpu, &mut cpu, 19, &MANY_STEPS).unwrap();
            assert!(c.passed(), "{who}\n{}", c.table());
        }
    }
}

#[test]
fn a_scene_without_walls_allocates_no_wall_arrays() {
    let with = variant(true, true, true, true);
    let without = variant(true, false, true, true);
    let cells = with.params().grid.cell_count() as u64;
    let (cw, cwo) = (CpuSolver::<f64>::new(&with.params(), &with.initial_state()), CpuSolver::<f64>::new(&without.params(), &without.initial_state()));
    assert_eq!(cwo.walls().2.len(), 0);
    // The per-cell wall starts (4 bytes a cell) and the wall particles are gone (on the GPU two
    // 16-byte placeholders stay bound).
    let walls = with.initial_state().wall_positions.len() as u64;
    assert_eq!(cw.memory_bytes() - cwo.memory_bytes(), (cells + 1) * 4 + walls * 32);
    for ctx in common::contexts() {
        let g = GpuSolver::new(wgsph::gpu::GpuContext::from_adapter(ctx.adapter.clone()).unwrap(), &with.params(), &with.initial_state()).unwrap();
        let go = GpuSolver::new(ctx, &without.params(), &without.initial_state()).unwrap();
        assert!(g.memory_bytes() - go.memory_bytes() == (cells + 1) * 4 + walls * 16 - 32, "{} {}", g.memory_bytes(), go.memory_bytes());
    }
}
