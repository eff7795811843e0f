//! The library entry point for programs that embed the simulator.
//!
//! A [`Simulation`] is built from a [`Scene`] (a file, a TOML string, or built in code) on the
//! GPU or the CPU, advanced with [`Simulation::step`] and read with
//! [`Simulation::snapshot`]. On the GPU, [`Simulation::device`], [`Simulation::queue`] and
//! [`Simulation::particle_buffers`] give access to the wgpu device and the particle buffers, so
//! a program can render the particles without copying them back to the host.
//!
//! ```
//! use wgsph::{Scene, Simulation};
//!
//! // A built-in scene at a low resolution, on the CPU (runs everywhere).
//! let scene = Scene::builtin("hydrostatic").unwrap().with_fluid_particles(300);
//! let mut sim = Simulation::cpu(scene)?;
//! sim.step(5)?;
//! let snapshot = sim.snapshot()?;
//! assert_eq!(snapshot.step, 5);
//! assert_eq!(snapshot.len(), sim.fluid_count());
//! assert!(sim.health()?.is_ok());
//! # Ok::<(), anyhow::Error>(())
//! ```

use super::cpu::exchange::InitialSource;
use super::cpu::CpuSolver;
use super::gpu::{GpuContext, GpuOptions, GpuSolver, ParticleBuffers};
use super::backend::Backend;
use super::communicator::Ranks;
use crate::model::check::{cpu_list_bytes_per_fluid_particle, host_memory_shortfall_with, CPU_BYTES_PER_PARTICLE};
use crate::model::initial::InitialState;
use crate::model::params::Params;
use crate::model::real::Real;
use crate::model::scene::{Scene, SceneError, SceneOrigin};
use crate::model::state::{Health, Snapshot};

/// Which device runs a scene.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Device {
    /// A hardware GPU when there is one, else the CPU path: a software adapter (llvmpipe,
    /// lavapipe, WARP) runs the same cores slower than the CPU path does. An adapter named
    /// with `WGPU_ADAPTER_NAME`, or a device given, is used whatever its kind.
    #[default]
    Auto,
    Cpu,
    Gpu,
}

/// Float type of the CPU path (the GPU always computes in f32).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Precision {
    #[default]
    F64,
    F32,
}

/// How to run a scene: the device, the CPU's float type, the GPU step's tuning and, optionally,
/// a GPU device the caller opened.
#[derive(Clone, Debug, Default)]
pub struct BackendChoice {
    pub device: Device,
    pub precision: Precision,
    pub gpu_options: GpuOptions,
    /// Run on this GPU device instead of choosing an adapter (`Device::Gpu` or `Auto`).
    pub context: Option<GpuContext>,
    /// This process's rank when one simulation runs across several (`None`, or one rank:
    /// the whole scene here). See docs/scale-out.md.
    pub ranks: Option<Ranks>,
}

impl BackendChoice {
    /// The CPU reference path in `precision`.
    pub fn cpu(precision: Precision) -> Self {
        BackendChoice { device: Device::Cpu, precision, ..Default::default() }
    }
    /// The GPU, on the adapter `wgsph run` would choose.
    pub fn gpu() -> Self {
        BackendChoice { device: Device::Gpu, ..Default::default() }
    }
    /// The GPU, on a device the caller opened.
    pub fn gpu_on(context: GpuContext) -> Self {
        BackendChoice { device: Device::Gpu, context: Some(context), ..Default::default() }
    }
    /// The same choice, as one rank of a simulation across ranks.
    pub fn on_ranks(mut self, ranks: Ranks) -> Self {
        self.ranks = Some(ranks);
        self
    }
    /// The same choice with the GPU step's tuning options.
    pub fn with_gpu_options(mut self, options: GpuOptions) -> Self {
        self.gpu_options = options;
        self
    }
}

/// The solver behind a [`Simulation`].
pub enum Solver {
    Gpu(Box<GpuSolver>),
    Cpu64(CpuSolver<f64>),
    Cpu32(CpuSolver<f32>),
}

/// A running simulation of one scene.
pub struct Simulation {
    scene: Scene,
    solver: Solver,
    /// Which backend runs it and why, in words.
    reason: String,
}

/// What `Device::Auto` takes: a GPU adapter, or the CPU path; with the reason in words.
enum AutoChoice {
    Gpu(GpuContext, String),
    Cpu(String),
}

