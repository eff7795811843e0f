//! Every stage of the step and every shared function, GPU against its CPU twin, on the same
//! inputs: the kernels, the equations of state and the cell coordinates evaluated by a probe
//! shader that includes wgsl/shared/common.wgsl; the scan's block algorithm; the density and
//! pressure of a given state; the forces on a given state and its fields; the integration of a
//! given state with given accelerations; and the fused forces and integration. Each is judged
//! at f32 rounding, so a wrong stage shows even where a whole step would hide it.

use crate::common;
use crate::common::TestScene;
use wgsph::model::kernels::{exclusive_scan, pressure, KernelCoefficients};
use wgsph::model::real::V3;
use wgsph::model::scene::{BoundaryPressure, EquationOfState, Kernel, Scene};
use wgsph::solver::cpu::integrate::{advance_particle, Backstops, PlaneR, SolidBoxR};
use wgsph::solver::cpu::prefix_sum::{add_block_offsets, prefix_sum, scan_blocks, SCAN_BLOCK};
use wgsph::solver::gpu::params::GpuParams;
use wgsph::solver::gpu::readback::read_buffers;
use wgsph::solver::gpu::shaders::{assemble, bind_group, constants, layout, source, Use};
use wgsph::solver::gpu::GpuContext;
use wgsph::solver::Backend;
use wgpu::util::DeviceExt;

/// |a - b| within `ulps` units in the last place of f32 at the larger magnitude, or `floor`.
fn close(a: f64, b: f64, ulps: f64, floor: f64) -> bool {
    (a - b).abs() <= (ulps * f32::EPSILON as f64 * a.abs().max(b.abs())).max(floor)
}

/// The shared functions of common.wgsl evaluated on the GPU at `inputs` (distances in units of
/// h): per input, W(r^2), grad W at r along (0.6, 0.8, 0), lap W(r); the pressure of a density
/// between 0.9 and 1.1 rho0; and the cell of a point.
fn probe(ctx: &GpuContext, scene: &Scene, inputs: &[f32]) -> Vec<[f32; 4]> {
    let shader = r#"
//! include shared/common.wgsl
@group(0) @binding(1) var<storage, read> inputs: array<f32>;
@group(0) @binding(2) var<storage, read_write> outputs: array<vec4<f32>>;

@compute @workgroup_size(64)
fn probe(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if (i >= arrayLength(&inputs)) {
        return;
    }
    let r = inputs[i] * params.h;
    let g = kernel_grad(vec3<f32>(0.6 * r, 0.8 * r, 0.0), r);
    outputs[3u * i] = vec4<f32>(kernel_w(r * r), g.x, g.y, kernel_laplacian(r));
    let rho = params.rest_density * (0.9 + 0.2 * inputs[i] / 1.2);
    outputs[3u * i + 1u] = vec4<f32>(eos_pressure(rho), rho, 0.0, 0.0);
    let x = params.grid_origin.xyz + vec3<f32>(f32(i % 7u) + 0.37, f32(i % 5u) + 0.61, f32(i % 3u) + 0.23) / params.inv_cell;
    let c = cell_coords(x);
    outputs[3u * i + 2u] = vec4<f32>(bitcast<f32>(c.x), bitcast<f32>(c.y), bitcast<f32>(c.z), bitcast<f32>(cell_key(c)));
}
"#;
    let device = &ctx.device;
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("probe"),
        source: wgpu::ShaderSource::Wgsl(assemble(shader, &source).into()),
    });
    let layout = layout(device, "probe", &[Use::Uniform, Use::Read, Use::ReadWrite]);
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor { label: None, bind_group_layouts: &[Some(&layout)], immediate_size: 0 });
    let params = scene.params();
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("probe"),
        layout: Some(&pipeline_layout),
        module: &module,
        entry_point: Some("probe"),
        compilation_options: wgpu::PipelineCompilationOptions { constants: &constants(&params), zero_initialize_workgroup_memory: true },
        cache: None,
    });
    let uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: None,
        contents: &GpuParams::new(&params, 0, 0, params.viscosity_at_step(0)).bytes(),
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let input = device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: None, contents: bytemuck::cast_slice(inputs), usage: wgpu::BufferUsages::STORAGE });
    let bytes = inputs.len() as u64 * 48;
    let output = device.create_buffer(&wgpu::BufferDescriptor { label: None, size: bytes, usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC, mapped_at_creation: false });
    let group = bind_group(device, "probe", &layout, &[uniform.as_entire_binding(), input.as_entire_binding(), output.as_entire_binding()]);
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups((inputs.len() as u32).div_ceil(64), 1, 1);
    }
    ctx.queue.submit([encoder.finish()]);
    let data = read_buffers(ctx, &[(&output, bytes)]).unwrap();
    bytemuck::pod_collect_to_vec(&data[0])
}

