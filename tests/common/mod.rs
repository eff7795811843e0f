//! Helpers shared by the test programs: a device on every adapter (every GPU test runs on
//! each), the one builder of the scenes the tests make in code, and solvers made by the one
//! solver builder.

#![allow(dead_code)]

use wgsph::model::initial::InitialState;
use wgsph::model::real::Real;
use wgsph::model::scene::{
    Boundary, BoundaryPressure, BoundaryVolume, DensityMethod, DfsphSettings, InitialPressure, Domain, EquationOfState, FluidBlock, Kernel, Physics, PressureSolver, Scene, SceneOrigin, Time,
    ViscosityChange, WallParticles,
};
use wgsph::solver::cpu::CpuSolver;
use wgsph::solver::gpu::device::compute_adapters;
use wgsph::solver::gpu::{GpuContext, GpuOptions, GpuSolver};
use wgsph::solver::{open_with, BackendChoice, Precision};

/// A device on every adapter found. With none, the test is skipped with a visible message,
/// unless WGSPH_REQUIRE_GPU is set (CI sets it, so a missing driver fails there).
pub fn contexts() -> Vec<GpuContext> {
    // An adapter that is listed but cannot open a device is passed over, as `wgsph run` does.
    let list: Vec<GpuContext> = compute_adapters()
        .into_iter()
        .filter_map(|a| {
            let name = format!("{} ({:?})", a.get_info().name, a.get_info().backend);
            GpuContext::from_adapter(a).map_err(|e| eprintln!("SKIPPED adapter {name}: {e:#}")).ok()
        })
        .collect();
    if list.is_empty() {
        if std::env::var_os("WGSPH_REQUIRE_GPU").is_some() {
            panic!("WGSPH_REQUIRE_GPU is set but no GPU adapter with compute shaders was found");
        }
        eprintln!("SKIPPED: no GPU adapter with compute shaders (install mesa-vulkan-drivers for lavapipe)");
    }
    list
}

/// A scene made in code for a test, built from the public fields of [`Scene`]: [`TestScene::new`]
/// holds the settings most test scenes share, the chainable methods change what a test varies,
/// and [`TestScene::build`] checks the result as a scene file is checked, so that a test cannot
/// run a scene that `wgsph run` would refuse.
#[derive(Clone, Debug)]
pub struct TestScene {
    scene: Scene,
}

impl From<Scene> for TestScene {
    /// A variant of an existing scene (a built-in one, say).
    fn from(scene: Scene) -> TestScene {
        TestScene { scene }
    }
}

impl TestScene {
    /// A scene named "scene" with nothing in it (no fluid, no boundary), in the box
    /// (-0.1, -0.1, -0.1)..(0.7, 0.9, 0.3): h = 0.04, particle spacing 0.02, c0 = 20 m/s, a fixed
    /// dt = 0.0004 up to t = 1. Every other setting is a scene file's default: Mueller kernel,
    /// linear equation of state without clamping, no viscosity, no-slip mirrored walls, gravity
    /// 9.81 m/s^2 down, seed 1.
    pub fn new() -> TestScene {
        TestScene {
            scene: Scene {
                name: "scene".into(),
                description: String::new(),
                seed: 1,
                domain: Domain { min: [-0.1; 3], max: [0.7, 0.9, 0.3] },
                physics: Physics {
                    speed_of_sound: Some(20.0),
                    ..Physics::new(0.04, 0.02)
                },
                time: Time::fixed(0.0004, 1.0),
                fluid: Vec::new(),
                boundary: Vec::new(),
                camera: None,
                limits: Default::default(),
                probe: Vec::new(),
            },
        }
    }

    /// The small tank of the GPU-against-CPU checks: a jittered block of 10 x 15 x 10 particles
    /// moving at 0.3 m/s in an open tank of wall particles (friction 0.5), towards a plane
    /// inside the tank, with gravity and viscosity; Mueller kernel, Tait, clamped pressure.
    pub fn small_tank() -> TestScene {
        TestScene::new()
            .named("small")
            .equation_of_state(EquationOfState::Tait)
            .clamp_negative_pressure(true)
            .viscosity(0.005)
            .boundary_friction(0.5)
            .fluid([0.0; 3], [0.2, 0.3, 0.2])
            .jitter(0.1)
            .moving_at([0.3, 0.0, 0.0])
            .container([0.0; 3], [0.6, 0.5, 0.2])
            .plane([0.5, 0.0, 0.0], [-1.0, 0.0, 0.0], 0.5)
    }

