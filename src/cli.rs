//! The `wgsph` command line.

use crate::cpu::CpuSolver;
use crate::gpu::{GpuContext, GpuSolver};
use crate::run::{default_snapshot_every, run, steps_for_time, summary_line, RunOptions};
use crate::scene::{Scene, SceneError, BUILTIN_SCENES};
use crate::sim::Backend;
use clap::{Args, Parser, Subcommand, ValueEnum};
use std::path::PathBuf;

#[derive(Parser, Debug)]
#[command(name = "wgsph", version, about = "SPH fluid simulation on the GPU (WGSL compute through wgpu) with a CPU reference")]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Run a scene and write snapshots and a summary (the default command).
    Run(RunArgs),
    /// List the built-in scenes.
    Scenes,
    /// List the GPU adapters with their backend, type and the limits that matter.
    Adapters,
    /// Run the GPU and the f64 CPU reference from the same state and compare every field.
    Compare(CompareArgs),
    /// Run the validation cases against measurements and exact solutions; exit code 1 when one fails.
    Validate(crate::validate::ValidateArgs),
}

#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum)]
pub enum BackendChoice {
    /// The GPU when an adapter exists, else the CPU with a warning.
    Auto,
    Cpu,
    Gpu,
}

#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum)]
pub enum Precision {
    F64,
    F32,
}

#[derive(Args, Debug, Clone)]
pub struct RunArgs {
    /// A built-in scene name (see `wgsph scenes`) or a path to a scene TOML file.
    #[arg(default_value = "seed")]
    pub scene: String,
    /// Number of steps to run (default: up to the scene's end time).
    #[arg(long, conflicts_with = "time")]
    pub steps: Option<u64>,
    /// Simulated time to run, in the scene's time unit.
    #[arg(long)]
    pub time: Option<f64>,
    #[arg(long, value_enum, default_value_t = BackendChoice::Auto)]
    pub backend: BackendChoice,
    /// Float type of the CPU backend (the GPU always runs f32).
    #[arg(long, value_enum, default_value_t = Precision::F64)]
    pub precision: Precision,
    /// Output directory.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Write a snapshot every K steps (default: about 50 per run; 0: only the first and last).
    #[arg(long)]
    pub snapshot_every: Option<u64>,
    /// Refine or coarsen the scene to about N fluid particles (spacings, h and dt scale together).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub particles: Option<u64>,
    /// Check for NaN and escaped particles every K steps.
    #[arg(long, default_value_t = 50, value_parser = clap::value_parser!(u64).range(1..))]
    pub check_every: u64,
}

impl Default for RunArgs {
    fn default() -> Self {
        match Cli::parse_from(["wgsph", "run"]).command {
            Some(Command::Run(args)) => args,
            _ => unreachable!("`wgsph run` parses to the run command"),
        }
    }
}

#[derive(Args, Debug, Clone)]
pub struct CompareArgs {
    /// A built-in scene name or a path to a scene TOML file.
    #[arg(default_value = "seed")]
    pub scene: String,
    /// Steps of the second comparison (the first is after one step).
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u64).range(1..))]
    pub steps: u64,
}

/// An error in what the user gave: exit code 2.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct InputError(pub String);

/// Parses the command line, runs it and returns the process exit code:
/// 0 success, 1 a run that went bad or a failed check, 2 bad input.
pub fn main() -> i32 {
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn")).init();
    let cli = Cli::parse();
    let result = match cli.command.unwrap_or(Command::Run(RunArgs::default())) {
        Command::Run(args) => cmd_run(&args),
        Command::Compare(args) => cmd_compare(&args),
        Command::Validate(args) => crate::validate::cmd_validate(&args),
        Command::Adapters => {
            let lines = crate::gpu::device::describe_adapters();
            if lines.is_empty() {
                println!("no GPU adapter found");
            }
            for l in lines {
                println!("{l}");
            }
            Ok(0)
        }
        Command::Scenes => {
            for (name, description, _) in BUILTIN_SCENES {
                println!("{name:<12} {description}");
            }
            Ok(0)
        }
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            if e.downcast_ref::<SceneError>().is_some() || e.downcast_ref::<InputError>().is_some() {
                2
            } else {
                1
            }
        }
    }
}