fn auto_choice() -> AutoChoice {
    let by_name = std::env::var_os("WGPU_ADAPTER_NAME").is_some();
    let candidates = super::gpu::device::candidate_adapters();
    if candidates.is_empty() {
        return match super::gpu::device::choose_adapter() {
            Err(e) => AutoChoice::Cpu(format!("{e}")),
            Ok(_) => AutoChoice::Cpu("no GPU adapter with compute shaders".into()),
        };
    }
    // Best first: the first adapter that opens a device is taken, unless it is a software
    // renderer (then no hardware adapter opened, and the CPU path is faster on the same cores).
    let mut failures = Vec::new();
    for a in candidates {
        let info = a.get_info();
        let name = format!("{} ({:?})", info.name, info.backend);
        if info.device_type == wgpu::DeviceType::Cpu && !by_name {
            let mut why = format!(
                "the only GPU adapter that opens is the software renderer {name}, which runs slower than the CPU path on the same cores (--backend gpu runs on it)"
            );
            if !failures.is_empty() {
                why += &format!("; passed over: {}", failures.join("; "));
            }
            return AutoChoice::Cpu(why);
        }
        match GpuContext::from_adapter(a) {
            Ok(ctx) => {
                let mut why = if by_name { "chosen with WGPU_ADAPTER_NAME".to_string() } else { "a hardware adapter".to_string() };
                if !failures.is_empty() {
                    why += &format!("; passed over: {}", failures.join("; "));
                }
                return AutoChoice::Gpu(ctx, why);
            }
            Err(e) => failures.push(format!("{e:#}")),
        }
    }
    AutoChoice::Cpu(format!("no GPU adapter could open a device: {}", failures.join("; ")))
}

/// The device `Device::Auto` stands for on this machine, and why, in words (for commands
/// that open many backends and say once which).
pub fn auto_device() -> (Device, String) {
    match auto_choice() {
        AutoChoice::Gpu(ctx, why) => (Device::Gpu, format!("the GPU on {} ({:?}): {why}", ctx.info.name, ctx.info.backend)),
        AutoChoice::Cpu(why) => (Device::Cpu, why),
    }
}

/// The one builder: the scene (validated again, as code may have changed it) on the backend
/// `choice` names, from the scene's own initial particles. See [`open_with`].
pub fn open(scene: &Scene, choice: &BackendChoice) -> anyhow::Result<Simulation> {
    open_with(scene, None, choice)
}

/// The one builder, with the particles at t = 0 given (`None`: the scene's own). Every command,
/// test, bench and example builds its backend here, so the fallback rule and the memory checks
/// are the same everywhere: the GPU's [`super::gpu::memory::MemoryPlan`] is checked against the
/// adapter before any particle is created on the host, and the CPU's host memory against what
/// the machine has.
pub fn open_with(scene: &Scene, initial: Option<InitialState>, choice: &BackendChoice) -> anyhow::Result<Simulation> {
    scene.validate(&SceneOrigin::Text)?;
    let params = scene.params();
    if let Some(ranks) = choice.ranks.as_ref().filter(|r| r.comm.size() > 1) {
        return open_part(scene, &params, initial, choice, ranks);
    }
    let initial_of = |initial: Option<InitialState>| initial.unwrap_or_else(|| scene.initial_state());
    let gpu = |ctx: GpuContext, initial: Option<InitialState>| -> anyhow::Result<Solver> {
        super::gpu::memory::MemoryPlan::for_scene(scene).check(&ctx)?;
        Ok(Solver::Gpu(Box::new(GpuSolver::with_options(ctx, &params, &initial_of(initial), choice.gpu_options)?)))
    };
    let cpu = |initial: Option<InitialState>| -> anyhow::Result<Solver> {
        check_host_memory(scene, 1.0)?;
        let initial = initial_of(initial);
        Ok(match choice.precision {
            Precision::F64 => Solver::Cpu64(CpuSolver::new(&params, &initial)),
            Precision::F32 => Solver::Cpu32(CpuSolver::new(&params, &initial)),
        })
    };
    let context = || match &choice.context {
        Some(c) => Ok(c.clone()),
        None => GpuContext::new(),
    };
    let cpu_name = match choice.precision {
        Precision::F64 => "the CPU path in f64",
        Precision::F32 => "the CPU path in f32",
    };
    let (solver, reason) = match choice.device {
        Device::Cpu => (cpu(initial)?, format!("{cpu_name}, as asked")),
        Device::Gpu => {
            let ctx = context()?;
            let name = ctx.describe();
            (gpu(ctx, initial)?, format!("the GPU on {name}, as asked"))
        }
        Device::Auto => match &choice.context {
            Some(c) => (gpu(c.clone(), initial)?, format!("the GPU on {}, the device given", c.describe())),
            None => match auto_choice() {
                AutoChoice::Gpu(ctx, why) => {
                    let name = ctx.describe();
                    (gpu(ctx, initial)?, format!("the GPU on {name}: {why}"))
                }
                AutoChoice::Cpu(why) => (cpu(initial)?, format!("{cpu_name}: {why}")),
            },
        },
    };
    Ok(Simulation { scene: scene.clone(), solver, reason })
}