    /// The scene, checked: panics with the error where it is not a valid scene.
    pub fn build(self) -> Scene {
        if let Err(e) = self.scene.validate(&SceneOrigin::Text) {
            panic!("invalid test scene: {e}\n{}", self.scene.to_toml());
        }
        self.scene
    }

    /// The error that refuses the scene, for tests of the checks; panics where it is valid.
    pub fn validation_error(self) -> String {
        match self.scene.validate(&SceneOrigin::Text) {
            Ok(()) => panic!("the scene was expected to be refused:\n{}", self.scene.to_toml()),
            Err(e) => e.to_string(),
        }
    }

    /// Adds a `[[probe]]` table.
    pub fn probe(mut self, probe: wgsph::model::scene::ProbeSpec) -> TestScene {
        self.scene.probe.push(probe);
        self
    }

    pub fn named(mut self, name: &str) -> TestScene {
        self.scene.name = name.into();
        self
    }

    pub fn domain(mut self, min: [f64; 3], max: [f64; 3]) -> TestScene {
        self.scene.domain = Domain { min, max };
        self
    }

    // Physics.

    /// The kernel's support radius h.
    pub fn smoothing_length(mut self, h: f64) -> TestScene {
        self.scene.physics.smoothing_length = h;
        self
    }

    pub fn particle_spacing(mut self, spacing: f64) -> TestScene {
        self.scene.physics.particle_spacing = spacing;
        self
    }

    pub fn kernel(mut self, kernel: Kernel) -> TestScene {
        self.scene.physics.kernel = kernel;
        self
    }

    pub fn equation_of_state(mut self, eos: EquationOfState) -> TestScene {
        self.scene.physics.equation_of_state = eos;
        self
    }

    /// The stiffness k of the equation of state, in place of a speed of sound (a scene gives
    /// exactly one of them).
    pub fn stiffness(mut self, k: f64) -> TestScene {
        self.scene.physics.stiffness = Some(k);
        self.scene.physics.speed_of_sound = None;
        self
    }

    /// The speed of sound c0, in place of a stiffness.
    pub fn speed_of_sound(mut self, c0: f64) -> TestScene {
        self.scene.physics.speed_of_sound = Some(c0);
        self.scene.physics.stiffness = None;
        self
    }

    pub fn clamp_negative_pressure(mut self, clamp: bool) -> TestScene {
        self.scene.physics.clamp_negative_pressure = clamp;
        self
    }

    /// The kinematic viscosity at t = 0.
    pub fn viscosity(mut self, nu: f64) -> TestScene {
        self.scene.physics.viscosity = nu;
        self
    }

    /// Adds a change of the viscosity to `nu` at `time` to the schedule.
    pub fn viscosity_change(mut self, time: f64, nu: f64) -> TestScene {
        self.scene.physics.viscosity_schedule.push(ViscosityChange { time, viscosity: nu });
        self
    }

    pub fn gravity(mut self, g: [f64; 3]) -> TestScene {
        self.scene.physics.gravity = g;
        self
    }

    /// The viscosity between fluid and wall particles: 1 no-slip, 0 free slip.
    pub fn boundary_friction(mut self, friction: f64) -> TestScene {
        self.scene.physics.boundary_friction = friction;
        self
    }

    pub fn boundary_pressure(mut self, pressure: BoundaryPressure) -> TestScene {
        self.scene.physics.boundary_pressure = pressure;
        self
    }

    /// Density carried by the continuity equation.
    pub fn continuity(mut self) -> TestScene {
        self.scene.physics.density = DensityMethod::Continuity;
        self
    }

    /// delta of the density diffusion (continuity density only).
    pub fn density_diffusion(mut self, delta: f64) -> TestScene {
        self.scene.physics.density_diffusion = delta;
        self
    }

    /// alpha of Monaghan's artificial viscosity.
    pub fn artificial_viscosity(mut self, alpha: f64) -> TestScene {
        self.scene.physics.artificial_viscosity = alpha;
        self
    }

    /// gamma of Akinci et al.'s surface tension.
    pub fn surface_tension(mut self, gamma: f64) -> TestScene {
        self.scene.physics.surface_tension = gamma;
        self
    }

    /// beta of Akinci et al.'s adhesion to the wall particles.
    pub fn wall_adhesion(mut self, beta: f64) -> TestScene {
        self.scene.physics.wall_adhesion = beta;
        self
    }

