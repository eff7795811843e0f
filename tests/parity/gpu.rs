//! The GPU pipeline against the CPU reference, on every adapter found (lavapipe and llvmpipe in
//! CI).

use crate::common;
use crate::common::TestScene;

use wgsph::solver::compare::step_and_compare;
use wgsph::solver::compare::MANY_STEPS;
use wgsph::solver::compare::ONE_STEP;
use wgsph::solver::cpu::prefix_sum::prefix_sum;
use wgsph::solver::cpu::reorder;
use wgsph::model::kernels::sort_by_cell;
use wgsph::solver::gpu::prefix_sum::exclusive_scan;
use wgsph::solver::gpu::GpuContext;
use wgsph::model::real::V3;
use wgsph::model::scene::{BoundaryPressure, EquationOfState, Kernel, Scene};
use wgsph::solver::Backend;

/// The small tank for each model combination, with a viscosity schedule.
fn small_scene(kernel: Kernel, eos: EquationOfState, clamp: bool) -> TestScene {
    TestScene::small_tank().kernel(kernel).equation_of_state(eos).clamp_negative_pressure(clamp).viscosity_change(0.002, 0.001)
}

/// Runs `steps` steps on the GPU and on the f64 CPU path from the scene's initial state and
/// compares them.
fn gpu_against_cpu(ctx: GpuContext, scene: &Scene, steps: u64, tol: &wgsph::solver::compare::Tolerances) -> wgsph::solver::compare::Comparison {
    let mut gpu = common::gpu(ctx, &scene);
    let mut cpu = common::cpu::<f64>(&scene);
    step_and_compare(&mut gpu, &mut cpu, steps, tol).unwrap()
}

#[test]
fn one_step_agrees_with_the_f64_cpu_path_to_f32_precision() {
    for ctx in common::contexts() {
        let name = ctx.describe();
        for (kernel, eos, clamp) in [
            (Kernel::Mueller, EquationOfState::Tait, true),
            (Kernel::Mueller, EquationOfState::Linear, false),
            (Kernel::CubicSpline, EquationOfState::Tait, false),
            (Kernel::Wendland, EquationOfState::Tait, true),
        ] {
            let device = GpuContext::from_adapter(ctx.adapter.clone()).unwrap();
            let c = gpu_against_cpu(device, &small_scene(kernel, eos, clamp).build(), 1, &ONE_STEP);
            let what = format!("{name} {kernel:?}/{eos:?}:\n{}", c.table());
            // Density to a relative 1e-5; acceleration to 1e-4 of its RMS magnitude.
            assert!(c.field("density").max < 1e-5, "{what}");
            assert!(c.field("acceleration").max < 1e-4, "{what}");
            assert!(c.passed(), "{what}");
        }
    }
}



#[test]
fn many_steps_stay_within_the_stated_tolerances_including_a_viscosity_change() {
    for ctx in common::contexts() {
        let c = gpu_against_cpu(ctx, &small_scene(Kernel::Mueller, EquationOfState::Tait, true).build(), 100, &MANY_STEPS);
        assert!(c.passed(), "{}", c.table());
    }
}

#[test]
fn compare_dam_break_100_steps_passes() {
    for ctx in common::contexts() {
        let c = gpu_against_cpu(ctx, &Scene::builtin("dam_break").unwrap(), 100, &MANY_STEPS);
        assert!(c.passed(), "{}", c.table());
    }
}

#[test]
fn binning_matches_a_cpu_counting_sort_exactly() {
    for ctx in common::contexts() {
        // The small scene, and one where every particle is in a single cell: h = 0.5, in a
        // domain grown to hold the walls, whose layers grow with h (still one cell of fluid).
        let crowded = small_scene(Kernel::Mueller, EquationOfState::Linear, false).smoothing_length(0.5).domain([-0.6; 3], [1.2, 1.1, 0.8]).build();
        for scene in [small_scene(Kernel::Mueller, EquationOfState::Tait, true).build(), crowded] {
            let (p, init) = (scene.params(), scene.initial_state());
            let mut gpu = common::gpu(GpuContext::from_adapter(ctx.adapter.clone()).unwrap(), &scene);
            let (ids, starts) = gpu.binning().unwrap();
            let grid = p.grid.cast::<f32>();
            let pos: Vec<V3<f32>> = init.fluid_positions.iter().map(|&x| V3::from64(x)).collect();
            let (sorted, cpu_starts) = sort_by_cell(&grid, &pos);
            assert_eq!(starts, cpu_starts);
            assert_eq!(ids, sorted);
            // The twin of the GPU's two reorder entry points: sending each particle to its
            // destination gathers the state as the sorted order does.
            let mut dest = Vec::new();
            reorder::reorder_rank(&sorted, &mut dest);
            let mut scattered = vec![V3([0.0f32; 3]); pos.len()];
            for (i, &d) in dest.iter().enumerate() {
                scattered[d as usize] = pos[i];
            }
            let mut gathered = Vec::new();
            reorder::reorder(&sorted, &pos, &mut gathered);
            assert!(scattered == gathered);
        }
    }
}

