//! `wgsph compare`: the GPU against the f64 CPU reference from the same state, every field.

use super::args::CompareArgs;
use crate::solver::compare::{many_steps, one_step, step_and_compare};
use crate::solver::{open, BackendChoice, Precision};

pub fn cmd_compare(args: &CompareArgs) -> anyhow::Result<i32> {
    let scene = super::args::load_scene(&args.scene, None, false)?;
    let mut gpu = open(&scene, &BackendChoice::gpu())?.into_backend();
    let mut cpu = open(&scene, &BackendChoice::cpu(Precision::F64))?.into_backend();
    println!("{}: {} fluid + {} wall particles; gpu {} against cpu f64", scene.name, gpu.fluid_count(), gpu.wall_count(), gpu.adapter());
    let mut ok = true;
    let mut done = 0;
    let (one, many) = (one_step(&scene.params()), many_steps(&scene.params()));
    for (target, tol) in [(1, &one), (args.steps.max(1), &many)] {
        if target <= done {
            continue;
        }
        let c = step_and_compare(gpu.as_mut(), cpu.as_mut(), target - done, tol)?;
        done = target;
        print!("{}", c.table());
        ok &= c.passed();
    }
    println!("{}", if ok { "compare: passed" } else { "compare: FAILED (an error is over its tolerance)" });
    Ok(if ok { 0 } else { 1 })
}

