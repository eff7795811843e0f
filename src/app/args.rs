//! The command line's arguments (clap): the commands, their flags, and how flags map to the
//! library's choices.

use super::errors::InputError;
use crate::io::snapshot::format::SnapshotFormat;
use crate::model::numbers::short3;
use crate::model::scene::{Scene, SceneOrigin};
use crate::io::surface::MeshFormat;
use crate::model::overrides::Override;
use crate::solver::gpu::skin::out_of_range;
use crate::solver::gpu::{GpuOptions, SolverLoop, WorkgroupSizes};
use crate::solver::{BackendChoice, Device, Precision};
use crate::viz::render;
use super::validate::case::Resolution;
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
    /// Run a scene and write snapshots and a summary. Without a command, wgsph runs its first
    /// run: the dam break at a small size, with pictures.
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
    Tradeoff(TradeoffArgs),
    /// Run the validation cases against measurements and exact solutions; exit code 1 when one fails.
    Validate(ValidateArgs),
    /// Time each compute stage of the GPU step; bandwidth, interactions/s and memory per particle.
    Profile(ProfileArgs),
    /// Time the peers' block workload on every path, against the recorded SPlisHSPlasH figure.
    Bench(BenchArgs),
}

#[derive(Args, Debug, Clone)]
pub struct ViewArgs {
    /// A built-in scene name, a path to a scene TOML file, or a SPlisHSPlasH JSON scene (`*.json`).
    #[arg(default_value = "dam_break")]
    pub scene: String,
    #[command(flatten)]
    pub overrides: SceneOverrides,
    /// Refine or coarsen the scene to about N fluid particles.
    #[arg(long, value_parser = at_least_one)]
    pub particles: Option<u64>,
    /// Simulation steps per drawn frame (default: 1/60 s of simulated time, at most 64).
    #[arg(long, value_parser = at_least_one)]
    pub steps_per_frame: Option<u64>,
    #[command(flatten)]
    pub picture: PictureArgs,
    /// Save the last frame's picture (as presented) to this PNG file; needs --quit-after.
    #[arg(long, value_name = "FILE", requires = "quit_after")]
    pub screenshot: Option<PathBuf>,
    /// Close the window after N frames.
    #[arg(long, value_name = "N", value_parser = at_least_one)]
    pub quit_after: Option<u64>,
}

/// `--backend`: which device runs the scene.
#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum)]
pub enum BackendArg {
    /// A hardware GPU when there is one, else the CPU path (a software GPU adapter runs
    /// slower than the CPU path); says which and why.
    Auto,
    Cpu,
    Gpu,
}

impl BackendArg {
    pub fn device(self) -> Device {
        match self {
            BackendArg::Auto => Device::Auto,
            BackendArg::Cpu => Device::Cpu,
            BackendArg::Gpu => Device::Gpu,
        }
    }
}

/// `--precision`: the CPU path's float type.
#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum)]
pub enum PrecisionArg {
    F64,
    F32,
}

impl PrecisionArg {
    pub fn precision(self) -> Precision {
        match self {
            PrecisionArg::F64 => Precision::F64,
            PrecisionArg::F32 => Precision::F32,
        }
    }
}

/// `--snapshot-every`: a number of steps, or a simulated time (`0.02s`).
#[derive(Copy, Clone, Debug, PartialEq)]
pub enum SnapshotInterval {
    Steps(u64),
    Seconds(f64),
}

impl std::str::FromStr for SnapshotInterval {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        let t = text.trim();
        let allowed = "allowed: a number of steps (e.g. 100; 0 for only the first and the last) or a simulated time in seconds (e.g. 0.02s)";
        if let Some(seconds) = t.strip_suffix('s') {
            return match seconds.trim().parse::<f64>() {
                Ok(v) if v.is_finite() && v > 0.0 => Ok(SnapshotInterval::Seconds(v)),
                _ => Err(format!("'{text}' is not a time > 0; {allowed}")),
            };
        }
        t.parse::<u64>().map(SnapshotInterval::Steps).map_err(|_| format!("'{text}' is not a whole number of steps; {allowed}"))
    }
}

