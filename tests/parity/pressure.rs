//! Continuity density, density diffusion (with the hydrostatic correction), artificial viscosity
//! and the hydrostatic start: the GPU against the f64 CPU path for each, fused and in two
//! passes, and a saved state that continues bit for bit.

use crate::common;
use crate::common::TestScene;

use wgsph::model::scene::{BoundaryPressure, Scene};
use wgsph::solver::compare::{step_and_compare, MANY_STEPS, ONE_STEP};
use wgsph::solver::gpu::{GpuContext, GpuOptions};
use wgsph::solver::Backend;

/// The small tank (Tait, clamped, moving block, walls and a plane) with each new option.
fn variants() -> Vec<(&'static str, Scene)> {
    let tank = || TestScene::small_tank();
    vec![
        ("continuity", tank().continuity().build()),
        ("continuity + diffusion", tank().continuity().density_diffusion(0.1).build()),
        ("continuity + diffusion + hydrostatic start", tank().continuity().density_diffusion(0.1).hydrostatic_start().build()),
        ("artificial viscosity (summation)", tank().viscosity(0.0).artificial_viscosity(0.1).build()),
        ("Adami wall pressure (summation)", tank().boundary_pressure(BoundaryPressure::Adami).build()),
        ("Adami wall pressure + continuity + diffusion", tank().boundary_pressure(BoundaryPressure::Adami).continuity().density_diffusion(0.1).hydrostatic_start().build()),
        ("everything", tank().continuity().density_diffusion(0.1).artificial_viscosity(0.05).hydrostatic_start().build()),
    ]
}

#[test]
fn each_option_agrees_with_the_f64_cpu_path_fused_and_in_two_passes() {
    for ctx in common::contexts() {
        for (name, scene) in variants() {
            for fuse in [false, true] {
                let options = GpuOptions { fuse_forces_and_integration: Some(fuse), ..GpuOptions::default() };
                let device = GpuContext::from_adapter(ctx.adapter.clone()).unwrap();
                let mut gpu = common::gpu_with(device, &scene, None, options).unwrap();
                let mut cpu = common::cpu::<f64>(&scene);
                let who = format!("{name} (fused {fuse}) on {}", ctx.describe());
                let c = step_and_compare(&mut gpu, &mut cpu, 1, &ONE_STEP).unwrap();
                assert!(c.field("density").max < 1e-5, "{who}\n{}", c.table());
                assert!(c.passed(), "{who}\n{}", c.table());
                let c = step_and_compare(&mut gpu, &mut cpu, 99, &MANY_STEPS).unwrap();
                assert!(c.passed(), "{who}\n{}", c.table());
            }
        }
    }
}

/// Steps `first`, saves the state into a new solver and steps both `then`: the carried
/// densities go with the state, so both end on the same bits.
fn resumed_equals_uninterrupted(a: &mut dyn Backend, b: &mut dyn Backend, first: u64, then: u64) -> bool {
    a.step(first).unwrap();
    let state = a.save_state().unwrap();
    assert_eq!(state.densities.len(), a.fluid_count(), "the saved state carries every particle's density");
    b.restore_state(&state).unwrap();
    a.step(then).unwrap();
    b.step(then).unwrap();
    let (sa, sb) = (a.snapshot().unwrap(), b.snapshot().unwrap());
    sa.positions == sb.positions && sa.velocities == sb.velocities && sa.densities == sb.densities
}

#[test]
fn a_saved_state_carries_the_densities_and_continues_bit_for_bit() {
    let scene = variants().pop().unwrap().1;
    let (mut a, mut b) = (common::cpu::<f32>(&scene), common::cpu::<f32>(&scene));
    assert!(resumed_equals_uninterrupted(&mut a, &mut b, 30, 30), "cpu f32");
    for ctx in common::contexts() {
        let mut a = common::gpu(GpuContext::from_adapter(ctx.adapter.clone()).unwrap(), &scene);
        let mut b = common::gpu(GpuContext::from_adapter(ctx.adapter.clone()).unwrap(), &scene);
        assert!(resumed_equals_uninterrupted(&mut a, &mut b, 30, 30), "{}", ctx.describe());
    }
}