#[test]
fn kernels_equations_of_state_and_cells_agree_function_by_function() {
    // 0 (the gradient's special case), the support itself, and beyond it.
    let inputs: Vec<f32> = (0..=120).map(|k| k as f32 / 100.0).collect();
    for ctx in common::contexts() {
        for (kernel, eos, clamp) in [
            (Kernel::Mueller, EquationOfState::Linear, false),
            (Kernel::Mueller, EquationOfState::Tait, true),
            (Kernel::CubicSpline, EquationOfState::Tait, false),
            (Kernel::CubicSpline, EquationOfState::Linear, true),
            (Kernel::Wendland, EquationOfState::Tait, true),
        ] {
            let scene = TestScene::small_tank().kernel(kernel).equation_of_state(eos).clamp_negative_pressure(clamp).build();
            let p = scene.params();
            let gpu = probe(&ctx, &scene, &inputs);
            let k = KernelCoefficients::<f32>::new(kernel, p.h);
            let grid = p.grid.cast::<f32>();
            let what = format!("{kernel:?} {eos:?} clamp {clamp} on {}", ctx.describe());
            for (i, &q) in inputs.iter().enumerate() {
                let r = q * p.h as f32;
                let g = k.grad_w(V3::new(0.6 * r, 0.8 * r, 0.0), r);
                let cpu = [k.w(r * r), g.x(), g.y(), k.lap_w(r)];
                // W and its derivatives scale like 1/h^3..1/h^6: judge against the kernel's size.
                let scale = [k.w(0.0), k.grad.abs() * p.h as f32, k.grad.abs() * p.h as f32, k.lap.abs() * p.h as f32].map(|x| x as f64 * 1e-6);
                for c in 0..4 {
                    assert!(close(gpu[3 * i][c] as f64, cpu[c] as f64, 8.0, scale[c]), "{what}: kernel value {c} at r = {q} h: gpu {} cpu {}", gpu[3 * i][c], cpu[c]);
                }
                let rho = gpu[3 * i + 1][1];
                let want = pressure::<f32>(rho, p.rest_density as f32, p.stiffness as f32, eos, clamp);
                // The equation of state's rounding is relative to k (rho/rho0)^7 times the
                // exponent (it subtracts 1 from the power), not to the pressure itself.
                let ratio = rho as f64 / p.rest_density;
                let eos_scale = match eos {
                    EquationOfState::Tait => 7.0 * p.stiffness * ratio.powi(7),
                    EquationOfState::Linear => p.stiffness * ratio,
                };
                assert!(
                    (gpu[3 * i + 1][0] as f64 - want as f64).abs() <= 16.0 * f32::EPSILON as f64 * eos_scale,
                    "{what}: pressure at rho = {rho}: gpu {} cpu {want}",
                    gpu[3 * i + 1][0]
                );
                let x = V3::new(
                    grid.origin.x() + ((i % 7) as f32 + 0.37) / grid.inv_cell,
                    grid.origin.y() + ((i % 5) as f32 + 0.61) / grid.inv_cell,
                    grid.origin.z() + ((i % 3) as f32 + 0.23) / grid.inv_cell,
                );
                let c = grid.cell_coords(x);
                let got = gpu[3 * i + 2].map(f32::to_bits);
                assert_eq!([got[0], got[1], got[2]], c, "{what}: cell of point {i}");
                assert_eq!(got[3], grid.key(c), "{what}: key of point {i}");
            }
        }
    }
}