pub fn load_scene(name: &str) -> anyhow::Result<Scene> {
    Ok(Scene::load(name)?)
}

/// Builds the backend a run asked for.
pub fn make_backend(scene: &Scene, choice: BackendChoice, precision: Precision) -> anyhow::Result<Box<dyn Backend>> {
    let params = scene.params();
    let initial = scene.initial_state();
    let cpu = |precision| -> Box<dyn Backend> {
        match precision {
            Precision::F64 => Box::new(CpuSolver::<f64>::new(&params, &initial)),
            Precision::F32 => Box::new(CpuSolver::<f32>::new(&params, &initial)),
        }
    };
    match choice {
        BackendChoice::Cpu => Ok(cpu(precision)),
        BackendChoice::Gpu => Ok(Box::new(GpuSolver::new(GpuContext::new()?, &params, &initial)?)),
        BackendChoice::Auto => match GpuContext::new() {
            Ok(ctx) => Ok(Box::new(GpuSolver::new(ctx, &params, &initial)?)),
            Err(e) => {
                eprintln!("warning: {e:#}; falling back to the cpu backend");
                Ok(cpu(precision))
            }
        },
    }
}

fn cmd_compare(args: &CompareArgs) -> anyhow::Result<i32> {
    let scene = load_scene(&args.scene)?;
    let params = scene.params();
    let initial = scene.initial_state();
    let mut gpu = GpuSolver::new(GpuContext::new()?, &params, &initial)?;
    let mut cpu = CpuSolver::<f64>::new(&params, &initial);
    println!(
        "{}: {} fluid + {} wall particles; gpu {} against cpu f64",
        scene.name,
        initial.fluid_positions.len(),
        initial.wall_positions.len(),
        gpu.adapter()
    );
    let mut ok = true;
    let mut done = 0;
    for (target, tol) in [(1, &crate::compare::ONE_STEP), (args.steps.max(1), &crate::compare::MANY_STEPS)] {
        if target <= done {
            continue;
        }
        let c = crate::compare::step_and_compare(&mut gpu, &mut cpu, target - done, tol)?;
        done = target;
        print!("{}", c.table());
        ok &= c.passed();
    }
    println!("{}", if ok { "compare: passed" } else { "compare: FAILED (an error is over its tolerance)" });
    Ok(if ok { 0 } else { 1 })
}

fn cmd_run(args: &RunArgs) -> anyhow::Result<i32> {
    if let Some(t) = args.time {
        if !(t.is_finite() && t >= 0.0) {
            return Err(InputError(format!("--time is {t}; must be a finite number >= 0")).into());
        }
    }
    let mut scene = load_scene(&args.scene)?;
    if let Some(n) = args.particles {
        scene = scene.with_fluid_particles(n);
        scene.validate(&crate::scene::SceneOrigin::Text).map_err(|e| InputError(format!("--particles {n}: {e}")))?;
    }
    let params = scene.params();
    let steps = args.steps.unwrap_or_else(|| steps_for_time(&params, args.time));
    let mut backend = make_backend(&scene, args.backend, args.precision)?;
    let opts = RunOptions {
        steps,
        out: args.out.clone(),
        snapshot_every: args.snapshot_every.unwrap_or_else(|| default_snapshot_every(steps)),
        check_every: args.check_every,
        progress: true,
    };
    let summary = run(backend.as_mut(), &scene, &opts)?;
    println!("{}", summary_line(&summary, &args.out));
    if let Some(f) = &summary.failure {
        eprintln!("error: the run stopped at {f}");
        if let Some(s) = &summary.last_snapshot {
            eprintln!("the last good snapshot is {s}; the summary is {}", args.out.join("summary.json").display());
        }
        return Ok(1);
    }
    Ok(0)
}
