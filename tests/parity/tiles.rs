//! The neighbour tiles (wgsl/shared/tiles.wgsl): where the adapter's subgroups have 8
//! invocations, the tiled density, continuity density, forces and DFSPH solve passes give the
//! one-particle-per-invocation stages' bits for every term they carry, and so do the forces and
//! DFSPH's solves walking the neighbour lists (wgsl/shared/neighbour_lists.wgsl), whether every
//! list fits, some or none; elsewhere asking for the tiles is refused with the reason.

use crate::common;
use crate::common::TestScene;

use wgsph::model::scene::{BoundaryPressure, EquationOfState, Kernel, Scene};
use wgsph::solver::gpu::{GpuOptions, WorkgroupSizes};
use wgsph::solver::Backend;

fn scenes() -> Vec<(&'static str, Scene)> {
    let tank = || TestScene::small_tank();
    vec![
        ("small tank (walls, plane, viscosity)", tank().build()),
        ("cubic spline, linear, unclamped", tank().kernel(Kernel::CubicSpline).equation_of_state(EquationOfState::Linear).clamp_negative_pressure(false).build()),
        ("Wendland, viscosity", tank().kernel(Kernel::Wendland).viscosity(0.005).build()),
        ("Adami wall pressure, artificial viscosity", tank().boundary_pressure(BoundaryPressure::Adami).viscosity(0.0).artificial_viscosity(0.1).build()),
        ("continuity, diffusion, hydrostatic start", tank().continuity().density_diffusion(0.1).hydrostatic_start().build()),
        ("planes only", tank().without_walls().plane([0.0; 3], [0.0, 1.0, 0.0], 0.5).build()),
        ("surface tension, adhesion", tank().surface_tension(0.5).wall_adhesion(2.0).build()),
        ("solid box", tank().solid_box([0.3, 0.0, 0.05], [0.4, 0.1, 0.15]).build()),
        ("dam break", Scene::load("dam_break").unwrap().with_fluid_particles(2000)),
        ("DFSPH", tank().dfsph().build()),
        ("DFSPH, adaptive dt", tank().dfsph().adaptive().build()),
    ]
}

#[test]
fn subgroup_tiles_change_no_value() {
    for ctx in common::contexts() {
        let tiles = |on: bool| GpuOptions { subgroup_tiles: Some(on), ..GpuOptions::default() };
        if let Some(why) = ctx.subgroup_tiles_unavailable() {
            let scene = TestScene::small_tank().build();
            let e = common::gpu_with(ctx.clone(), &scene, None, tiles(true)).err().expect("refused");
            let msg = format!("{e:#}");
            assert!(msg.contains(&why) && msg.contains("--subgroup-tiles") && msg.contains(&ctx.info.name), "{msg}");
            assert!(!common::gpu_with(ctx.clone(), &scene, None, GpuOptions::default()).unwrap().subgroup_tiles());
            continue;
        }
        for (name, scene) in scenes() {
            let run = |options: GpuOptions| {
                let mut solver = common::gpu_with(ctx.clone(), &scene, None, options).unwrap();
                // Equal bits after one step already say the values agree; 30 steps let the
                // particles move far enough for lists to fill up and overflow as they go.
                solver.step(30).unwrap();
                ((solver.subgroup_tiles(), solver.neighbour_list_capacity()), solver.snapshot().unwrap(), solver.step_fields().unwrap())
            };
            let ((used, capacity), tiled_state, tiled_fields) = run(GpuOptions::default());
            assert!(used, "{name} on {}: subgroup tiles are the default here", ctx.describe());
            let ((used, _), state, fields) = run(tiles(false));
            assert!(!used);
            assert!(state.positions != scene.initial_state().fluid_positions, "{name}: the particles moved");
            assert!(tiled_state == state && tiled_fields == fields, "{name} on {}: the tiles changed a value", ctx.describe());
            // Neighbour lists are the default with the tiles (the weakly compressible forces and
            // DFSPH's solves walk them); without them, and with lists too short for some or all
            // particles (their subgroups walk the tiles), the same bits.
            assert!(capacity.is_some(), "{name}: lists with the tiles");
            let lists = |on: bool, capacity: Option<u32>| GpuOptions { neighbour_lists: Some(on), neighbour_list_capacity: capacity, ..GpuOptions::default() };
            for (options, what) in [(lists(false, None), "without lists"), (lists(true, Some(12)), "12 slots"), (lists(true, Some(2)), "2 slots")] {
                let (_, listed_state, listed_fields) = run(options);
                assert!(listed_state == state && listed_fields == fields, "{name} on {}: {what} changed a value", ctx.describe());
            }
        }
        // Workgroups that are not whole subgroups: per particle by default, refused when asked.
        let scene = TestScene::small_tank().build();
        let odd = WorkgroupSizes { forces: 100, ..WorkgroupSizes::default() };
        let solver = common::gpu_with(ctx.clone(), &scene, None, GpuOptions { workgroup_sizes: odd, ..GpuOptions::default() }).unwrap();
        assert!(!solver.subgroup_tiles());
        let e = common::gpu_with(ctx.clone(), &scene, None, GpuOptions { workgroup_sizes: odd, ..tiles(true) }).err().expect("refused");
        assert!(format!("{e:#}").contains("workgroups of 100"), "{e:#}");
    }
}

#[test]
fn neighbour_lists_report_how_full_they_are() {
    for ctx in common::contexts() {
        if ctx.subgroup_tiles_unavailable().is_some() {
            continue;
        }
        let scene = TestScene::small_tank().build();
        let usage = |capacity: Option<u32>| {
            let options = GpuOptions { neighbour_list_capacity: capacity, ..GpuOptions::default() };
            let mut solver = common::gpu_with(ctx.clone(), &scene, None, options).unwrap();
            solver.step(10).unwrap();
            let n = solver.snapshot().unwrap().positions.len() as u64;
            (solver.neighbour_list_usage().unwrap().expect("lists with the tiles"), n)
        };
        // The default leaves room: nothing overflows, and the longest list is its own length.
        let (u, _) = usage(None);
        assert!(u.full == 0 && u.longest > 0 && u.longest <= u.slots, "{u:?}");
        // Shorter than the longest: some overflow; two slots: nearly all.
        let (some, n) = usage(Some(u.longest - 1));
        assert!(some.full > 0 && some.full < n && some.longest <= some.slots, "{some:?} of {n}");
        let (few, n) = usage(Some(2));
        assert!(few.full > n / 2, "{few:?} of {n}");
        // Without lists, nothing to report.
        let mut solver = common::gpu_with(ctx.clone(), &scene, None, GpuOptions { neighbour_lists: Some(false), ..GpuOptions::default() }).unwrap();
        solver.step(1).unwrap();
        assert_eq!(solver.neighbour_list_usage().unwrap(), None);
    }
}