#[test]
fn the_scan_twin_runs_the_blocks_like_the_gpu_and_equals_a_plain_scan() {
    for len in [0usize, 1, 255, 256, 257, SCAN_BLOCK * SCAN_BLOCK - 1, SCAN_BLOCK * SCAN_BLOCK + 3, 70_001] {
        let counts: Vec<u32> = (0..len as u32).map(|i| i.wrapping_mul(2654435761u32) >> 29).collect();
        let mut twin = vec![0u32; len + 1];
        prefix_sum(&counts, &mut twin);
        let mut plain = vec![0u32; len + 1];
        exclusive_scan(&counts, &mut plain);
        assert_eq!(twin, plain, "{len} counts");
        // One level by hand: each block scanned alone, then offset by the blocks before it.
        let mut data = counts.clone();
        let mut sums = vec![0u32; len.div_ceil(SCAN_BLOCK).max(1)];
        scan_blocks(&mut data, &mut sums);
        let mut offsets = vec![0u32; sums.len() + 1];
        exclusive_scan(&sums, &mut offsets);
        add_block_offsets(&mut data, &offsets[..sums.len()]);
        assert_eq!(data[..], plain[..len], "{len} counts, by blocks");
    }
}

/// A scene with walls, planes, gravity and viscosity in a tank, and its variants.
fn scene_with(kernel: Kernel, eos: EquationOfState, boundary_pressure: BoundaryPressure, viscosity: f64) -> Scene {
    TestScene::small_tank().kernel(kernel).equation_of_state(eos).boundary_pressure(boundary_pressure).viscosity(viscosity).build()
}

fn variants() -> Vec<Scene> {
    vec![
        scene_with(Kernel::Mueller, EquationOfState::Tait, BoundaryPressure::Mirror, 0.005),
        scene_with(Kernel::Mueller, EquationOfState::Linear, BoundaryPressure::Consistent, 0.0),
        scene_with(Kernel::CubicSpline, EquationOfState::Tait, BoundaryPressure::Consistent, 0.005),
        scene_with(Kernel::Wendland, EquationOfState::Linear, BoundaryPressure::Mirror, 0.005),
        // Continuity density with diffusion, artificial viscosity and a hydrostatic start.
        TestScene::small_tank().viscosity(0.0).continuity().density_diffusion(0.1).artificial_viscosity(0.05).hydrostatic_start().build(),
        // The Adami wall pressure, with summation and with continuity density.
        scene_with(Kernel::CubicSpline, EquationOfState::Tait, BoundaryPressure::Adami, 0.005),
        TestScene::small_tank().boundary_pressure(BoundaryPressure::Adami).continuity().density_diffusion(0.1).hydrostatic_start().build(),
    ]
}

/// Particles of the scene moved a few steps, so that neighbours are not on a lattice: the
/// common input of the stage tests (the same bits on both sides).
fn moved_state(scene: &Scene) -> wgsph::model::state::BackendState {
    let mut cpu = common::cpu::<f64>(scene);
    cpu.step(20);
    let mut state = cpu.save_state();
    // Widened from f32, so that both float types start from exactly the same positions.
    for v in state.positions.iter_mut().chain(state.velocities.iter_mut()) {
        *v = v.map(|x| x as f32 as f64);
    }
    for d in state.densities.iter_mut() {
        *d = *d as f32 as f64;
    }
    state
}

