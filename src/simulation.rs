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
//! let mut sim = Simulation::cpu(scene);
//! sim.step(5)?;
//! let snapshot = sim.snapshot()?;
//! assert_eq!(snapshot.step, 5);
//! assert_eq!(snapshot.len(), sim.fluid_count());
//! assert!(sim.health()?.is_ok());
//! # Ok::<(), anyhow::Error>(())
//! ```

use crate::cpu::CpuSolver;
use crate::gpu::{GpuContext, GpuSolver, ParticleBuffers};
use crate::scene::{Params, Scene, SceneError, SceneOrigin};
use crate::sim::{Backend, Health, Snapshot};

enum Solver {
    Gpu(Box<GpuSolver>),
    Cpu64(CpuSolver<f64>),
    Cpu32(CpuSolver<f32>),
}

/// A running simulation of one scene.
pub struct Simulation {
    scene: Scene,
    solver: Solver,
}

impl Simulation {
    /// Parses and validates a scene from TOML text (the format of the README's *Scene files*).
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
        Self::gpu_on(scene, GpuContext::new()?)
    }

    /// The scene on the GPU, on a device the caller opened (for example the one it renders
    /// with: [`GpuContext::from_device`] of its adapter, device and queue). The device should
    /// have the adapter's storage-buffer limits for large scenes.
    pub fn gpu_on(scene: Scene, context: GpuContext) -> anyhow::Result<Self> {
        Self::gpu_with(scene, context, crate::gpu::GpuOptions::default())
    }

    /// Like [`Simulation::gpu_on`], with the GPU step's tuning options (fusion, workgroup
    /// sizes, steps per submission; none changes a value).
    pub fn gpu_with(scene: Scene, context: GpuContext, options: crate::gpu::GpuOptions) -> anyhow::Result<Self> {
        scene.validate(&SceneOrigin::Text)?;
        crate::gpu::memory::MemoryPlan::for_scene(&scene).check(&context)?;
        let solver = GpuSolver::with_options(context, &scene.params(), &scene.initial_state(), options)?;
        Ok(Simulation { scene, solver: Solver::Gpu(Box::new(solver)) })
    }

    /// The scene on the CPU reference path in f64 (parallel over the available cores).
    pub fn cpu(scene: Scene) -> Self {
        let solver = CpuSolver::<f64>::new(&scene.params(), &scene.initial_state());
        Simulation { scene, solver: Solver::Cpu64(solver) }
    }

    /// The scene on the CPU in f32: the same arithmetic as the GPU, to rounding.
    pub fn cpu_f32(scene: Scene) -> Self {
        let solver = CpuSolver::<f32>::new(&scene.params(), &scene.initial_state());
        Simulation { scene, solver: Solver::Cpu32(solver) }
    }

    /// The backend as the command line drives it (checkpoints, step fields).
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
    /// solver's cell order (`ids[slot]` is the original index). The solver alternates between
    /// two sets of buffers, so ask again after every [`Simulation::step`]; work submitted to
    /// [`Simulation::queue`] afterwards sees the new state. Every buffer has `STORAGE`,
    /// `COPY_SRC` and `COPY_DST` usage: bind it read-only in a vertex or compute shader, or copy
    /// from it.
    pub fn particle_buffers(&self) -> Option<ParticleBuffers<'_>> {
        match &self.solver {
            Solver::Gpu(s) => Some(s.particle_buffers()),
            _ => None,
        }
    }
}
