//! One time step of the GPU and CPU paths for the `dam_break` scene and a resting block, at
//! 10 k fluid particles (and 100 k where the adapter allows it in reasonable time: set
//! WGSPH_BENCH_LARGE=1, and 1 M with WGSPH_BENCH_HUGE=1). Throughput is reported in fluid
//! particle-steps per second; the bytes of GPU memory per fluid particle are printed.

#[path = "../tests/common/mod.rs"]
mod common;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use std::time::{Duration, Instant};
use wgsph::solver::gpu::GpuContext;
use wgsph::model::scene::Scene;

fn scenes() -> Vec<(&'static str, Scene)> {
    vec![("dam_break", Scene::builtin("dam_break").unwrap()), ("resting_block", Scene::builtin("hydrostatic").unwrap())]
}

fn sizes() -> Vec<u64> {
    if std::env::var_os("WGSPH_BENCH_HUGE").is_some() {
        vec![10_000, 100_000, 1_000_000]
    } else if std::env::var_os("WGSPH_BENCH_LARGE").is_some() {
        vec![10_000, 100_000]
    } else {
        vec![10_000]
    }
}

fn bench_step(c: &mut Criterion) {
    let mut group = c.benchmark_group("step");
    group.sample_size(10).measurement_time(Duration::from_secs(5)).warm_up_time(Duration::from_secs(1));
    for (name, base) in scenes() {
        for &n in &sizes() {
            let scene = base.with_fluid_particles(n);
            let init = scene.initial_state();
            let fluid = init.fluid_positions.len() as u64;
            group.throughput(Throughput::Elements(fluid));
            if let Ok(ctx) = GpuContext::new() {
                let adapter = ctx.describe();
                let mut gpu = common::gpu(ctx, &scene);
                println!(
                    "gpu/{name}/{fluid}/{adapter}: {} bytes of GPU memory, {:.1} bytes per fluid particle",
                    gpu.memory_bytes(),
                    gpu.memory_bytes() as f64 / fluid as f64
                );
                group.bench_function(format!("gpu/{name}/{fluid}/{adapter}"), |b| {
                    b.iter_custom(|iters| {
                        let t = Instant::now();
                        gpu.advance(iters);
                        gpu.wait().unwrap();
                        t.elapsed()
                    })
                });
            }
            let mut cpu32 = common::cpu::<f32>(&scene);
            group.bench_function(format!("cpu_f32/{name}/{fluid}"), |b| b.iter(|| cpu32.step_once()));
            let mut cpu64 = common::cpu::<f64>(&scene);
            group.bench_function(format!("cpu_f64/{name}/{fluid}"), |b| b.iter(|| cpu64.step_once()));
        }
    }
    group.finish();
}

criterion_group!(benches, bench_step);
criterion_main!(benches);