/// A CPU solver of type `R` and a GPU solver on `ctx` holding `state` (the GPU's kind of state).
fn both(ctx: GpuContext, scene: &Scene, state: &wgsph::model::state::BackendState) -> (wgsph::solver::gpu::GpuSolver, wgsph::solver::cpu::CpuSolver<f32>, wgsph::solver::cpu::CpuSolver<f64>) {
    let mut gpu = common::gpu(ctx, scene);
    let mut gpu_state = gpu.save_state().unwrap();
    gpu_state.positions = state.positions.clone();
    gpu_state.velocities = state.velocities.clone();
    gpu_state.ids = state.ids.clone();
    gpu_state.densities = state.densities.clone();
    gpu.restore_state(&gpu_state).unwrap();
    let mut f32s = common::cpu::<f32>(scene);
    let mut f64s = common::cpu::<f64>(scene);
    for (cpu_state, kind) in [(&mut f32s as &mut dyn Backend, "cpu f32"), (&mut f64s as &mut dyn Backend, "cpu f64")] {
        let mut s = state.clone();
        s.kind = kind.into();
        cpu_state.restore_state(&s).unwrap();
    }
    (gpu, f32s, f64s)
}

#[test]
fn density_and_pressure_of_a_state_agree_stage_alone() {
    for ctx in common::contexts() {
        for scene in variants() {
            let state = moved_state(&scene);
            let (mut gpu, mut f32s, mut f64s) = both(GpuContext::from_adapter(ctx.adapter.clone()).unwrap(), &scene, &state);
            // A snapshot bins the state and runs the density stage alone.
            let (g, c32, c64) = (gpu.snapshot().unwrap(), f32s.snapshot(), f64s.snapshot());
            let k = scene.params().stiffness;
            let rho0 = scene.params().rest_density;
            for i in 0..g.len() {
                // The equation of state subtracts 1 from (rho/rho0)^7: its rounding is relative
                // to k (rho/rho0)^7 times the exponent, not to the pressure.
                let p_scale = 7.0 * k * (g.densities[i] / rho0).powi(7);
                let what = format!("{} particle {i} on {}", format!("{:?}", scene.physics.kernel), ctx.describe());
                assert!(close(g.densities[i], c32.densities[i], 64.0, 0.0), "{what}: density gpu {} cpu f32 {}", g.densities[i], c32.densities[i]);
                assert!(close(g.densities[i], c64.densities[i], 64.0, 0.0), "{what}: density gpu {} cpu f64 {}", g.densities[i], c64.densities[i]);
                assert!((g.pressures[i] - c64.pressures[i]).abs() <= 64.0 * f32::EPSILON as f64 * p_scale, "{what}: pressure gpu {} cpu f64 {}", g.pressures[i], c64.pressures[i]);
            }
        }
    }
}

