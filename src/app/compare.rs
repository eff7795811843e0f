//! `wgsph compare`: the GPU against the f64 CPU reference from the same state, every field.
//!
//! A DFSPH scene is compared twice. Its solves stop at a tolerance, and a solve whose error ends
//! within rounding of it stops one iteration earlier on one path than on the other: the two
//! paths then differ by a Jacobi step of the size of the tolerance, which the flow amplifies
//! over the steps far beyond rounding (docs/dfsph.md, "GPU against the CPU"). So the run as the
//! scene sets it is judged after one step and by its iteration counts, and the many-step
//! comparison of the state is made again with every solve held at a fixed number of
//! iterations on both paths, where only the arithmetic differs.

use super::args::CompareArgs;
use crate::model::scene::Scene;
use crate::model::state::IterationStats;
use crate::solver::compare::{compare, many_steps, one_step, step_and_compare, step_and_read};
use crate::solver::{open, BackendChoice, Precision};

/// Iterations per step of the two paths' solves may differ by this fraction of the
/// reference's (and by 3 iterations over the run): a solve stops one iteration apart now and then.
pub const ITERATION_TOLERANCE: f64 = 0.05;

/// The DFSPH many-step comparison's tolerances are at least this many times the CPU's f32
/// path's errors against its f64 path (rounding's own growth in that scene).
pub const F32_FLOOR: f64 = 3.0;

pub fn cmd_compare(args: &CompareArgs) -> anyhow::Result<i32> {
    let scene = super::args::load_scene(&args.scene, None, false)?;
    let steps = args.steps.max(1);
    let dfsph = scene.physics.solver == crate::model::scene::PressureSolver::Dfsph;
    let (mut ok, iterations) = compare_runs(&scene, steps, !dfsph)?;
    if let Some((gpu, cpu)) = iterations {
        ok &= iterations_agree(&gpu, &cpu, steps);
        let pinned = with_fixed_iterations(&scene, &cpu, steps);
        let d = &pinned.physics.dfsph;
        println!(
            "the same {steps} steps with every solve held at {} constant-density{} iterations on both paths:",
            d.max_iterations,
            if d.divergence_solve { format!(" and {} divergence", d.max_divergence_iterations) } else { String::new() }
        );
        ok &= compare_pinned(&pinned, steps)?;
    }
    println!("{}", if ok { "compare: passed" } else { "compare: FAILED (an error is over its tolerance)" });
    Ok(if ok { 0 } else { 1 })
}

/// Runs `scene` on the GPU and on the f64 CPU path from the same state and prints the
/// comparison after one step and after `steps`; whether every judged comparison passed, and
/// for DFSPH the two paths' iterations (GPU, CPU). `judge_many`: whether the comparison after
/// `steps` counts (otherwise it is printed as information).
fn compare_runs(scene: &Scene, steps: u64, judge_many: bool) -> anyhow::Result<(bool, Option<(IterationStats, IterationStats)>)> {
    let mut gpu = open(scene, &BackendChoice::gpu())?.into_backend();
    let mut cpu = open(scene, &BackendChoice::cpu(Precision::F64))?.into_backend();
    println!("{}: {} fluid + {} wall particles; gpu {} against cpu f64", scene.name, gpu.fluid_count(), gpu.wall_count(), gpu.adapter());
    let mut ok = true;
    let mut done = 0;
    let (one, many) = (one_step(&scene.params()), many_steps(&scene.params()));
    for (target, tol, judged) in [(1, &one, true), (steps, &many, judge_many)] {
        if target <= done {
            continue;
        }
        let c = step_and_compare(gpu.as_mut(), cpu.as_mut(), target - done, tol)?;
        done = target;
        print!("{}", c.table_as(judged));
        if judged {
            ok &= c.passed();
        } else {
            println!(
                "  (not judged: each solve stops at its tolerance, one iteration apart on the two paths now and then, \
                 and the flow amplifies that step's difference; judged below with the iterations held fixed)"
            );
        }
    }
    let iterations = match (gpu.health()?.iterations, cpu.health()?.iterations) {
        (Some(g), Some(c)) => Some((g, c)),
        _ => None,
    };
    Ok((ok, iterations))
}

