//! Helpers shared by the test programs: a device on every adapter (every GPU test runs on
//! each), the scenes the tests build, and solvers made by the one builder.

#![allow(dead_code)]

use wgsph::model::initial::InitialState;
use wgsph::model::real::Real;
use wgsph::model::scene::{Scene, SceneOrigin};
use wgsph::solver::cpu::CpuSolver;
use wgsph::solver::gpu::device::compute_adapters;
use wgsph::solver::gpu::{GpuContext, GpuOptions, GpuSolver};
use wgsph::solver::{open_with, BackendChoice, Precision};

/// A device on every adapter found. With none, the test is skipped with a visible message,
/// unless WGSPH_REQUIRE_GPU is set (CI sets it, so a missing driver fails there).
pub fn contexts() -> Vec<GpuContext> {
    let list: Vec<GpuContext> =
        compute_adapters().into_iter().map(|a| GpuContext::from_adapter(a).expect("device on a listed adapter")).collect();
    if list.is_empty() {
        if std::env::var_os("WGSPH_REQUIRE_GPU").is_some() {
            panic!("WGSPH_REQUIRE_GPU is set but no GPU adapter with compute shaders was found");
        }
        eprintln!("SKIPPED: no GPU adapter with compute shaders (install mesa-vulkan-drivers for lavapipe)");
    }
    list
}

/// The text of a small scene for GPU-against-CPU checks: a jittered block moving in a tank of
/// wall particles with a plane, gravity and viscosity. `physics_extra` and `time_extra` are
/// lines added to the `[physics]` and `[time]` tables.
pub fn small_scene_text(kernel: &str, eos: &str, clamp: bool, physics_extra: &str, time_extra: &str) -> String {
    format!(
        r#"
        name = "small"
        [domain]
        min = [-0.1, -0.1, -0.1]
        max = [0.7, 0.9, 0.3]
        [physics]
        smoothing_length = 0.04
        particle_spacing = 0.02
        kernel = "{kernel}"
        equation_of_state = "{eos}"
        speed_of_sound = 20.0
        clamp_negative_pressure = {clamp}
        viscosity = 0.005
        {physics_extra}
        boundary_friction = 0.5
        [time]
        dt = 0.0004
        end_time = 1.0
        {time_extra}
        [[fluid]]
        min = [0.0, 0.0, 0.0]
        max = [0.2, 0.3, 0.2]
        jitter = 0.1
        velocity = [0.3, 0.0, 0.0]
        [[boundary]]
        type = "container"
        min = [0.0, 0.0, 0.0]
        max = [0.6, 0.5, 0.2]
        [[boundary]]
        type = "plane"
        point = [0.5, 0.0, 0.0]
        normal = [-1.0, 0.0, 0.0]
        restitution = 0.5
        "#
    )
}

pub fn scene_from(text: &str) -> Scene {
    Scene::from_toml_str(text, &SceneOrigin::Text).unwrap_or_else(|e| panic!("{e}\n{text}"))
}

/// The GPU solver of `scene` on the device `ctx`, built by the one builder
/// ([`wgsph::solver::open`]).
pub fn gpu(ctx: GpuContext, scene: &Scene) -> GpuSolver {
    gpu_with(ctx, scene, None, GpuOptions::default()).expect("the scene opens on the GPU")
}

/// The GPU solver of `scene` from the particles `initial`.
pub fn gpu_from(ctx: GpuContext, scene: &Scene, initial: &InitialState) -> GpuSolver {
    gpu_with(ctx, scene, Some(initial.clone()), GpuOptions::default()).expect("the scene opens on the GPU")
}

/// The GPU solver of `scene` with `options` (and the particles `initial`, or the scene's own):
/// the builder's error where it refuses.
pub fn gpu_with(ctx: GpuContext, scene: &Scene, initial: Option<InitialState>, options: GpuOptions) -> anyhow::Result<GpuSolver> {
    let choice = BackendChoice::gpu_on(ctx).with_gpu_options(options);
    Ok(open_with(scene, initial, &choice)?.into_gpu().expect("a GPU was chosen"))
}

/// The CPU reference of `scene` in float type `R`.
pub fn cpu<R: Real>(scene: &Scene) -> CpuSolver<R> {
    cpu_open::<R>(scene, None)
}

/// The CPU reference of `scene` in float type `R`, from the particles `initial`.
pub fn cpu_from<R: Real>(scene: &Scene, initial: &InitialState) -> CpuSolver<R> {
    cpu_open::<R>(scene, Some(initial.clone()))
}

fn cpu_open<R: Real>(scene: &Scene, initial: Option<InitialState>) -> CpuSolver<R> {
    let precision = if std::mem::size_of::<R>() == 4 { Precision::F32 } else { Precision::F64 };
    open_with(scene, initial, &BackendChoice::cpu(precision)).expect("the scene opens on the CPU").into_cpu::<R>().expect("the chosen float type")
}
