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
    /// Open a window that runs a scene on the GPU and draws every frame (orbit camera, keys).
    View(ViewArgs),
    /// Measure speed against accuracy: one scene under many settings against a reference run.
    Tradeoff(crate::tradeoff::TradeoffArgs),
    /// Run the validation cases against measurements and exact solutions; exit code 1 when one fails.
    Validate(crate::validate::ValidateArgs),
    /// Time each compute stage of the GPU step; bandwidth, interactions/s and memory per particle.
    Profile(crate::profile::ProfileArgs),
}

#[derive(Args, Debug, Clone)]
pub struct ViewArgs {
    /// A built-in scene name or a path to a scene TOML file.
    #[arg(default_value = "dam_break")]
    pub scene: String,
    /// Refine or coarsen the scene to about N fluid particles.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub particles: Option<u64>,
    /// Simulation steps per drawn frame (default: 1/60 s of simulated time, at most 64).
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..))]
    pub steps_per_frame: Option<u64>,
    #[command(flatten)]
    pub picture: PictureArgs,
    /// Save the last frame's picture (as presented) to this PNG file; needs --quit-after.
    #[arg(long, value_name = "FILE", requires = "quit_after")]
    pub screenshot: Option<PathBuf>,
    /// Close the window after N frames.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub quit_after: Option<u64>,
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
    #[command(flatten)]
    pub gpu: crate::gpu::workgroups::GpuTuning,
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
    /// Snapshot formats, repeated or comma-separated: csv, vtk (ParaView, with a .vtk.series
    /// index), ply (Blender, splashsurf).
    #[arg(long = "format", value_enum, value_delimiter = ',', default_values_t = [crate::export::SnapshotFormat::Csv])]
    pub formats: Vec<crate::export::SnapshotFormat>,
    /// No progress bar and no summary line (warnings and errors are still printed).
    #[arg(long, short)]
    pub quiet: bool,
    /// Replace the output directory if it exists and is not empty (otherwise that is refused).
    #[arg(long)]
    pub overwrite: bool,
    /// Write the full state to DIR/checkpoint.wgsph every K steps (0: never).
    #[arg(long, default_value_t = 0, value_name = "K")]
    pub checkpoint_every: u64,
    /// Continue the run in DIR from its checkpoint, to the end it was heading to (or for
    /// --steps N / --time T more); scene and settings come from the checkpoint.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["scene", "particles", "backend", "precision", "out", "snapshot_every", "check_every", "formats", "overwrite", "checkpoint_every", "surface_mesh_every", "surface_mesh_format", "frames"])]
    pub resume: Option<PathBuf>,
    /// Reconstruct the fluid surface (marching cubes over an SPH density field, splashsurf)
    /// every K steps into DIR/surface/step_NNNNNN.obj (0: never).
    #[arg(long, default_value_t = 0, value_name = "K")]
    pub surface_mesh_every: u64,
    /// File format of the surface meshes.
    #[arg(long, value_enum, default_value_t = crate::surface::MeshFormat::Obj)]
    pub surface_mesh_format: crate::surface::MeshFormat,
    /// Write rendered pictures DIR/frame_00000.png, ... (every --frame-every steps).
    #[arg(long, value_name = "DIR")]
    pub frames: Option<PathBuf>,
    /// A picture every K steps (default: about 100 per run).
    #[arg(long, value_name = "K", requires = "frames", value_parser = clap::value_parser!(u64).range(1..))]
    pub frame_every: Option<u64>,
    #[command(flatten)]
    pub picture: PictureArgs,
}

/// How pictures look (`run --frames` and `view`).
#[derive(Args, Debug, Clone)]
pub struct PictureArgs {
    /// Picture size WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x720", value_parser = crate::render::parse_resolution)]
    pub resolution: (u32, u32),
    #[arg(long, value_enum, default_value_t = crate::render::Style::Particles)]
    pub style: crate::render::Style,
    /// The field that colours the particles (viridis colour map).
    #[arg(long, value_enum, default_value_t = crate::render::ColorBy::Speed)]
    pub color_by: crate::render::ColorBy,
    /// A fixed colour range MIN:MAX (default: each picture's smallest to largest value).
    #[arg(long, value_name = "MIN:MAX", value_parser = crate::render::parse_range)]
    pub color_range: Option<(f32, f32)>,
    #[arg(long, value_enum, default_value_t = crate::render::Walls::Faint)]
    pub walls: crate::render::Walls,
}