#[test]
fn the_wall_pressure_of_a_state_agrees_stage_alone() {
    for ctx in common::contexts() {
        for scene in variants().into_iter().filter(|s| s.physics.boundary_pressure == BoundaryPressure::Adami) {
            let state = moved_state(&scene);
            let (mut gpu, mut f32s, mut f64s) = both(GpuContext::from_adapter(ctx.adapter.clone()).unwrap(), &scene, &state);
            // A snapshot runs the density stage and then the wall stage on its fields.
            gpu.snapshot().unwrap();
            f32s.snapshot();
            f64s.snapshot();
            let (g, c32, c64) = (gpu.wall_fields().unwrap(), f32s.wall_fields(), f64s.wall_fields());
            assert_eq!(g.len(), scene.initial_state().wall_positions.len(), "one pressure and density per wall particle");
            assert_eq!((c32.len(), c64.len()), (g.len(), g.len()));
            let p_scale = c64.iter().map(|f| f[0].abs()).fold(0.0, f64::max);
            let wetted = c64.iter().filter(|f| f[0] > 0.0).count();
            // Walls under water carry a pressure (else the comparison below proves nothing).
            assert!(p_scale > 10.0 && wetted > 20, "{} wall particles with pressure, largest {p_scale} Pa", wetted);
            let (mut worst_p, mut worst_rho) = (0.0f64, 0.0f64);
            for w in 0..g.len() {
                // The f64 and f32 twins agree with each other; the GPU agrees with both to f32
                // sums of some 30 terms whose densities differ in their last bits.
                worst_p = worst_p.max((g[w][0] - c64[w][0]).abs().max((g[w][0] - c32[w][0]).abs()) / p_scale);
                worst_rho = worst_rho.max((g[w][1] - c64[w][1]).abs() / c64[w][1]);
            }
            let what = format!("{:?} {:?} on {}", scene.physics.kernel, scene.physics.density, ctx.describe());
            assert!(worst_p < 1e-4, "{what}: largest wall pressure difference / largest wall pressure {worst_p:.2e}");
            assert!(worst_rho < 1e-6, "{what}: largest relative wall density difference {worst_rho:.2e}");
        }
    }
}