/// `--set` and `--unset`: a scene changed from the command line, for every command that takes
/// a scene.
#[derive(Args, Debug, Clone, Default)]
pub struct SceneOverrides {
    /// Change a field of the scene: its dotted path in the scene file and a value written as
    /// in TOML (`--set time.dt=1e-4 --set physics.viscosity=0`); repeated; checked like the file.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub sets: Vec<Override>,
    /// Remove a field of the scene (back to its default) or an entry of a list (`boundary.2`),
    /// before the `--set`s: `--set physics.solver=dfsph --unset physics.speed_of_sound`; repeated.
    #[arg(long = "unset", value_name = "KEY", value_parser = Override::unset)]
    pub unsets: Vec<Override>,
}

impl SceneOverrides {
    /// The scene `name` (a built-in scene or a file) with these changes: the removals first,
    /// then the `--set`s, in order; checked once all have applied.
    pub fn scene(&self, name: &str) -> anyhow::Result<(Scene, Vec<String>)> {
        let (scene, notes) = Scene::load_noting(name)?;
        let origin = match Scene::builtin(name) {
            Some(_) => crate::model::scene::SceneOrigin::BuiltIn(name.to_string()),
            None => crate::model::scene::SceneOrigin::File(PathBuf::from(name)),
        };
        let all: Vec<Override> = self.unsets.iter().chain(&self.sets).cloned().collect();
        Ok((scene.with_overrides(&all, &origin)?, notes))
    }
}

#[derive(Args, Debug, Clone)]
pub struct RunArgs {
    /// A built-in scene name (see `wgsph scenes`), a path to a scene TOML file, or a SPlisHSPlasH JSON scene (`*.json`).
    #[arg(default_value = "dam_break")]
    pub scene: String,
    #[command(flatten)]
    pub overrides: SceneOverrides,
    /// Number of steps to run (default: up to the scene's end time).
    #[arg(long, conflicts_with = "time", value_parser = whole_number)]
    pub steps: Option<u64>,
    /// Simulated time to run, in seconds (`0.5` or `0.5s`).
    #[arg(long, value_parser = seconds)]
    pub time: Option<f64>,
    #[arg(long, value_enum, default_value_t = BackendArg::Auto)]
    pub backend: BackendArg,
    /// Float type of the CPU backend (default f64; the GPU always runs f32).
    #[arg(long, value_enum)]
    pub precision: Option<PrecisionArg>,
    #[command(flatten)]
    pub gpu: GpuTuning,
    /// Across GPU ranks (`mpirun -np N wgsph-mpi run ...`), read every held particle back after
    /// each step and upload them all before the next, instead of keeping them on the device
    /// with only the band next to each slab's faces crossing the bus: the path the resident
    /// steps are compared against (the same values, slower).
    #[arg(long)]
    pub full_exchange: bool,
    /// Output directory (default: a new one per run, out/SCENE-001, out/SCENE-002, ...).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write a snapshot every K steps, or at the first step reaching each multiple of a
    /// simulated time (`0.02s`) (default: about 50 per run; 0: only the first and last).
    #[arg(long, value_name = "K|Ts")]
    pub snapshot_every: Option<SnapshotInterval>,
    /// Refine or coarsen the scene to about N fluid particles (spacings, h and dt scale together).
    #[arg(long, value_parser = at_least_one)]
    pub particles: Option<u64>,
    /// Check for NaN and escaped particles every K steps.
    #[arg(long, default_value_t = 50, value_parser = at_least_one)]
    pub check_every: u64,
    /// Snapshot formats, repeated or comma-separated: csv, vtk (ParaView, with a .vtk.series
    /// index), ply (Blender, splashsurf).
    #[arg(long = "format", value_enum, value_delimiter = ',', default_values_t = [SnapshotFormat::Csv])]
    pub formats: Vec<SnapshotFormat>,
    /// No progress bar and no summary line (warnings and errors are still printed).
    #[arg(long, short)]
    pub quiet: bool,
    /// Replace the earlier wgsph run in --out (and --frames): only the files a run writes are
    /// replaced, and only in a directory a wgsph run wrote.
    #[arg(long, requires = "out")]
    pub overwrite: bool,
    /// Write the full state to DIR/checkpoint.wgsph every K steps (0: never).
    #[arg(long, default_value_t = 0, value_name = "K", value_parser = whole_number)]
    pub checkpoint_every: u64,
    /// Continue the run in DIR from its checkpoint, to the end it was heading to (or for
    /// --steps N / --time T more); scene and settings come from the checkpoint.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["scene", "sets", "unsets", "particles", "backend", "precision", "out", "snapshot_every", "check_every", "formats", "overwrite", "checkpoint_every", "surface_mesh_every", "surface_mesh_format", "frames", "full_exchange"])]
    pub resume: Option<PathBuf>,
    /// Reconstruct the fluid surface (marching cubes over an SPH density field, splashsurf)
    /// every K steps into DIR/surface/step_NNNNNN.obj (0: never).
    #[arg(long, default_value_t = 0, value_name = "K", value_parser = whole_number)]
    pub surface_mesh_every: u64,
    /// File format of the surface meshes (default obj; needs --surface-mesh-every).
    #[arg(long, value_enum)]
    pub surface_mesh_format: Option<MeshFormat>,
    /// Write rendered pictures DIR/frame_00000.png, ... (every --frame-every steps).
    #[arg(long, value_name = "DIR")]
    pub frames: Option<PathBuf>,
    /// A picture every K steps (default: about 100 per run).
    #[arg(long, value_name = "K", requires = "frames", value_parser = at_least_one)]
    pub frame_every: Option<u64>,
    #[command(flatten)]
    pub picture: PictureArgs,
}