#[test]
fn the_density_and_pressure_arrays_handed_to_the_renderer_are_the_state_s_as_by_their_twin() {
    use wgsph::solver::cpu::fields::output_fields;
    use wgsph::solver::gpu::readback::read_buffers;
    for ctx in common::contexts() {
        // Summed density (in the w of the velocities), and the continuity equation's array.
        for continuity in [false, true] {
            let base = small_scene(Kernel::Mueller, EquationOfState::Tait, false);
            let scene = if continuity { base.continuity() } else { base }.build();
            let p = scene.params();
            let mut gpu = common::gpu(ctx.clone(), &scene);
            gpu.step(7).unwrap();
            let snapshot = gpu.snapshot().unwrap();
            let buffers = gpu.particle_buffers().unwrap();
            let n = buffers.count as u64;
            let data = read_buffers(&ctx, &[(&buffers.positions, n * 16), (&buffers.densities, n * 4), (&buffers.pressures, n * 4)]).unwrap();
            let pos: Vec<[f32; 4]> = bytemuck::pod_collect_to_vec(&data[0]);
            let (rho, pressure): (Vec<f32>, Vec<f32>) = (bytemuck::pod_collect_to_vec(&data[1]), bytemuck::pod_collect_to_vec(&data[2]));
            // The snapshot's densities in slot order, through the CPU twin.
            let slot_densities: Vec<f32> = pos.iter().map(|x| snapshot.densities[x[3].to_bits() as usize] as f32).collect();
            let eos = |r: f32| wgsph::model::kernels::pressure::<f32>(r, p.rest_density as f32, p.stiffness as f32, p.eos, p.clamp_negative_pressure);
            let (mut d, mut q) = (Vec::new(), Vec::new());
            output_fields(&slot_densities, eos, &mut d, &mut q);
            assert!(rho == d, "{}: densities differ", ctx.describe());
            for (k, (&a, &b)) in pressure.iter().zip(&q).enumerate() {
                assert!((a - b).abs() <= 1e-5 * p.stiffness as f32, "{}: pressure {k}: {a} against {b}", ctx.describe());
            }
            assert!(rho.iter().any(|&r| r != p.rest_density as f32));
        }
    }
}

#[test]
fn prefix_sum_is_exact_for_any_cell_count() {
    for ctx in common::contexts() {
        for n in [1usize, 255, 256, 257, 65_536, 1_000_003] {
            let counts: Vec<u32> = (0..n).map(|i| ((i as u64 * 2654435761) % 7) as u32).collect();
            let mut expected = vec![0u32; n + 1];
            prefix_sum(&counts, &mut expected);
            let got = exclusive_scan(&ctx, &counts).unwrap();
            assert_eq!(got.len(), n + 1);
            assert!(got == expected, "{}: scan of {n} values differs", ctx.describe());
        }
    }
}

#[test]
fn runs_are_bitwise_reproducible_and_conserve_mass() {
    for ctx in common::contexts() {
        let scene = small_scene(Kernel::Mueller, EquationOfState::Tait, true).build();
        let init = scene.initial_state();
        let run = || {
            let mut gpu = common::gpu(GpuContext::from_adapter(ctx.adapter.clone()).unwrap(), &scene);
            gpu.step(60).unwrap();
            // A snapshot in the middle must not change the trajectory.
            let mid = gpu.snapshot().unwrap();
            gpu.step(40).unwrap();
            let (ids, _) = gpu.binning().unwrap();
            (mid, gpu.snapshot().unwrap(), ids)
        };
        let (mid_a, a, ids) = run();
        let (mid_b, b, _) = run();
        let bits = |s: &wgsph::Snapshot| -> Vec<u64> {
            s.positions.iter().chain(&s.velocities).flatten().chain(&s.densities).chain(&s.pressures).map(|v| v.to_bits()).collect()
        };
        assert!(bits(&mid_a) == bits(&mid_b), "{}: runs differ at step 60", ctx.describe());
        assert!(bits(&a) == bits(&b), "{}: runs differ at step 100", ctx.describe());
        // Mass: every particle is still there exactly once, each with its mass.
        let mut sorted = ids.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..init.fluid_positions.len() as u32).collect::<Vec<_>>());
        assert_eq!(a.len(), init.fluid_positions.len());
        assert_eq!(a.non_finite_count(), 0);
    }
}

#[test]
fn a_snapshot_between_steps_does_not_change_the_trajectory() {
    for ctx in common::contexts() {
        let scene = small_scene(Kernel::CubicSpline, EquationOfState::Tait, true).build();
        let mut with = common::gpu(GpuContext::from_adapter(ctx.adapter.clone()).unwrap(), &scene);
        let mut without = common::gpu(ctx, &scene);
        for _ in 0..5 {
            with.step(7).unwrap();
            with.snapshot().unwrap();
        }
        without.step(35).unwrap();
        assert_eq!(with.snapshot().unwrap(), without.snapshot().unwrap());
    }
}

/// The consistent wall pressure (p_i / rho_i^2) agrees between the GPU and the CPU, and the
/// GPU's specialisation constant takes effect: its step differs from the CPU's mirrored one.
#[test]
fn consistent_wall_pressure_agrees_with_the_cpu_path() {
    for ctx in common::contexts() {
        let name = ctx.describe();
        let consistent = small_scene(Kernel::CubicSpline, EquationOfState::Tait, true).boundary_pressure(BoundaryPressure::Consistent).build();
        let device = GpuContext::from_adapter(ctx.adapter.clone()).unwrap();
        let c = gpu_against_cpu(device, &consistent, 1, &ONE_STEP);
        assert!(c.field("acceleration").max < 1e-4 && c.passed(), "{name}:\n{}", c.table());
        let mut gpu = common::gpu(GpuContext::from_adapter(ctx.adapter.clone()).unwrap(), &consistent);
        let mirror = small_scene(Kernel::CubicSpline, EquationOfState::Tait, true).build();
        let mut cpu_mirror = common::cpu::<f64>(&mirror);
        let c = step_and_compare(&mut gpu, &mut cpu_mirror, 1, &ONE_STEP).unwrap();
        assert!(!c.passed() && c.field("acceleration").max > 1e-3, "{name}: the wall pressure made no difference:\n{}", c.table());
    }
}