    /// The fluid starts at its hydrostatic density and pressure (continuity density only).
    pub fn hydrostatic_start(mut self) -> TestScene {
        self.scene.physics.initial_pressure = InitialPressure::Hydrostatic;
        self
    }

    // Time.

    pub fn dt(mut self, dt: f64) -> TestScene {
        self.scene.time.dt = dt;
        self
    }

    pub fn end_time(mut self, t: f64) -> TestScene {
        self.scene.time.end_time = t;
        self
    }

    /// Adaptive time steps from the CFL, force and viscous conditions, between dt_min and
    /// dt_max (by default dt / 1000 and dt).
    pub fn adaptive(mut self) -> TestScene {
        self.scene.time.adaptive = true;
        self
    }

    pub fn dt_min(mut self, dt: f64) -> TestScene {
        self.scene.time.dt_min = Some(dt);
        self
    }

    pub fn dt_max(mut self, dt: f64) -> TestScene {
        self.scene.time.dt_max = Some(dt);
        self
    }

    pub fn cfl_number(mut self, c: f64) -> TestScene {
        self.scene.time.cfl_number = Some(c);
        self
    }

    pub fn force_number(mut self, c: f64) -> TestScene {
        self.scene.time.force_number = c;
        self
    }

    pub fn neighbour_rebuild_every(mut self, steps: u32) -> TestScene {
        self.scene.time.neighbour_rebuild_every = steps;
        self
    }

    // Fluid.

    /// Adds a block of fluid at rest filling [min, max], with the default jitter of 0.05
    /// spacings; `jitter` and `moving_at` change it.
    pub fn fluid(mut self, min: [f64; 3], max: [f64; 3]) -> TestScene {
        self.scene.fluid.push(FluidBlock::new(min, max));
        self
    }

    /// The random offset of the particles of the fluid block added last, in spacings.
    pub fn jitter(mut self, jitter: f64) -> TestScene {
        self.last_fluid_block().jitter = jitter;
        self
    }

    /// The initial velocity of the fluid block added last.
    pub fn moving_at(mut self, velocity: [f64; 3]) -> TestScene {
        self.last_fluid_block().velocity = velocity;
        self
    }

    pub fn without_fluid(mut self) -> TestScene {
        self.scene.fluid.clear();
        self
    }

    fn last_fluid_block(&mut self) -> &mut FluidBlock {
        self.scene.fluid.last_mut().expect("a fluid block to change: add one with `fluid` first")
    }

    // Boundaries.

    /// Adds a tank of wall particles around [min, max] with an open top.
    pub fn container(mut self, min: [f64; 3], max: [f64; 3]) -> TestScene {
        self.scene.boundary.push(Boundary::Container { min, max, open_top: true, walls: WallParticles::default() });
        self
    }

    /// Adds a solid box obstacle [min, max]: wall particles filling a shell inside it.
    pub fn solid_box(mut self, min: [f64; 3], max: [f64; 3]) -> TestScene {
        self.scene.boundary.push(Boundary::Box { min, max, walls: WallParticles::default() });
        self
    }

    /// Adds a tank of wall particles around [min, max], closed on every side.
    pub fn closed_container(mut self, min: [f64; 3], max: [f64; 3]) -> TestScene {
        self.scene.boundary.push(Boundary::Container { min, max, open_top: false, walls: WallParticles::default() });
        self
    }

    /// The layers of wall particles of every container and box (default: as many as fill h).
    pub fn wall_layers(mut self, layers: u32) -> TestScene {
        for b in &mut self.scene.boundary {
            if let Boundary::Container { walls, .. } | Boundary::Box { walls, .. } = b {
                walls.layers = Some(layers);
            }
        }
        self
    }

    /// Adds an analytic plane through `point`; the fluid stays on the side `normal` points to
    /// and keeps the fraction `restitution` of its normal speed on impact.
    pub fn plane(mut self, point: [f64; 3], normal: [f64; 3], restitution: f64) -> TestScene {
        self.scene.boundary.push(Boundary::Plane { point, normal, restitution });
        self
    }

    pub fn without_planes(mut self) -> TestScene {
        self.scene.boundary.retain(|b| !matches!(b, Boundary::Plane { .. }));
        self
    }

    /// Without containers and boxes of wall particles (planes stay).
    pub fn without_walls(mut self) -> TestScene {
        self.scene.boundary.retain(|b| matches!(b, Boundary::Plane { .. }));
        self
    }