/// How pictures look (`run --frames` and `view`).
#[derive(Args, Debug, Clone)]
pub struct PictureArgs {
    /// Picture size WIDTHxHEIGHT (default: 1280x720).
    #[arg(long, value_name = "WxH", value_parser = render::parse_resolution)]
    pub resolution: Option<(u32, u32)>,
    /// How the fluid is drawn (default: particles).
    #[arg(long, value_enum)]
    pub style: Option<render::Style>,
    /// The field that colours the particles, viridis colour map (default: speed).
    #[arg(long, value_enum)]
    pub color_by: Option<render::ColorBy>,
    /// A fixed colour range MIN:MAX (default: each picture's smallest to largest value).
    #[arg(long, value_name = "MIN:MAX", value_parser = render::parse_range)]
    pub color_range: Option<(f32, f32)>,
    /// How the walls are drawn (default: faint).
    #[arg(long, value_enum)]
    pub walls: Option<render::Walls>,
}

impl PictureArgs {
    pub fn options(&self) -> render::RenderOptions {
        let d = render::RenderOptions::default();
        let (width, height) = self.resolution.unwrap_or((d.width, d.height));
        render::RenderOptions {
            width,
            height,
            style: self.style.unwrap_or(d.style),
            color_by: self.color_by.unwrap_or(d.color_by),
            range: self.color_range,
            walls: self.walls.unwrap_or(d.walls),
        }
    }

    /// The picture flags given (for `run`, where they need `--frames`).
    pub fn given(&self) -> Vec<&'static str> {
        [
            (self.resolution.is_some(), "--resolution"),
            (self.style.is_some(), "--style"),
            (self.color_by.is_some(), "--color-by"),
            (self.color_range.is_some(), "--color-range"),
            (self.walls.is_some(), "--walls"),
        ]
        .into_iter()
        .filter_map(|(given, flag)| given.then_some(flag))
        .collect()
    }
}

impl RunArgs {
    /// The arguments of `wgsph run ARGS...`.
    pub fn parse_from<'a>(args: impl IntoIterator<Item = &'a str>) -> Self {
        match Cli::parse_from(["wgsph", "run"].into_iter().chain(args)).command {
            Some(Command::Run(args)) => args,
            _ => unreachable!("`wgsph run` parses to the run command"),
        }
    }
}

impl Default for RunArgs {
    fn default() -> Self {
        RunArgs::parse_from([])
    }
}

#[derive(Args, Debug, Clone)]
pub struct CompareArgs {
    /// A built-in scene name, a path to a scene TOML file, or a SPlisHSPlasH JSON scene (`*.json`).
    #[arg(default_value = "seed")]
    pub scene: String,
    #[command(flatten)]
    pub overrides: SceneOverrides,
    /// Steps of the second comparison (the first is after one step).
    #[arg(long, default_value_t = 100, value_parser = at_least_one)]
    pub steps: u64,
}


impl RunArgs {
    /// The backend these flags ask for.
    pub fn backend_choice(&self) -> BackendChoice {
        let precision = self.precision.map_or(Precision::F64, PrecisionArg::precision);
        BackendChoice { device: self.backend.device(), precision, gpu_options: GpuOptions { full_exchange: self.full_exchange, ..self.gpu.options() }, context: None, ranks: None }
    }
}