/// One rank's part of a simulation across several: the CPU path on the particles of its slab
/// (docs/scale-out.md). What the exchange does not carry yet is refused here, by name.
fn open_part(scene: &Scene, params: &Params, initial: Option<InitialState>, choice: &BackendChoice, ranks: &Ranks) -> anyhow::Result<Simulation> {
    let size = ranks.comm.size();
    let refuse = |field: &str, message: String| -> anyhow::Result<Simulation> {
        Err(SceneError { origin: scene.name.clone(), field: field.into(), message }.into())
    };
    if params.rebuild_every != 1 {
        return refuse("time.neighbour_rebuild_every", format!("is {}; across ranks ({size}) the exchange runs with every rebuild of the grid, so it must be 1", params.rebuild_every));
    }
    let cpu_name = match choice.precision {
        Precision::F64 => "the CPU path in f64",
        Precision::F32 => "the CPU path in f32",
    };
    if choice.device == Device::Gpu {
        return open_part_on_gpu(scene, params, initial, choice, ranks);
    }
    let reason = match choice.device {
        Device::Gpu => unreachable!("opened above"),
        Device::Cpu => format!("{cpu_name}, as asked, on rank {} of {size}", ranks.comm.rank()),
        Device::Auto => format!("{cpu_name} on rank {} of {size}: across ranks only the CPU path runs yet", ranks.comm.rank()),
    };
    // This machine's ranks hold their shares of the particles (the grid is every rank's).
    let (_, node_ranks) = ranks.comm.node_rank();
    check_host_memory(scene, node_ranks as f64 / size as f64)?;
    let source = initial.as_ref().map_or(InitialSource::Scene(scene), InitialSource::Whole);
    let solver = match choice.precision {
        Precision::F64 => Solver::Cpu64(CpuSolver::new_part(params, source, ranks.comm.clone(), ranks.balance_every)?),
        Precision::F32 => Solver::Cpu32(CpuSolver::new_part(params, source, ranks.comm.clone(), ranks.balance_every)?),
    };
    Ok(Simulation { scene: scene.clone(), solver, reason })
}

/// One rank's part on the GPU: the host runs the exchange of the CPU path, the GPU the rest of
/// the step on the rank's particles and ghosts (src/solver/gpu/ranks.rs). The adapter is the
/// rank's by its place on its machine ([`super::gpu::device::rank_adapter`]).
fn open_part_on_gpu(scene: &Scene, params: &Params, initial: Option<InitialState>, choice: &BackendChoice, ranks: &Ranks) -> anyhow::Result<Simulation> {
    let (rank, size) = (ranks.comm.rank(), ranks.comm.size());
    let (ctx, why) = match &choice.context {
        Some(c) => (c.clone(), "the device given".to_string()),
        None => {
            let candidates = super::gpu::device::candidate_adapters();
            let kinds: Vec<wgpu::DeviceType> = candidates.iter().map(|a| a.get_info().device_type).collect();
            let (node_rank, node_ranks) = ranks.comm.node_rank();
            let Some((index, why)) = super::gpu::device::rank_adapter(&kinds, node_rank, node_ranks) else {
                super::gpu::device::choose_adapter()?;
                anyhow::bail!("rank {rank} of {size}: no GPU adapter with compute shaders");
            };
            let adapter = candidates.into_iter().nth(index).expect("rank_adapter picks an index of the list");
            (GpuContext::from_adapter(adapter)?, why)
        }
    };
    let name = ctx.describe();
    let source = initial.as_ref().map_or(InitialSource::Scene(scene), InitialSource::Whole);
    let stages = super::gpu::ranks::GpuRankStages::new(ctx, params, choice.gpu_options, why, ranks.comm.clone());
    let solver = CpuSolver::<f32>::new_part_on(params, source, ranks.comm.clone(), ranks.balance_every, Box::new(stages))?;
    let reason = format!("the GPU on {name}, as asked, on rank {rank} of {size} (the exchange on the host)");
    Ok(Simulation { scene: scene.clone(), solver: Solver::Cpu32(solver), reason })
}