/// The many-step comparison of a DFSPH scene whose solves run a fixed number of iterations:
/// the GPU against the f64 CPU path after `steps` steps, with each tolerance at least
/// [`F32_FLOOR`] times the error of the CPU's own f32 path against the same reference (the
/// iterative solve turns rounding into velocity changes of the size of the flow's own, which
/// the f32 path measures for this scene); whether it passed.
fn compare_pinned(scene: &Scene, steps: u64) -> anyhow::Result<bool> {
    let mut gpu = open(scene, &BackendChoice::gpu())?.into_backend();
    let mut f32_path = open(scene, &BackendChoice::cpu(Precision::F32))?.into_backend();
    let mut reference = open(scene, &BackendChoice::cpu(Precision::F64))?.into_backend();
    let read = [step_and_read(gpu.as_mut(), steps)?, step_and_read(f32_path.as_mut(), steps)?, step_and_read(reference.as_mut(), steps)?];
    let done = [gpu.steps_done(), f32_path.steps_done(), reference.steps_done()];
    anyhow::ensure!(done[0] == done[2] && done[1] == done[2], "the paths stopped at different steps (gpu {}, cpu f32 {}, cpu f64 {})", done[0], done[1], done[2]);
    let params = scene.params();
    let tol = many_steps(&params);
    let judge = |k: usize| compare(&params, done[2], &tol, (&read[k].0, &read[k].1), (&read[2].0, &read[2].1));
    let (mut c, floor) = (judge(0), judge(1));
    c.widen_to(&floor, F32_FLOOR);
    print!("{}", c.table());
    println!("  (tolerances at least {F32_FLOOR} times the cpu f32 path's own errors against cpu f64)");
    Ok(c.passed())
}

/// Prints the two paths' iterations over `steps` steps and whether they agree within
/// [`ITERATION_TOLERANCE`].
fn iterations_agree(gpu: &IterationStats, cpu: &IterationStats, steps: u64) -> bool {
    let mut ok = true;
    println!("iterations per step over {steps} steps:\n  {:<16} {:>8} {:>8} {:>9}  result", "solve", "gpu", "cpu", "tolerance");
    for (name, g, c) in [("constant density", gpu.pressure, cpu.pressure), ("divergence", gpu.divergence, cpu.divergence)] {
        let tolerance = (ITERATION_TOLERANCE * c.total as f64).max(3.0);
        let agree = g.total.abs_diff(c.total) as f64 <= tolerance;
        ok &= agree;
        println!(
            "  {:<16} {:>8.2} {:>8.2} {:>9.2}  {}",
            name,
            g.total as f64 / steps as f64,
            c.total as f64 / steps as f64,
            tolerance / steps as f64,
            if agree { "ok" } else { "FAIL" }
        );
    }
    ok
}

/// `scene` with each DFSPH solve held at the iterations per step the reference needed on
/// average over `steps` steps, rounded up (and within the scene's own bounds).
fn with_fixed_iterations(scene: &Scene, reference: &IterationStats, steps: u64) -> Scene {
    let mut pinned = scene.clone();
    let d = &mut pinned.physics.dfsph;
    let fixed = |total: u64, min: u32, max: u32| (total.div_ceil(steps) as u32).clamp(min.max(1), max.max(1));
    let pressure = fixed(reference.pressure.total, d.min_iterations, d.max_iterations);
    let divergence = fixed(reference.divergence.total, d.min_divergence_iterations, d.max_divergence_iterations);
    (d.min_iterations, d.max_iterations) = (pressure, pressure);
    (d.min_divergence_iterations, d.max_divergence_iterations) = (divergence, divergence);
    pinned
}