/// `--neighbour-skin`: a fraction of h in the range `skin::out_of_range` allows.
fn parse_skin(text: &str) -> Result<f64, String> {
    let skin: f64 = text.parse().map_err(|_| format!("'{text}' is not a number (a fraction of the kernel's support h, e.g. 0.1)"))?;
    match out_of_range(skin) {
        Some(why) => Err(why),
        None => Ok(skin),
    }
}

/// The GPU step's tuning options of `wgsph run` and `wgsph profile` (none changes a value but
/// `--neighbour-skin`, which changes the order of the sums).
#[derive(clap::Args, Debug, Clone, Default)]
pub struct GpuTuning {
    /// Run the forces and the integration as two passes, the particle state updated in place
    /// (the default: 48 bytes of state per fluid particle).
    #[arg(long, conflicts_with = "fused")]
    pub unfused: bool,
    /// Run the forces and the integration as one pass with fixed dt (one pass over the state
    /// less, but two copies of it: 16 bytes more per fluid particle).
    #[arg(long)]
    pub fused: bool,
    /// Walk the neighbour stencils of a subgroup's particles together in the density and the
    /// two-pass forces (the default where the adapter's subgroups have exactly 8 invocations, as
    /// a software adapter's do; an error elsewhere). The same values.
    #[arg(long, conflicts_with = "no_subgroup_tiles")]
    pub subgroup_tiles: bool,
    /// Give every particle its own walk of its stencil, even where subgroup tiles are possible.
    #[arg(long)]
    pub no_subgroup_tiles: bool,
    /// With subgroup tiles, walk them in the forces and DFSPH's solves too instead of the
    /// neighbour lists recorded once a step (lists: the default with the forces in a pass of
    /// their own; 4 bytes per slot of each fluid particle's list). The same values.
    #[arg(long)]
    pub no_neighbour_lists: bool,
    /// Keep the neighbour grid, the particles' order and the neighbour lists from one rebuild
    /// to the next, with cells and lists reaching h (1 + SKIN) (a fraction of the kernel's
    /// support, above 0 and at most 1; e.g. 0.1), and rebuild only once a particle has moved
    /// SKIN h, or two may have closed in by it: the same neighbours, summed in another order.
    /// Weakly compressible scenes on one device. Each step is then submitted alone (the host
    /// reads whether the next one rebuilds), so it cannot go with --steps-per-submit.
    #[arg(long, value_name = "SKIN", value_parser = parse_skin, conflicts_with = "steps_per_submit")]
    pub neighbour_skin: Option<f64>,
    /// Threads per workgroup: one size for every particle stage (`64`), or some stages' sizes
    /// (`density=64,forces=256`; stages: bin_count, bin_scatter, reorder, density, forces,
    /// integrate). Default 128.
    #[arg(long, value_name = "SIZES")]
    pub workgroup_size: Option<WorkgroupSizes>,
    /// Steps recorded into one command buffer (default 32).
    #[arg(long, value_name = "K", value_parser = at_least_one)]
    pub steps_per_submit: Option<u64>,
    /// How a DFSPH solve's loop ends on the GPU (the GPU makes iterations recorded past the
    /// end empty): `adaptive` (default: a first block as long as the last step's solve, then
    /// blocks of 4, the host asking after each), `indirect` (every iteration up to the limit
    /// recorded; no host round trip) or `readback:K` (blocks of K iterations).
    #[arg(long, value_name = "LOOP")]
    pub solver_loop: Option<SolverLoop>,
}