/// The CPU path's host memory against what the machine has (where the platform tells), for
/// `share` of the scene's particles (across ranks, those of the machine's ranks).
fn check_host_memory(scene: &Scene, share: f64) -> Result<(), SceneError> {
    let count = (scene.estimated_particle_count() as f64 * share.min(1.0)).ceil() as u64;
    let cells = scene.grid().cell_count() as u64;
    let fluid = (scene.fluid_particle_count() as f64 * share.min(1.0)).ceil() as u64;
    let lists = fluid.saturating_mul(cpu_list_bytes_per_fluid_particle(scene.physics.smoothing_length, scene.physics.particle_spacing));
    match host_memory_shortfall_with(count, cells, CPU_BYTES_PER_PARTICLE, lists, " on the cpu backend (with its neighbour lists)") {
        Some(message) => Err(SceneError { origin: scene.name.clone(), field: "fluid".into(), message }),
        None => Ok(()),
    }
}

impl Simulation {
    /// Parses and validates a scene from TOML text (the format of docs/scenes.md).
    ///
    /// ```
    /// let scene = wgsph::Simulation::scene_from_toml(r#"
    ///     name = "drop"
    ///     domain = { min = [0, 0, 0], max = [1, 1, 1] }
    ///     physics = { smoothing_length = 0.1, particle_spacing = 0.05, speed_of_sound = 10 }
    ///     time = { dt = 0.001, end_time = 0.1 }
    ///     [[fluid]]
    ///     min = [0.3, 0.3, 0.3]
    ///     max = [0.6, 0.6, 0.6]
    /// "#)?;
    /// assert_eq!(scene.fluid_particle_count(), 6 * 6 * 6);
    /// # Ok::<(), wgsph::SceneError>(())
    /// ```
    pub fn scene_from_toml(text: &str) -> Result<Scene, SceneError> {
        Scene::from_toml_str(text, &SceneOrigin::Text)
    }

    /// Loads a scene: a built-in name (`seed`, `dam_break`, `hydrostatic`) or a file path.
    pub fn scene_from_file(name_or_path: &str) -> Result<Scene, SceneError> {
        Scene::load(name_or_path)
    }

    /// The scene on the GPU, on the adapter `wgsph run` would choose (`WGPU_BACKEND` and
    /// `WGPU_ADAPTER_NAME` apply). Fails when there is no adapter with compute shaders or the
    /// scene does not fit the adapter's limits.
    pub fn gpu(scene: Scene) -> anyhow::Result<Self> {
        open(&scene, &BackendChoice::gpu())
    }

    /// The scene on the GPU, on a device the caller opened (for example the one it renders
    /// with: [`GpuContext::from_device`] of its adapter, device and queue). The device should
    /// have the adapter's storage-buffer limits for large scenes.
    pub fn gpu_on(scene: Scene, context: GpuContext) -> anyhow::Result<Self> {
        open(&scene, &BackendChoice::gpu_on(context))
    }

    /// Like [`Simulation::gpu_on`], with the GPU step's tuning options (fusion, workgroup
    /// sizes, steps per submission; none changes a value).
    pub fn gpu_with(scene: Scene, context: GpuContext, options: GpuOptions) -> anyhow::Result<Self> {
        open(&scene, &BackendChoice::gpu_on(context).with_gpu_options(options))
    }

    /// The scene on the CPU reference path in f64 (parallel over the available cores).
    pub fn cpu(scene: Scene) -> anyhow::Result<Self> {
        open(&scene, &BackendChoice::cpu(Precision::F64))
    }

    /// The scene on the CPU in f32: the same arithmetic as the GPU, to rounding.
    pub fn cpu_f32(scene: Scene) -> anyhow::Result<Self> {
        open(&scene, &BackendChoice::cpu(Precision::F32))
    }

    /// The backend as the layers above drive it (runs, checkpoints, step fields).
    pub fn backend(&mut self) -> &mut dyn Backend {
        match &mut self.solver {
            Solver::Gpu(s) => s.as_mut(),
            Solver::Cpu64(s) => s,
            Solver::Cpu32(s) => s,
        }
    }

    fn backend_ref(&self) -> &dyn Backend {
        match &self.solver {
            Solver::Gpu(s) => s.as_ref(),
            Solver::Cpu64(s) => s,
            Solver::Cpu32(s) => s,
        }
    }

