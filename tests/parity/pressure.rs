//! Continuity density, density diffusion (with the hydrostatic correction), artificial viscosity,
//! surface tension and adhesion, and the hydrostatic start: the GPU against the f64 CPU path for each, fused and in two
//! passes, and a saved state that continues bit for bit.

use crate::common;
use crate::common::TestScene;

use wgsph::model::scene::{BoundaryPressure, Scene};
use wgsph::solver::compare::{compare, step_and_read, MANY_STEPS, ONE_STEP};
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
        ("surface tension and adhesion (summation)", tank().surface_tension(0.5).wall_adhesion(2.0).build()),
        ("everything", tank().continuity().density_diffusion(0.1).artificial_viscosity(0.05).hydrostatic_start().surface_tension(0.5).wall_adhesion(2.0).build()),
    ]
}

/// The variants (indices into `variants`) whose fused form runs on every adapter: the two that
/// carry every term between them (Adami's wall pressure with continuity density and diffusion,
/// and everything else). The first adapter runs every variant in both forms.
const FUSED_ON_EVERY_ADAPTER: [usize; 2] = [5, 7];

#[test]
fn each_option_agrees_with_the_f64_cpu_path_fused_and_in_two_passes() {
    let contexts = common::contexts();
    for (i, (name, scene)) in variants().into_iter().enumerate() {
        // The reference after 1 and after 100 steps, computed once for every GPU run.
        let mut cpu = common::cpu::<f64>(&scene);
        let (one, hundred) = (step_and_read(&mut cpu, 1).unwrap(), step_and_read(&mut cpu, 99).unwrap());
        let params = cpu.params().clone();
        for (k, ctx) in contexts.iter().enumerate() {
            // Another adapter (the same WGSL through another driver; OpenGL's llvmpipe steps
            // about three times slower than lavapipe) runs each variant in two passes and the
            // fused form where it adds no term (docs/testing.md: the suite's time budget).
            let forms: &[bool] = if k == 0 || FUSED_ON_EVERY_ADAPTER.contains(&i) { &[false, true] } else { &[false] };
            for &fuse in forms {
                let options = GpuOptions { fuse_forces_and_integration: Some(fuse), ..GpuOptions::default() };
                let device = GpuContext::from_adapter(ctx.adapter.clone()).unwrap();
                let mut gpu = common::gpu_with(device, &scene, None, options).unwrap();
                let who = format!("{name} (fused {fuse}) on {}", ctx.describe());
                let (fields, state) = step_and_read(&mut gpu, 1).unwrap();
                let c = compare(&params, 1, &ONE_STEP, (&fields, &state), (&one.0, &one.1));
                assert!(c.field("density").max < 1e-5, "{who}\n{}", c.table());
                assert!(c.passed(), "{who}\n{}", c.table());
                let (fields, state) = step_and_read(&mut gpu, 99).unwrap();
                assert_eq!(gpu.steps_done(), 100, "{who}");
                let c = compare(&params, 100, &MANY_STEPS, (&fields, &state), (&hundred.0, &hundred.1));
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
