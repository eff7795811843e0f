//! `wgsph` without a command: the first run. The built-in dam break (a water column twice as
//! tall as wide collapsing in a tank, as in Martin & Moyce's experiment) at a size that
//! finishes in well under a minute on a laptop's CPU, with a few pictures, into a new numbered
//! directory, so that it can be run again and again. It is an ordinary `wgsph run`, and says
//! which one.

use super::args::RunArgs;
use super::run::{cmd_run, steps_for_time};
use crate::io::rundir::numbered_run_dir;
use crate::model::scene::Scene;
use std::path::Path;

/// Fluid particles of the first run: the dam break's 0.4 x 0.8 x 0.1 m column as a 16 x 32 x 4
/// lattice of spacing 0.025 m, which fills the column exactly (another count is rounded to the
/// nearest layers, with a warning line that a first run should not need).
pub const FIRST_RUN_PARTICLES: u64 = 2048;
/// Pictures of the first run: the start, the end, and evenly between.
pub const FIRST_RUN_PICTURES: u64 = 7;

/// The first run's `wgsph run` arguments, writing into `out`; `pictures`: whether there is an
/// adapter to draw them with.
pub fn first_run_args(out: &Path, pictures: bool) -> Vec<String> {
    let scene = Scene::builtin("dam_break").expect("dam_break is built in").with_fluid_particles(FIRST_RUN_PARTICLES);
    let steps = steps_for_time(&scene.params(), None);
    let every = steps.div_ceil(FIRST_RUN_PICTURES - 1).max(1);
    let mut args: Vec<String> = ["dam_break", "--particles", &FIRST_RUN_PARTICLES.to_string(), "--out", &out.display().to_string()].map(String::from).to_vec();
    if pictures {
        let frames = out.join("frames").display().to_string();
        args.extend(["--frames", &frames, "--frame-every", &every.to_string(), "--style", "surface", "--resolution", "960x540"].map(String::from));
    }
    args
}

/// `wgsph` without a command.
pub fn cmd_first_run() -> anyhow::Result<i32> {
    let out = numbered_run_dir(Path::new("out"), "dam_break");
    // Pictures are drawn on a GPU adapter; a software one serves.
    let pictures = !crate::solver::gpu::device::compute_adapters().is_empty();
    let args = first_run_args(&out, pictures);
    println!(
        "wgsph: no command given, so this is the first run: the dam break, a water column collapsing in a tank, for 1.5 s{}",
        if pictures { ", with pictures" } else { "" }
    );
    println!("  (the same as `wgsph run {}`; `wgsph --help` lists the commands)", args.join(" "));
    if !pictures {
        println!("  no GPU adapter (not even a software one such as llvmpipe) to draw pictures with: the run writes none");
    }
    cmd_run(&RunArgs::parse_from(args.iter().map(String::as_str)), None)
}