    /// The backend, owned (for code that keeps several of different kinds).
    pub fn into_backend(self) -> Box<dyn Backend> {
        match self.solver {
            Solver::Gpu(s) => s,
            Solver::Cpu64(s) => Box::new(s),
            Solver::Cpu32(s) => Box::new(s),
        }
    }

    /// The solver itself.
    pub fn solver(&mut self) -> &mut Solver {
        &mut self.solver
    }

    /// The GPU solver, when running on the GPU.
    pub fn gpu_solver(&mut self) -> Option<&mut GpuSolver> {
        match &mut self.solver {
            Solver::Gpu(s) => Some(s),
            _ => None,
        }
    }

    /// The GPU solver, owned, when running on the GPU.
    pub fn into_gpu(self) -> Option<GpuSolver> {
        match self.solver {
            Solver::Gpu(s) => Some(*s),
            _ => None,
        }
    }

    /// The CPU solver in float type `R`, owned, when running on the CPU in that type.
    pub fn into_cpu<R: Real>(self) -> Option<CpuSolver<R>> {
        let any: Box<dyn std::any::Any> = match self.solver {
            Solver::Gpu(_) => return None,
            Solver::Cpu64(s) => Box::new(s),
            Solver::Cpu32(s) => Box::new(s),
        };
        any.downcast::<CpuSolver<R>>().ok().map(|s| *s)
    }

    /// Advances `n` time steps. On the GPU this only records and submits work (nothing is
    /// waited for or read back), so it is cheap to call every frame; call
    /// [`Simulation::health`] now and then to learn whether the state went bad.
    pub fn step(&mut self, n: u64) -> anyhow::Result<()> {
        self.backend().step(n)
    }

    /// The fluid particles in their original order, with density and pressure evaluated for
    /// the current positions (on the GPU: a readback that waits for the queued steps). Taking a
    /// snapshot never changes the trajectory.
    pub fn snapshot(&mut self) -> anyhow::Result<Snapshot> {
        self.backend().snapshot()
    }

    /// Particles that became non-finite or left the domain, and the largest density so far
    /// (a few bytes read back on the GPU).
    pub fn health(&mut self) -> anyhow::Result<Health> {
        self.backend().health()
    }

    pub fn scene(&self) -> &Scene {
        &self.scene
    }
    /// Which backend runs the simulation and why, in words (what `Device::Auto` chose).
    pub fn backend_reason(&self) -> &str {
        &self.reason
    }
    /// The resolved constants (h, dt, stiffness, grid, ...).
    pub fn params(&self) -> &Params {
        self.backend_ref().params()
    }
    pub fn steps_done(&self) -> u64 {
        self.backend_ref().steps_done()
    }
    /// Simulated time reached.
    pub fn time(&self) -> f64 {
        self.backend_ref().time()
    }
    pub fn fluid_count(&self) -> usize {
        self.backend_ref().fluid_count()
    }
    /// `"gpu"` or `"cpu"`.
    pub fn kind(&self) -> &'static str {
        self.backend_ref().kind()
    }
    /// The adapter's name and backend, or the CPU float type.
    pub fn adapter(&self) -> String {
        self.backend_ref().adapter()
    }

    /// The GPU context (adapter, device, queue), when running on the GPU.
    pub fn gpu_context(&self) -> Option<&GpuContext> {
        match &self.solver {
            Solver::Gpu(s) => Some(s.context()),
            _ => None,
        }
    }
    /// The wgpu device, when running on the GPU.
    pub fn device(&self) -> Option<&wgpu::Device> {
        self.gpu_context().map(|c| &c.device)
    }
    /// The wgpu queue the simulation submits to, when running on the GPU.
    pub fn queue(&self) -> Option<&wgpu::Queue> {
        self.gpu_context().map(|c| &c.queue)
    }

    /// The storage buffers of the current particle state, when running on the GPU: positions
    /// and velocities as `array<vec4<f32>>` (w = 0), ids, densities and pressures, in the
    /// solver's cell order (`ids[slot]` is the original index). The solver's buffers change
    /// roles as it steps, so ask again after every [`Simulation::step`]; work submitted to
    /// [`Simulation::queue`] afterwards sees the new state. Every buffer has `STORAGE`,
    /// `COPY_SRC` and `COPY_DST` usage: bind it read-only in a vertex or compute shader, or copy
    /// from it. An error where the density and pressure arrays the solver makes on the first
    /// request cannot be made.
    pub fn particle_buffers(&self) -> Option<anyhow::Result<ParticleBuffers>> {
        match &self.solver {
            Solver::Gpu(s) => Some(s.particle_buffers()),
            _ => None,
        }
    }
}