impl GpuTuning {
    /// The flags given, by name (a run on the CPU path has no use for any of them).
    pub fn given(&self) -> Vec<&'static str> {
        let flags = [
            (self.unfused, "--unfused"),
            (self.fused, "--fused"),
            (self.subgroup_tiles, "--subgroup-tiles"),
            (self.no_subgroup_tiles, "--no-subgroup-tiles"),
            (self.no_neighbour_lists, "--no-neighbour-lists"),
            (self.neighbour_skin.is_some(), "--neighbour-skin"),
            (self.workgroup_size.is_some(), "--workgroup-size"),
            (self.steps_per_submit.is_some(), "--steps-per-submit"),
            (self.solver_loop.is_some(), "--solver-loop"),
        ];
        flags.iter().filter(|(given, _)| *given).map(|&(_, name)| name).collect()
    }
    /// The solver options these flags ask for.
    pub fn options(&self) -> GpuOptions {
        GpuOptions {
            fuse_forces_and_integration: if self.fused { Some(true) } else if self.unfused { Some(false) } else { None },
            workgroup_sizes: self.workgroup_size.unwrap_or_default(),
            steps_per_submit: self.steps_per_submit.unwrap_or(0),
            single_cells: false,
            solver_loop: self.solver_loop.unwrap_or_default(),
            subgroup_tiles: if self.subgroup_tiles { Some(true) } else if self.no_subgroup_tiles { Some(false) } else { None },
            neighbour_lists: if self.no_neighbour_lists { Some(false) } else { None },
            neighbour_list_capacity: None,
            neighbour_skin: self.neighbour_skin,
            full_exchange: false,
        }
    }

    /// The flags that cannot apply to a scene with `params`: `--solver-loop` steers DFSPH's
    /// solves, which a weakly compressible scene does not have.
    pub fn check_scene(&self, params: &crate::model::params::Params) -> Result<(), InputError> {
        if let (Some(mode), None) = (self.solver_loop, &params.dfsph) {
            return Err(InputError(format!(
                "--solver-loop {mode} steers the GPU's DFSPH solves, and the scene uses the weakly compressible solver (physics.solver = \"wcsph\"): leave it out"
            )));
        }
        Ok(())
    }
}

/// `wgsph profile`.
#[derive(Args, Debug, Clone)]
pub struct ProfileArgs {
    /// A built-in scene name, a path to a scene TOML file, or a SPlisHSPlasH JSON scene (`*.json`).
    #[arg(default_value = "dam_break")]
    pub scene: String,
    #[command(flatten)]
    pub overrides: SceneOverrides,
    /// Refine or coarsen the scene to about N fluid particles.
    #[arg(long, value_parser = at_least_one)]
    pub particles: Option<u64>,
    /// Steps to time (after 2 warm-up steps).
    #[arg(long, default_value_t = 20, value_parser = at_least_one)]
    pub steps: u64,
    #[command(flatten)]
    pub tuning: GpuTuning,
    /// Visit the neighbour stencil as 27 single cells instead of 9 runs of 3 cells (to measure
    /// what the runs gain; each particle walks its own stencil, so not with subgroup tiles).
    #[arg(long, conflicts_with = "subgroup_tiles")]
    pub single_cells: bool,
    /// Also write the numbers to this JSON file.
    #[arg(long, value_name = "FILE.json")]
    pub out: Option<PathBuf>,
}

/// `wgsph tradeoff`.
#[derive(Args, Debug, Clone)]
pub struct TradeoffArgs {
    /// A built-in scene name, a path to a scene TOML file, or a SPlisHSPlasH JSON scene (`*.json`).
    #[arg(default_value = "dam_break")]
    pub scene: String,
    #[command(flatten)]
    pub overrides: SceneOverrides,
    /// Output directory for tradeoff.md and tradeoff.png.
    #[arg(long, default_value = "tradeoff")]
    pub out: PathBuf,
    /// Fluid particles of the base resolution (the scene is refined or coarsened to it).
    #[arg(long, default_value_t = 2000, value_parser = at_least_one)]
    pub particles: u64,
    /// Simulated time of every run (default 0.3 s: the dam-break surge before it reaches the
    /// far wall, after which the splash makes single trajectories chaotic).
    #[arg(long, default_value_t = 0.3, value_parser = seconds)]
    pub time: f64,
    /// Times at which the runs are compared.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u64).range(1..=1000))]
    pub samples: u64,
}

/// `wgsph validate`.
#[derive(Args, Debug, Clone)]
pub struct ValidateArgs {
    /// A case (hydrostatic, dam_break_martin_moyce, dam_break_koshizuka_oka, conservation, buchner_p1, hydrostatic_dfsph, dam_break_martin_moyce_dfsph, dam_break_koshizuka_oka_dfsph) or `all`.
    #[arg(default_value = "all")]
    pub case: String,
    /// Output directory: CASE.png, CASE.csv per case and validation.md.
    #[arg(long, default_value = "validation")]
    pub out: PathBuf,
    #[arg(long, value_enum, default_value_t = Resolution::Default)]
    pub resolution: Resolution,
    /// A hardware GPU when there is one, else the CPU path (see `wgsph run --help`).
    #[arg(long, value_enum, default_value_t = BackendArg::Auto)]
    pub backend: BackendArg,
}