#[test]
fn forces_on_a_state_agree_stage_alone() {
    for ctx in common::contexts() {
        for scene in variants() {
            let state = moved_state(&scene);
            let (mut gpu, mut f32s, mut f64s) = both(GpuContext::from_adapter(ctx.adapter.clone()).unwrap(), &scene, &state);
            // The fields of the state, then the forces on them (the accelerations the step
            // fields report are those of the state the last density stage saw).
            gpu.snapshot().unwrap();
            f32s.snapshot();
            f64s.snapshot();
            f32s.compute_forces();
            f64s.compute_forces();
            let (g, c32, c64) = (gpu.step_fields().unwrap(), f32s.step_fields(), f64s.step_fields());
            let norm = |a: [f64; 3]| (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
            let scale = (c64.accelerations.iter().map(|a| norm(*a).powi(2)).sum::<f64>() / c64.accelerations.len() as f64).sqrt();
            let mut worst = (0.0f64, 0.0f64);
            for i in 0..g.accelerations.len() {
                let d = |a: [f64; 3], b: [f64; 3]| norm([a[0] - b[0], a[1] - b[1], a[2] - b[2]]) / scale;
                worst.0 = worst.0.max(d(g.accelerations[i], c32.accelerations[i]));
                worst.1 = worst.1.max(d(g.accelerations[i], c64.accelerations[i]));
            }
            // Sums of some 50 terms in f32 whose inputs (densities) already differ in their last
            // bits: far below the 1e-3 a whole step is allowed.
            assert!(worst.0 < 1e-4 && worst.1 < 1e-4, "{} on {}: largest acceleration difference / rms against cpu f32 {:.2e}, f64 {:.2e}", format!("{:?}", scene.physics.kernel), ctx.describe(), worst.0, worst.1);
        }
    }
}

/// One GPU step from `state`, and the CPU twin's integration of the same state with the
/// accelerations that step used: the same positions and velocities to a rounding.
fn integration_agrees(ctx: &GpuContext, scene: &Scene, state: &wgsph::model::state::BackendState) -> wgsph::model::state::Snapshot {
    let (mut gpu, _, _) = both(GpuContext::from_adapter(ctx.adapter.clone()).unwrap(), scene, state);
    let before = gpu.snapshot().unwrap();
    gpu.step(1).unwrap();
    // The accelerations the GPU's step used, its state after the step.
    let a = gpu.step_fields().unwrap().accelerations;
    let after = gpu.snapshot().unwrap();
    let p = scene.params();
    let backstops = Backstops {
        planes: p.planes.iter().map(|q| PlaneR { normal: V3::from64(q.normal), offset: q.offset as f32, restitution: q.restitution as f32 }).collect(),
        boxes: p.solid_boxes.iter().map(|b| SolidBoxR { min: V3::from64(b.min), max: V3::from64(b.max) }).collect(),
    };
    let domain = (V3::from64(p.domain_min), V3::from64(p.domain_max));
    for i in 0..before.len() {
        let (mut x, mut v) = (V3::<f32>::from64(before.positions[i]), V3::<f32>::from64(before.velocities[i]));
        advance_particle(&mut x, &mut v, V3::from64(a[i]), p.dt as f32, &backstops, domain);
        for k in 0..3 {
            // One rounding apart at most (a fused multiply-add on the GPU).
            assert!(close(after.positions[i][k], x.0[k] as f64, 2.0, 1e-12), "particle {i} x[{k}] on {}: gpu {} cpu {}", ctx.describe(), after.positions[i][k], x.0[k]);
            assert!(close(after.velocities[i][k], v.0[k] as f64, 2.0, 2.0 * f32::EPSILON as f64 * p.dt * a[i][k].abs().max(1.0)), "particle {i} v[{k}] on {}: gpu {} cpu {}", ctx.describe(), after.velocities[i][k], v.0[k]);
        }
    }
    after
}

#[test]
fn the_integration_of_a_state_with_given_accelerations_agrees_stage_alone() {
    for ctx in common::contexts() {
        for scene in variants() {
            let state = moved_state(&scene);
            integration_agrees(&ctx, &scene, &state);
        }
    }
}

#[test]
fn a_particle_inside_a_solid_box_is_put_back_on_its_nearest_face_as_by_its_twin() {
    // The small tank with a box obstacle, and particles moved into the box near each of its
    // six faces, moving inwards: each leaves by its nearest face, with no velocity into the box.
    let (lo, hi) = ([0.3, 0.05, 0.05], [0.42, 0.2, 0.15]);
    let scene = TestScene::small_tank().solid_box(lo, hi).build();
    let mut state = moved_state(&scene);
    let inside = [
        ([0.303, 0.12, 0.1], [1.0, 0.0, 0.0], (0, lo[0])),
        ([0.418, 0.12, 0.1], [-1.0, 0.0, 0.0], (0, hi[0])),
        ([0.36, 0.052, 0.1], [0.0, 1.0, 0.0], (1, lo[1])),
        ([0.36, 0.197, 0.1], [0.0, -1.0, 0.0], (1, hi[1])),
        ([0.36, 0.12, 0.053], [0.2, 0.3, 1.0], (2, lo[2])),
        ([0.36, 0.12, 0.148], [0.0, 0.0, -1.0], (2, hi[2])),
    ];
    for (k, (x, v, _)) in inside.iter().enumerate() {
        state.positions[k] = *x;
        state.velocities[k] = *v;
    }
    let ids = state.ids.clone();
    for ctx in common::contexts() {
        let after = integration_agrees(&ctx, &scene, &state);
        for (k, (_, _, (axis, face))) in inside.iter().enumerate() {
            let i = ids[k] as usize;
            let x = after.positions[i];
            assert!((x[*axis] - face).abs() < 1e-6, "{}: particle {k} at {x:?}, not on the face {axis} = {face}", ctx.describe());
            let inward = if (*face - lo[*axis]).abs() < 1e-9 { after.velocities[i][*axis] } else { -after.velocities[i][*axis] };
            assert!(inward <= 0.0, "{}: particle {k} still moves into the box at {inward} m/s", ctx.describe());
        }
    }
}

#[test]
fn the_fused_twin_gives_the_two_pass_step_bit_for_bit() {
    for scene in variants() {
        let mut cpu = common::cpu::<f32>(&scene);
        cpu.step(20);
        cpu.bin();
        cpu.compute_density();
        let (x, v, found) = cpu.forces_and_integrate();
        let mut two_pass = cpu.clone();
        two_pass.compute_forces();
        let found_two = two_pass.integrate();
        let (x2, v2, _) = two_pass.particles();
        assert!(x == x2 && v == v2, "{}: the fused step differs from forces then integration", format!("{:?}", scene.physics.kernel));
        assert_eq!(found, found_two);
    }
}

#[test]
fn the_steps_bookkeeping_records_the_first_bad_step_as_its_twin_does() {
    // A block falling freely at 1 m/s and faster (no walls), with each check tripped on its own
    // at a step all the solvers reach with the same figures: the Mach number (a level halfway
    // between the largest speeds of steps 9 and 10, which differ by 0.4 %, far above f32
    // rounding), the density (a level below the block's own, heavier particles: step 1), the
    // domain (its bottom 0.04 m below the block, which falls without pressure forces, so that
    // its bottom layer leaves at once, 0.3 mm past it).
    // c0 = 0.01 m/s: the pressure forces are a millionth of gravity, so every particle falls freely.
    let falling = || TestScene::new().speed_of_sound(0.01).fluid([0.0, 0.2, 0.0], [0.1, 0.3, 0.1]).jitter(0.0).moving_at([0.0, -1.0, 0.0]).without_limits();
    let mut probe = common::cpu::<f64>(&falling().build());
    let mut speeds = Vec::new();
    for _ in 0..10 {
        probe.step(1);
        speeds.push(probe.health().max_speed);
    }
    assert!(speeds[9] > 1.003 * speeds[8], "{speeds:?}");
    let mut heavy = falling().build();
    heavy.physics.particle_mass = Some(1.5 * 1000.0 * 0.02f64.powi(3));
    let densest = common::cpu::<f64>(&heavy).snapshot().densities.iter().cloned().fold(0.0, f64::max);
    let cases = [
        ("mach", falling().stop_levels(f64::INFINITY, 0.5 * (speeds[8] + speeds[9]) / 0.01).build(), Some(10)),
        ("density", TestScene::from(heavy).stop_levels(0.999 * densest / 1000.0, f64::INFINITY).build(), Some(1)),
        ("domain", falling().domain([-0.1, 0.17, -0.1], [0.7, 0.9, 0.3]).build(), None),
    ];
    for (what, scene, expected) in cases {
        let mut f32s = common::cpu::<f32>(&scene);
        let mut f64s = common::cpu::<f64>(&scene);
        f32s.step(200);
        f64s.step(200);
        let reference = f64s.health().bad_step.unwrap_or_else(|| panic!("{what}: f64 never went bad"));
        if let Some(step) = expected {
            assert_eq!(reference.step, step, "{what}: {reference:?}");
        }
        let mut sides = vec![("cpu f32".to_string(), f32s.health())];
        for ctx in common::contexts() {
            let mut gpu = common::gpu(ctx, &scene);
            // More steps than the bad one: the GPU runs on, and must still report that step.
            gpu.step(200).unwrap();
            sides.push((gpu.adapter(), gpu.health().unwrap()));
        }
        for (who, health) in sides {
            let bad = health.bad_step.unwrap_or_else(|| panic!("{what} on {who}: no bad step"));
            assert_eq!((bad.step, bad.too_dense, bad.too_fast), (reference.step, reference.too_dense, reference.too_fast), "{what} on {who}: {bad:?}");
            let (m, r) = (&bad.measured, &reference.measured);
            assert_eq!((m.non_finite, m.escaped), (r.non_finite, r.escaped), "{what} on {who}: {bad:?}");
            assert!(close(m.max_speed, r.max_speed, 64.0, 0.0) && close(m.max_density, r.max_density, 64.0, 0.0), "{what} on {who}: {bad:?} against {reference:?}");
            assert!(close(m.dt, r.dt, 1.0, 0.0) && close(m.time, r.time, 4.0, 0.0), "{what} on {who}: {bad:?}");
            assert_eq!(health.first_bad_step, Some(bad.step), "{what} on {who}");
        }
    }
}