impl PictureArgs {
    pub fn options(&self) -> crate::render::RenderOptions {
        crate::render::RenderOptions {
            width: self.resolution.0,
            height: self.resolution.1,
            style: self.style,
            color_by: self.color_by,
            range: self.color_range,
            walls: self.walls,
        }
    }
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
    let cli = Cli::parse();
    let quiet = matches!(&cli.command, Some(Command::Run(a)) if a.quiet);
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or(if quiet { "error" } else { "warn" })).init();
    let result = match cli.command.unwrap_or(Command::Run(RunArgs::default())) {
        Command::Run(args) => cmd_run(&args),
        Command::Compare(args) => cmd_compare(&args),
        Command::View(args) => cmd_view(&args),
        Command::Tradeoff(args) => crate::tradeoff::cmd_tradeoff(&args),
        Command::Validate(args) => crate::validate::cmd_validate(&args),
        Command::Profile(args) => crate::profile::cmd_profile(&args),
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
            // A scene or a setting beyond what the adapter allows is bad input too.
            let too_big = e.downcast_ref::<crate::gpu::memory::GpuMemoryError>().is_some()
                || matches!(e.downcast_ref::<crate::gpu::GpuError>(), Some(crate::gpu::GpuError::Limit { .. }));
            if too_big || e.downcast_ref::<SceneError>().is_some() || e.downcast_ref::<InputError>().is_some() {
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
pub fn make_backend(scene: &Scene, choice: BackendChoice, precision: Precision, gpu_options: crate::gpu::GpuOptions) -> anyhow::Result<Box<dyn Backend>> {
    let params = scene.params();
    let cpu = |precision| -> Box<dyn Backend> {
        let initial = scene.initial_state();
        match precision {
            Precision::F64 => Box::new(CpuSolver::<f64>::new(&params, &initial)),
            Precision::F32 => Box::new(CpuSolver::<f32>::new(&params, &initial)),
        }
    };
    // The GPU's limits are checked before the particles are created on the host.
    let gpu = |ctx: GpuContext| -> anyhow::Result<Box<dyn Backend>> {
        crate::gpu::memory::MemoryPlan::for_scene(scene).check(&ctx)?;
        Ok(Box::new(GpuSolver::with_options(ctx, &params, &scene.initial_state(), gpu_options)?))
    };
    match choice {
        BackendChoice::Cpu => Ok(cpu(precision)),
        BackendChoice::Gpu => gpu(GpuContext::new()?),
        BackendChoice::Auto => match GpuContext::new() {
            Ok(ctx) => gpu(ctx),
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

#[cfg(feature = "view")]
fn cmd_view(args: &ViewArgs) -> anyhow::Result<i32> {
    if args.picture.style == crate::render::Style::Mesh {
        return Err(InputError("--style mesh is for `wgsph run --frames` (the surface is reconstructed on the host, too slowly for a window); `wgsph view` takes --style particles or surface".into()).into());
    }
    let mut scene = load_scene(&args.scene)?;
    if let Some(n) = args.particles {
        scene = scene.with_fluid_particles(n);
        scene.validate(&crate::scene::SceneOrigin::Text).map_err(|e| InputError(format!("--particles {n}: {e}")))?;
    }
    let dt = scene.time.dt;
    let steps_per_frame = args.steps_per_frame.unwrap_or_else(|| ((1.0 / 60.0 / dt).ceil() as u64).clamp(1, 64));
    crate::view::view(
        scene,
        crate::view::ViewOptions {
            picture: args.picture.options(),
            steps_per_frame,
            screenshot: args.screenshot.clone(),
            quit_after: args.quit_after,
        },
    )
}

#[cfg(not(feature = "view"))]
fn cmd_view(_: &ViewArgs) -> anyhow::Result<i32> {
    Err(InputError("this wgsph was built without the `view` feature (a headless build); rebuild with default features for `wgsph view`".into()).into())
}

fn cmd_run(args: &RunArgs) -> anyhow::Result<i32> {
    if let Some(t) = args.time {
        if !(t.is_finite() && t >= 0.0) {
            return Err(InputError(format!("--time is {t}; must be a finite number >= 0")).into());
        }
    }
    if let Some(dir) = &args.resume {
        return crate::checkpoint::resume_run(dir, args);
    }
    let mut scene = load_scene(&args.scene)?;
    if let Some(n) = args.particles {
        scene = scene.with_fluid_particles(n);
        scene.validate(&crate::scene::SceneOrigin::Text).map_err(|e| InputError(format!("--particles {n}: {e}")))?;
    }
    let params = scene.params();
    let steps = args.steps.unwrap_or_else(|| steps_for_time(&params, args.time));
    if args.checkpoint_every > 0 && params.rebuild_every > 1 {
        return Err(InputError(format!(
            "--checkpoint-every {} needs time.neighbour_rebuild_every = 1 (the scene has {}): between rebuilds the state depends on the grid of the last rebuild, which a checkpoint does not hold",
            args.checkpoint_every, params.rebuild_every
        ))
        .into());
    }
    crate::rundir::prepare_out_dir(&args.out, args.overwrite)?;
    crate::rundir::write_scene_copy(&args.out, &scene)?;
    // With adaptive dt a run to a time has no step count known in advance.
    let end_time = (params.adaptive.is_some() && args.steps.is_none()).then(|| args.time.unwrap_or(params.end_time));
    let mut backend = make_backend(&scene, args.backend, args.precision, args.gpu.options())?;
    let opts = RunOptions {
        steps: if end_time.is_some() { u64::MAX / 4 } else { steps },
        out: args.out.clone(),
        snapshot_every: args.snapshot_every.unwrap_or_else(|| default_snapshot_every(steps)),
        check_every: args.check_every,
        progress: !args.quiet,
        formats: args.formats.clone(),
        checkpoint_every: args.checkpoint_every,
        resumed: None,
        frames: args.frames.as_ref().map(|dir| crate::run::FramesSpec {
            dir: dir.clone(),
            every: args.frame_every.unwrap_or((steps / 100).max(1)),
            options: args.picture.options(),
        }),
        end_time,
        surface_mesh_every: args.surface_mesh_every,
        surface_mesh_format: args.surface_mesh_format,
    };
    let summary = run(backend.as_mut(), &scene, &opts)?;
    if let (Some(dir), false) = (&args.frames, args.quiet) {
        println!("{} pictures in {}", summary.frames, dir.display());
    }
    report_run(&summary, &args.out, args.quiet)
}

/// Prints the end of a run (the summary line unless quiet; the failure, if any) and returns
/// its exit code.
pub fn report_run(summary: &crate::output::Summary, out: &std::path::Path, quiet: bool) -> anyhow::Result<i32> {
    if !quiet {
        println!("{}", summary_line(summary, out));
    }
    if let Some(f) = &summary.failure {
        eprintln!("error: the run stopped at {f}");
        if let Some(s) = &summary.last_snapshot {
            eprintln!("the last good snapshot is {s}; the summary is {}", out.join("summary.json").display());
        }
        return Ok(1);
    }
    Ok(0)
}