/// A path `wgsph bench` times.
#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum)]
pub enum BenchPath {
    CpuF32,
    CpuF64,
    Gpu,
    /// The same block with DFSPH (steps of 1 ms).
    DfsphCpuF32,
    DfsphCpuF64,
    DfsphGpu,
}

impl BenchPath {
    /// The path's name, as on the command line.
    pub fn name(self) -> &'static str {
        match self {
            BenchPath::CpuF32 => "cpu-f32",
            BenchPath::CpuF64 => "cpu-f64",
            BenchPath::Gpu => "gpu",
            BenchPath::DfsphCpuF32 => "dfsph-cpu-f32",
            BenchPath::DfsphCpuF64 => "dfsph-cpu-f64",
            BenchPath::DfsphGpu => "dfsph-gpu",
        }
    }
}

/// `wgsph bench`.
#[derive(Args, Debug, Clone)]
pub struct BenchArgs {
    /// n^3 fluid particles (the peers were measured at 20, 30 and 40).
    #[arg(long, default_value_t = 30, value_parser = clap::value_parser!(u32).range(2..=400))]
    pub n: u32,
    /// Steps to time (after one warm-up step).
    #[arg(long, default_value_t = 200, value_parser = at_least_one)]
    pub steps: u64,
    /// The paths to time, comma-separated.
    #[arg(long, value_enum, value_delimiter = ',', default_values_t = [BenchPath::CpuF32, BenchPath::CpuF64, BenchPath::Gpu, BenchPath::DfsphCpuF32, BenchPath::DfsphGpu])]
    pub paths: Vec<BenchPath>,
    /// Threads of the CPU paths (default: every core).
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..))]
    pub threads: Option<u16>,
    /// The GPU path on every adapter with compute shaders, not only the one a run would choose.
    #[arg(long)]
    pub every_adapter: bool,
    /// How the dfsph-gpu path ends a solve's loop: `adaptive` (default), `indirect` or
    /// `readback:K` (see `wgsph run --help`), to measure one against another.
    #[arg(long, value_name = "LOOP")]
    pub solver_loop: Option<SolverLoop>,
    /// Give every particle its own walk of its stencil on the GPU paths, even where subgroup
    /// tiles are possible (to measure what the tiles gain; see `wgsph run --help`).
    #[arg(long)]
    pub no_subgroup_tiles: bool,
    /// Walk the subgroup tiles in the forces too, without neighbour lists (to measure what the
    /// lists gain; see `wgsph run --help`).
    #[arg(long)]
    pub no_neighbour_lists: bool,
    /// The gpu path with a neighbour skin of SKIN h (see `wgsph run --help`).
    #[arg(long, value_name = "SKIN", value_parser = parse_skin)]
    pub neighbour_skin: Option<f64>,
    /// Also write the figures to this JSON file.
    #[arg(long, value_name = "FILE.json")]
    pub out: Option<PathBuf>,
}

/// The scene a command runs: `SCENE` loaded, at `--particles N` where given, with a warning
/// line on stderr for each fluid block that its particle lattice does not fill exactly (unless
/// `quiet`).
pub fn load_scene(name: &str, overrides: &SceneOverrides, particles: Option<u64>, quiet: bool) -> anyhow::Result<Scene> {
    let (scene, warnings) = load_scene_warning(name, overrides, particles)?;
    if !quiet {
        print_warnings(&warnings);
    }
    Ok(scene)
}

/// [`load_scene`], with its warnings for the caller to print: the notes of an import (a
/// setting taken as the nearest wgsph has), then the lattice's ([`lattice_warnings`]).
pub fn load_scene_warning(name: &str, overrides: &SceneOverrides, particles: Option<u64>) -> anyhow::Result<(Scene, Vec<String>)> {
    let (mut scene, mut warnings) = overrides.scene(name)?;
    let origin = match Scene::builtin(name) {
        Some(_) => SceneOrigin::BuiltIn(name.to_string()),
        None => SceneOrigin::File(name.into()),
    };
    if let Some(n) = particles {
        scene = at_particles(&scene, n, &origin)?;
    }
    check_force_probe_boxes(&scene, &origin)?;
    warnings.extend(lattice_warnings(&scene));
    Ok((scene, warnings))
}

