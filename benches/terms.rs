//! The cost of each model term: one step of `dam_break` (about 4000 fluid particles) with every
//! term, and with one term switched off (or, for adaptive dt and the grid rebuild interval,
//! switched on) at a time, from the initial state. The GPU pipelines are specialised per scene and the CPU path skips
//! unused terms, so the difference between two rows is what the term costs.

#[path = "../tests/common/mod.rs"]
mod common;

use criterion::{criterion_group, criterion_main, BatchSize, Criterion, Throughput};
use std::time::{Duration, Instant};
use wgsph::solver::gpu::GpuContext;
use wgsph::model::scene::Boundary;
use wgsph::model::scene::Scene;

fn variants() -> Vec<(&'static str, Scene)> {
    let base = Scene::builtin("dam_break").unwrap();
    let mut out = vec![("all terms", base.clone())];
    let mut s = base.clone();
    s.physics.viscosity = 0.0;
    out.push(("no viscosity", s));
    let mut s = base.clone();
    s.boundary.retain(|b| matches!(b, Boundary::Plane { .. }));
    out.push(("no wall particles", s));
    let mut s = base.clone();
    s.boundary.retain(|b| !matches!(b, Boundary::Plane { .. }));
    out.push(("no planes", s));
    let mut s = base.clone();
    s.physics.gravity = [0.0; 3];
    out.push(("no gravity", s));
    let mut s = base.clone();
    s.time.adaptive = true;
    out.push(("adaptive dt", s));
    let mut s = base.clone();
    s.time.neighbour_rebuild_every = 2;
    out.push(("grid rebuilt every 2nd step", s));
    out
}

fn bench_terms(c: &mut Criterion) {
    let mut group = c.benchmark_group("terms");
    group.sample_size(10).measurement_time(Duration::from_secs(3)).warm_up_time(Duration::from_secs(1));
    for (name, scene) in variants() {
        let init = scene.initial_state();
        group.throughput(Throughput::Elements(init.fluid_positions.len() as u64));
        // Every sample starts from the scene's initial state (a fresh solver, built outside the
        // timing), so that the variants are timed on the same flow, not on states that drifted
        // apart over hundreds of steps.
        if let Ok(ctx) = GpuContext::new() {
            let adapter = ctx.adapter.clone();
            drop(ctx);
            group.bench_function(format!("gpu/{name}"), |b| {
                b.iter_custom(|iters| {
                    let mut gpu = common::gpu(GpuContext::from_adapter(adapter.clone()).unwrap(), &scene);
                    gpu.wait().unwrap();
                    let t = Instant::now();
                    gpu.advance(iters);
                    gpu.wait().unwrap();
                    t.elapsed()
                })
            });
        }
        group.bench_function(format!("cpu_f32/{name}"), |b| {
            b.iter_batched(|| common::cpu::<f32>(&scene), |mut cpu| cpu.step_once(), BatchSize::LargeInput)
        });
    }
    group.finish();
}

criterion_group!(benches, bench_terms);
criterion_main!(benches);
