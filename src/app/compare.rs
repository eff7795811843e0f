//! `wgsph compare`: the GPU against the f64 CPU reference from the same state, every field.
//!
//! A DFSPH scene is compared twice. Its solves stop at a tolerance, and a solve whose error ends
//! within rounding of it stops one iteration earlier on one path than on the other: the two
//! paths then differ by a Jacobi step of the size of the tolerance, which the flow amplifies
//! over the steps far beyond rounding (docs/dfsph.md, "GPU against the CPU"). So the run as the
//! scene sets it is judged after one step and by its iteration counts, and the many-step
//! comparison of the state is made again with every solve held at a fixed number of
//! iterations on the GPU, the f64 and the f32 paths, where only the arithmetic differs.

use super::args::CompareArgs;
use crate::model::scene::Scene;
use crate::model::state::IterationStats;
use crate::solver::backend::{diagnose_failure, Backend};
use crate::solver::compare::{compare, many_steps, one_step, step_and_read};
use crate::solver::{open, BackendChoice, Precision};

/// Iterations per step of the two paths' solves may differ by this fraction of the
/// reference's (and by 3 iterations over the run): a solve stops one iteration apart now and then.
pub const ITERATION_TOLERANCE: f64 = 0.05;

/// Every comparison's tolerances are at least this many times the CPU's f32 path's errors
/// against its f64 path (what rounding alone does in that scene).
pub const F32_FLOOR: f64 = 3.0;

pub fn cmd_compare(args: &CompareArgs) -> anyhow::Result<i32> {
    let scene = super::args::load_scene(&args.scene, &args.overrides, None, false)?;
    let steps = args.steps.max(1);
    let dfsph = scene.physics.solver == crate::model::scene::PressureSolver::Dfsph;
    let (mut ok, iterations) = compare_runs(&scene, steps, !dfsph)?;
    if let Some((gpu, cpu)) = iterations {
        ok &= iterations_agree(&gpu, &cpu, steps, scene.physics.dfsph.divergence_solve);
        ok &= compare_held(&scene, &cpu, steps)?;
    }
    println!("{}", if ok { "compare: passed" } else { "compare: FAILED (an error is over its tolerance)" });
    Ok(if ok { 0 } else { 1 })
}

/// Where any of `paths` (a name and a backend of `scene`, the reference last) went bad: each
/// such path and its step, and (where `diagnosed`) why, from the last of them (the reference
/// where it went bad); None where none did.
fn went_bad(scene: &Scene, paths: &mut [(&str, &mut dyn Backend)], diagnosed: bool) -> anyhow::Result<Option<String>> {
    let mut bad = Vec::new();
    for (k, (name, backend)) in paths.iter_mut().enumerate() {
        if let Some(step) = backend.health()?.bad_step.map(|b| b.step) {
            bad.push((k, format!("on the {name} path at step {step}")));
        }
    }
    let Some(&(last, _)) = bad.last() else { return Ok(None) };
    let mut text = bad.iter().map(|b| b.1.as_str()).collect::<Vec<_>>().join(", ");
    if diagnosed {
        let (name, backend) = &mut paths[last];
        text += &format!(" ({name}: {})", diagnose_failure(&mut **backend, scene)?);
    }
    Ok(Some(text))
}