/// A force probe whose box (`min`, `max`) holds none of its boundary's wall particles would
/// read zero for the whole run: refused, naming the box and where the walls lie. (The walls
/// are made here only for a scene that has such a box.)
fn check_force_probe_boxes(scene: &Scene, origin: &SceneOrigin) -> Result<(), InputError> {
    if !scene.probe.iter().any(|p| p.min.is_some() || p.max.is_some()) {
        return Ok(());
    }
    let params = scene.params();
    let initial = scene.initial_state();
    for (k, p) in params.probes.probes.iter().enumerate() {
        let crate::model::probes::ProbeGeometry::Force { boundary, min, max, .. } = &p.geometry else { continue };
        let walls: Vec<[f64; 3]> = initial.wall_positions.iter().zip(&initial.wall_boundaries).filter(|(_, &b)| b as usize == *boundary).map(|(x, _)| *x).collect();
        if walls.is_empty() || walls.iter().any(|&x| p.takes_wall(*boundary, x)) {
            continue;
        }
        let (lo, hi) = walls.iter().fold(([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]), |(lo, hi), x| {
            (std::array::from_fn(|a| lo[a].min(x[a])), std::array::from_fn(|a| hi[a].max(x[a])))
        });
        let i = scene.probe.iter().position(|s| s.name == p.name).unwrap_or(k);
        return Err(InputError(format!(
            "{origin}: probe[{i}] ('{}'): the box min = {} .. max = {} holds none of boundary[{boundary}]'s wall particles, which lie within {} .. {}; the probe would read no force: make the box enclose part of the walls",
            p.name,
            short3(*min),
            short3(*max),
            short3(lo),
            short3(hi)
        )));
    }
    Ok(())
}

/// Each warning on its own line of stderr.
pub fn print_warnings(warnings: &[String]) {
    for line in warnings {
        eprintln!("warning: {line}");
    }
}

/// `scene` at about `n` fluid particles (`--particles N`): refused, naming the fewest the scene
/// allows, where that is too coarse.
pub fn at_particles(scene: &Scene, n: u64, origin: &SceneOrigin) -> anyhow::Result<Scene> {
    let scene = scene.at_fluid_particles(n).map_err(|e| InputError(format!("--particles {n}: {e}")))?;
    scene.validate(origin).map_err(|e| InputError(format!("--particles {n}: {e}")))?;
    Ok(scene)
}

/// A warning for each fluid block of `scene` that its particle lattice does not fill exactly,
/// one when the lattice does not start at its rest density, and one for each setting the scene
/// leaves unused ([`Scene::unused_settings`]).
pub fn lattice_warnings(scene: &Scene) -> Vec<String> {
    scene.lattice_changes().into_iter().chain(scene.rest_density_warning()).chain(scene.unused_settings()).collect()
}

/// A count of 0 or more (steps, intervals where 0 is never): Rust's own parse error ("invalid
/// digit found in string") says nothing of what is allowed.
fn whole_number(text: &str) -> Result<u64, String> {
    text.trim().parse::<u64>().map_err(|_| format!("'{text}' is not a whole number of 0 or more"))
}

/// A simulated time in seconds, written as a number or with the unit (`0.5`, `0.5s`), as
/// `--snapshot-every` takes its interval; its range is checked where it is used.
fn seconds(text: &str) -> Result<f64, String> {
    let t = text.trim();
    t.strip_suffix('s').unwrap_or(t).trim().parse::<f64>().map_err(|_| format!("'{text}' is not a time in seconds (a number, with or without s: 0.5 or 0.5s)"))
}

/// A count of at least 1 (steps, particles, intervals): clap's own range check names the type's
/// largest value as the bound, which says nothing to a user.
fn at_least_one(text: &str) -> Result<u64, String> {
    match text.trim().parse::<u64>() {
        Ok(n) if n >= 1 => Ok(n),
        Ok(_) => Err("0 is not allowed: give a whole number of at least 1".into()),
        Err(_) => Err(format!("'{text}' is not a whole number of at least 1")),
    }
}
