//! Terms a scene does not use are neither computed nor allocated: the specialised GPU pipelines
//! and the CPU path agree for every combination, and a scene without walls allocates no wall
//! arrays.

use crate::common;
use crate::common::TestScene;

use wgsph::solver::compare::step_and_compare;
use wgsph::solver::compare::MANY_STEPS;
use wgsph::solver::compare::ONE_STEP;
use wgsph::model::scene::Scene;
use wgsph::model::kernels::sort_by_cell;
use wgsph::model::real::V3;
use wgsph::solver::gpu::buffers::WallCellIndex;

/// dam_break at about 1000 particles with the chosen terms switched off.
fn variant(viscosity: bool, walls: bool, planes: bool, gravity: bool) -> Scene {
    let mut s = TestScene::from(Scene::builtin("dam_break").unwrap().with_fluid_particles(1000));
    if !viscosity {
        s = s.viscosity(0.0);
    }
    if !gravity {
        s = s.gravity([0.0; 3]);
    }
    if !walls {
        s = s.without_walls();
    }
    if !planes {
        s = s.without_planes();
    }
    s.build()
}

#[test]
fn every_combination_of_terms_agrees_with_the_f64_cpu_path() {
    for ctx in common::contexts() {
        for mask in 0..16u32 {
            let on = |bit: u32| mask & (1 << bit) == 0;
            let s = variant(on(0), on(1), on(2), on(3));
            let mut gpu = common::gpu(wgsph::solver::gpu::GpuContext::from_adapter(ctx.adapter.clone()).unwrap(), &s);
            let mut cpu = common::cpu::<f64>(&s);
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
    let (cw, cwo) = (common::cpu::<f64>(&with), common::cpu::<f64>(&without));
    assert_eq!(cwo.walls().2.len(), 0);
    // The per-cell wall starts (4 bytes a cell) and the wall particles are gone; on the CPU in f64 a wall particle is its position and
    // mass (32 bytes) and their copy as one element for the lane path's loads (32 bytes).
    let walls = with.initial_state().wall_positions.len() as u64;
    assert_eq!(cw.memory_bytes() - cwo.memory_bytes(), (cells + 1) * 4 + walls * 64);
    // On the GPU the wall cell index: a mask and a count per 32 cells, and the starts of the
    // cells that hold walls (three 16-byte placeholders stay bound without walls).
    let wall_f32: Vec<V3<f32>> = with.initial_state().wall_positions.iter().map(|&x| V3::from64(x)).collect();
    let (_, starts) = sort_by_cell(&with.params().grid.cast::<f32>(), &wall_f32);
    let index = WallCellIndex::new(&starts);
    let gpu_walls = index.blocks.len() as u64 * 8 + index.firsts.len() as u64 * 4 + walls * 16;
    for ctx in common::contexts() {
        let g = common::gpu(wgsph::solver::gpu::GpuContext::from_adapter(ctx.adapter.clone()).unwrap(), &with);
        let go = common::gpu(ctx, &without);
        assert!(g.memory_bytes() - go.memory_bytes() == gpu_walls - 48, "{} {}", g.memory_bytes(), go.memory_bytes());
    }
}