/// Runs `scene` on the GPU and on the f64 CPU path from the same state and prints the
/// comparison after one step and after `steps`; a tolerance that the CPU's own f32 path's error
/// is over (rounding alone, as in a strong surface tension's cohesion sums, whose terms cancel)
/// is raised to [`F32_FLOOR`] times that error; whether every judged comparison passed, and
/// for DFSPH the two paths' iterations (GPU, CPU). `judge_many`: whether the comparison after
/// `steps` counts (otherwise it is printed as information). A run that goes bad on either path
/// is an error that says where and why: the state after it is not the scene's flow.
fn compare_runs(scene: &Scene, steps: u64, judge_many: bool) -> anyhow::Result<(bool, Option<(IterationStats, IterationStats)>)> {
    let mut gpu = open(scene, &BackendChoice::gpu())?.into_backend();
    let mut cpu = open(scene, &BackendChoice::cpu(Precision::F64))?.into_backend();
    // The CPU's f32 path measures what f32 rounding alone does in this scene.
    let mut f32_path = open(scene, &BackendChoice::cpu(Precision::F32))?.into_backend();
    println!("{}: {} fluid + {} wall particles; gpu {} against cpu f64", scene.name, gpu.fluid_count(), gpu.wall_count(), gpu.adapter());
    let params = scene.params();
    let mut ok = true;
    let mut done = 0;
    let (one, many) = (one_step(&params), many_steps(&params));
    for (target, tol, judged) in [(1, &one, true), (steps, &many, judge_many)] {
        if target <= done {
            continue;
        }
        let (tf, ts) = step_and_read(gpu.as_mut(), target - done)?;
        let (rf, rs) = step_and_read(cpu.as_mut(), target - done)?;
        let (ff, fs) = step_and_read(f32_path.as_mut(), target - done)?;
        if let Some(bad) = went_bad(scene, &mut [("gpu", gpu.as_mut()), ("cpu f32", f32_path.as_mut()), ("cpu f64", cpu.as_mut())], true)? {
            anyhow::bail!("{} went bad within {target} steps, {bad}; there is no flow to compare after it: compare fewer steps (--steps) or a scene that holds", scene.name);
        }
        done = target;
        let mut c = compare(&params, done, tol, (&tf, &ts), (&rf, &rs));
        let widened = c.widen_to(&compare(&params, done, tol, (&ff, &fs), (&rf, &rs)), F32_FLOOR, true);
        print!("{}", c.table_as(judged));
        if !widened.is_empty() {
            println!(
                "  (tolerance of {} raised to {F32_FLOOR} times the cpu f32 path's own error against cpu f64: f32 rounding alone errs more than the usual tolerance in this scene)",
                widened.join(", ")
            );
        }
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

/// DFSPH's many-step comparison with every solve held at a fixed number of iterations on every
/// path: first the iterations per step the free reference run (`reference`, over `steps`
/// steps) needed on average, rounded up; where that leaves a solve too short and the run goes
/// bad, twice as many, up to the most any of its steps needed. Whether it passed.
fn compare_held(scene: &Scene, reference: &IterationStats, steps: u64) -> anyhow::Result<bool> {
    let d = &scene.physics.dfsph;
    let bounded = |n: u64, min: u32, max: u32| (n.min(u32::MAX as u64) as u32).clamp(min.max(1), max.max(1));
    let mut pressure = bounded(reference.pressure.total.div_ceil(steps), d.min_iterations, d.max_iterations);
    let mut divergence = bounded(reference.divergence.total.div_ceil(steps), d.min_divergence_iterations, d.max_divergence_iterations);
    let most = (bounded(reference.pressure.max as u64, d.min_iterations, d.max_iterations), bounded(reference.divergence.max as u64, d.min_divergence_iterations, d.max_divergence_iterations));
    loop {
        let mut held = scene.clone();
        let h = &mut held.physics.dfsph;
        (h.min_iterations, h.max_iterations, h.min_divergence_iterations, h.max_divergence_iterations) = (pressure, pressure, divergence, divergence);
        println!(
            "the same {steps} steps with every solve held at {pressure} constant-density{} iterations on every path:",
            if d.divergence_solve { format!(" and {divergence} divergence") } else { String::new() }
        );
        let last = (pressure, divergence) == most;
        match compare_pinned(&held, steps, last)? {
            Some(passed) => return Ok(passed),
            None => {
                (pressure, divergence) = ((2 * pressure).min(most.0), (2 * divergence).min(most.1));
                match d.divergence_solve {
                    true => println!("  (again with {pressure} constant-density and {divergence} divergence iterations)"),
                    false => println!("  (again with {pressure} constant-density iterations)"),
                }
            }
        }
    }
}

/// The many-step comparison of a DFSPH scene whose solves run a fixed number of iterations:
/// the GPU against the f64 CPU path after `steps` steps, with each tolerance at least
/// [`F32_FLOOR`] times the error of the CPU's own f32 path against the same reference (the
/// iterative solve turns rounding into velocity changes of the size of the flow's own, which
/// the f32 path measures for this scene); whether it passed, or None where a path went bad (an
/// error where `last`: no more iterations to give it).
fn compare_pinned(scene: &Scene, steps: u64, last: bool) -> anyhow::Result<Option<bool>> {
    let mut gpu = open(scene, &BackendChoice::gpu())?.into_backend();
    let mut f32_path = open(scene, &BackendChoice::cpu(Precision::F32))?.into_backend();
    let mut reference = open(scene, &BackendChoice::cpu(Precision::F64))?.into_backend();
    let read = [step_and_read(gpu.as_mut(), steps)?, step_and_read(f32_path.as_mut(), steps)?, step_and_read(reference.as_mut(), steps)?];
    if let Some(bad) = went_bad(scene, &mut [("gpu", gpu.as_mut()), ("cpu f32", f32_path.as_mut()), ("cpu f64", reference.as_mut())], last)? {
        anyhow::ensure!(!last, "held at the most iterations its steps needed, {} went bad {bad}", scene.name);
        println!("  went bad {bad}: the solves were held too short");
        return Ok(None);
    }
    let params = scene.params();
    let tol = many_steps(&params);
    let judge = |k: usize| compare(&params, steps, &tol, (&read[k].0, &read[k].1), (&read[2].0, &read[2].1));
    let (mut c, floor) = (judge(0), judge(1));
    c.widen_to(&floor, F32_FLOOR, false);
    print!("{}", c.table());
    println!("  (tolerances at least {F32_FLOOR} times the cpu f32 path's own errors against cpu f64)");
    Ok(Some(c.passed()))
}

/// Prints the two paths' iterations over `steps` steps and whether they agree within
/// [`ITERATION_TOLERANCE`] (the divergence solve's where the scene runs it).
fn iterations_agree(gpu: &IterationStats, cpu: &IterationStats, steps: u64, divergence_solve: bool) -> bool {
    let mut ok = true;
    println!("iterations per step over {steps} steps:\n  {:<16} {:>8} {:>8} {:>9}  result", "solve", "gpu", "cpu", "tolerance");
    let solves = [("constant density", gpu.pressure, cpu.pressure), ("divergence", gpu.divergence, cpu.divergence)];
    for (name, g, c) in solves.into_iter().take(1 + divergence_solve as usize) {
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