    pub fn without_boundaries(mut self) -> TestScene {
        self.scene.boundary.clear();
        self
    }

    /// The lattice spacing of the wall particles of every container and box.
    pub fn wall_spacing(mut self, spacing: f64) -> TestScene {
        for b in &mut self.scene.boundary {
            if let Boundary::Container { walls, .. } | Boundary::Box { walls, .. } = b {
                walls.spacing = Some(spacing);
            }
        }
        self
    }

    // DFSPH and Akinci walls.

    /// DFSPH instead of an equation of state (no stiffness or speed of sound), with the default
    /// tolerances.
    pub fn dfsph(mut self) -> TestScene {
        self.scene.physics.solver = PressureSolver::Dfsph;
        self.scene.physics.stiffness = None;
        self.scene.physics.speed_of_sound = None;
        self
    }

    /// Changes DFSPH's settings.
    pub fn dfsph_settings(mut self, change: impl FnOnce(&mut DfsphSettings)) -> TestScene {
        change(&mut self.scene.physics.dfsph);
        self
    }

    /// How a wall particle's mass is found.
    pub fn boundary_volume(mut self, volume: BoundaryVolume) -> TestScene {
        self.scene.physics.boundary_volume = volume;
        self
    }

    // Limits of the weakly compressible regime.

    /// The stop levels: the largest rho/rho0 and Mach number a step may reach (`inf`: none).
    pub fn stop_levels(mut self, max_density_ratio: f64, max_mach: f64) -> TestScene {
        self.scene.limits.max_density_ratio = max_density_ratio;
        self.scene.limits.max_mach = max_mach;
        self.scene.limits.warn_density_ratio = self.scene.limits.warn_density_ratio.min(max_density_ratio);
        self.scene.limits.warn_mach = self.scene.limits.warn_mach.min(max_mach);
        self
    }

    /// The warning levels of rho/rho0 and of the Mach number.
    pub fn warn_levels(mut self, density_ratio: f64, mach: f64) -> TestScene {
        self.scene.limits.warn_density_ratio = density_ratio;
        self.scene.limits.warn_mach = mach;
        self
    }

    /// No stop or warning level: a run stops only for non-finite or escaped particles.
    pub fn without_limits(self) -> TestScene {
        self.stop_levels(f64::INFINITY, f64::INFINITY).warn_levels(f64::INFINITY, f64::INFINITY)
    }
}

/// The GPU solver of `scene` on the device `ctx`, built by the one builder
/// ([`wgsph::solver::open`]).
pub fn gpu(ctx: GpuContext, scene: &Scene) -> GpuSolver {
    gpu_with(ctx, scene, None, GpuOptions::default()).expect("the scene opens on the GPU")
}

/// The GPU solver of `scene` from the particles `initial`.
pub fn gpu_from(ctx: GpuContext, scene: &Scene, initial: &InitialState) -> GpuSolver {
    gpu_with(ctx, scene, Some(initial.clone()), GpuOptions::default()).expect("the scene opens on the GPU")
}

/// The GPU solver of `scene` with `options` (and the particles `initial`, or the scene's own):
/// the builder's error where it refuses.
pub fn gpu_with(ctx: GpuContext, scene: &Scene, initial: Option<InitialState>, options: GpuOptions) -> anyhow::Result<GpuSolver> {
    let choice = BackendChoice::gpu_on(ctx).with_gpu_options(options);
    Ok(open_with(scene, initial, &choice)?.into_gpu().expect("a GPU was chosen"))
}

/// The CPU reference of `scene` in float type `R`.
pub fn cpu<R: Real>(scene: &Scene) -> CpuSolver<R> {
    cpu_open::<R>(scene, None)
}

/// The CPU reference of `scene` in float type `R`, from the particles `initial`.
pub fn cpu_from<R: Real>(scene: &Scene, initial: &InitialState) -> CpuSolver<R> {
    cpu_open::<R>(scene, Some(initial.clone()))
}

fn cpu_open<R: Real>(scene: &Scene, initial: Option<InitialState>) -> CpuSolver<R> {
    let precision = if std::mem::size_of::<R>() == 4 { Precision::F32 } else { Precision::F64 };
    open_with(scene, initial, &BackendChoice::cpu(precision)).expect("the scene opens on the CPU").into_cpu::<R>().expect("the chosen float type")
}
