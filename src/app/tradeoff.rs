//! `wgsph tradeoff`: the speed/accuracy trade measured. One scene is run under many settings
//! (time step, adaptive dt, resolution, kernel, equation of state and stiffness, neighbour-grid
//! rebuild interval, GPU f32 against CPU f64 and f32, each model term off, and DFSPH at three
//! tolerances of its average density error), every run is
//! compared with a reference run of the same scene at high accuracy (f64, dt / 4), and the
//! errors and costs go into `DIR/tradeoff.md` (a table) and `DIR/tradeoff.png` (error against
//! cost, the Pareto front marked).
//!
//! Errors, sampled at `samples` equally spaced times (the first step at or after each):
//! - compression: rho / rho0 - 1 where rho > rho0 (free-surface particles lack neighbours and
//!   sit below rho0; that is not compressibility), mean over particles and samples, and max;
//! - surge front: the largest x of any fluid particle, RMS difference from the reference (m);
//! - centre of mass: RMS distance from the reference's (m);
//! - kinetic energy: RMS difference over the reference's largest;
//! - per-particle position error at the end, RMS over particles / h, where the particles are
//!   the same (same resolution and initial state).
//!
//! Cost: wall seconds of stepping (health checks included, snapshots for the errors left out)
//! per simulated second and per particle-step, and the bytes the backend allocated.

use super::args::TradeoffArgs;
use super::errors::InputError;
use crate::io::atomic::write_atomic;
use crate::model::scene::{Boundary, BoundaryPressure, DensityMethod, DfsphSettings, EquationOfState, InitialPressure, Kernel, PressureSolver, Scene, SceneOrigin};
use crate::model::numbers::short;
use crate::model::state::Snapshot;
use crate::solver::compare::{diff as distance, rms};
use crate::solver::{open, Backend, BackendChoice, Device, Precision};
use crate::viz::plot::{Corner, Mark, Plot};
use std::time::{Duration, Instant};

/// Where a configuration runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Engine {
    Gpu,
    CpuF64,
    CpuF32,
}

/// One setting of the knobs.
#[derive(Clone, Debug)]
pub struct Config {
    pub name: String,
    /// Which knob it turns.
    pub knob: &'static str,
    pub scene: Scene,
    pub engine: Engine,
}

/// DFSPH's longest adaptive step, in steps of the base scene: its CFL condition is on the flow
/// speed alone, so it may take several of a weakly compressible scene's steps at once.
pub const DFSPH_DT_MAX_FACTOR: f64 = 8.0;

/// The tolerances of DFSPH's average density error the study runs (0.01 % is the default).
pub const DFSPH_TOLERANCES: [f64; 3] = [1e-4, 1e-3, 1e-2];

/// `base` with DFSPH at `density_error`: adaptive dt up to [`DFSPH_DT_MAX_FACTOR`] of the
/// base's step (an incompressible solve has no speed of sound to bound it), the equation of
/// state's settings dropped (DFSPH refuses them).
pub fn with_dfsph(base: &Scene, density_error: f64) -> Scene {
    let mut s = base.clone();
    if s.physics.solver != PressureSolver::Dfsph {
        s.physics.solver = PressureSolver::Dfsph;
        s.physics.stiffness = None;
        s.physics.speed_of_sound = None;
        s.time.adaptive = true;
        s.time.dt_max = Some(DFSPH_DT_MAX_FACTOR * base.time.dt);
        s.time.dt = DFSPH_DT_MAX_FACTOR * base.time.dt;
        s.time.dt_min = Some(base.time.dt * 1e-3);
    }
    s.physics.dfsph = DfsphSettings { density_error, ..s.physics.dfsph.clone() };
    s
}

/// The configurations of a study around `base`: the reference first, then the baseline (the
/// scene as it is, on the GPU), then one knob turned at a time. A DFSPH scene has no equation
/// of state, so its study leaves out the knobs of one.
pub fn configs(base: &Scene) -> Vec<Config> {
    let dt = base.time.dt;
    let with = |f: &dyn Fn(&mut Scene)| {
        let mut s = base.clone();
        f(&mut s);
        s
    };
    let c = |name: &str, knob: &'static str, scene: Scene, engine: Engine| Config { name: name.into(), knob, scene, engine };
    let c0 = base.params().speed_of_sound();
    let fluid = base.fluid_particle_count();
    let weakly_compressible = base.physics.solver == PressureSolver::Wcsph;
    let mut all = vec![
        c("reference (f64, dt/4)", "reference", with(&|s| s.time.dt = dt / 4.0), Engine::CpuF64),
        c("baseline (gpu f32)", "baseline", base.clone(), Engine::Gpu),
        c("cpu f64", "precision", base.clone(), Engine::CpuF64),
        c("cpu f32", "precision", base.clone(), Engine::CpuF32),
        c("dt x0.5", "time step", with(&|s| s.time.dt = dt / 2.0), Engine::Gpu),
        c("dt x2", "time step", with(&|s| s.time.dt = dt * 2.0), Engine::Gpu),
        c(
            "adaptive dt",
            "time step",
            with(&|s| {
                s.time.adaptive = true;
                s.time.dt_max = Some(2.0 * dt);
            }),
            Engine::Gpu,
        ),
        c("particles x0.5", "resolution", base.with_fluid_particles((fluid / 2).max(1)), Engine::Gpu),
        c("particles x2", "resolution", base.with_fluid_particles(fluid * 2), Engine::Gpu),
    ];
    // Each other kernel, with the same support h.
    all.extend(Kernel::ALL.into_iter().filter(|&k| k != base.physics.kernel).map(|kernel| {
        let name = match kernel {
            Kernel::Mueller => "Mueller kernels",
            Kernel::CubicSpline => "cubic spline kernel",
            Kernel::Wendland => "Wendland kernel",
        };
        c(name, "kernel", with(&|s| s.physics.kernel = kernel), Engine::Gpu)
    }));
    all.extend([
        c(
            "other EOS (same c0)",
            "equation of state",
            with(&|s| {
                s.physics.equation_of_state = match base.physics.equation_of_state {
                    EquationOfState::Linear => EquationOfState::Tait,
                    EquationOfState::Tait => EquationOfState::Linear,
                };
                s.physics.stiffness = None;
                s.physics.speed_of_sound = Some(c0);
            }),
            Engine::Gpu,
        ),
        c(
            "c0 x0.5 (k/4)",
            "stiffness",
            with(&|s| {
                s.physics.stiffness = None;
                s.physics.speed_of_sound = Some(c0 / 2.0);
            }),
            Engine::Gpu,
        ),
        c(
            "c0 x2 (4k, dt/2)",
            "stiffness",
            with(&|s| {
                s.physics.stiffness = None;
                s.physics.speed_of_sound = Some(c0 * 2.0);
                s.time.dt = dt / 2.0;
            }),
            Engine::Gpu,
        ),
        c("grid every 2nd step", "neighbour grid", with(&|s| s.time.neighbour_rebuild_every = 2), Engine::Gpu),
        c(
            "no viscosity",
            "model term",
            with(&|s| {
                s.physics.viscosity = 0.0;
                s.physics.viscosity_schedule.clear();
            }),
            Engine::Gpu,
        ),
        c("no wall particles", "model term", with(&|s| s.boundary.retain(|b| matches!(b, Boundary::Plane { .. }))), Engine::Gpu),
        c("no planes", "model term", with(&|s| s.boundary.retain(|b| !matches!(b, Boundary::Plane { .. }))), Engine::Gpu),
        c(
            "no pressure clamp",
            "model term",
            with(&|s| s.physics.clamp_negative_pressure = !base.physics.clamp_negative_pressure),
            Engine::Gpu,
        ),
        c("continuity density", "density", with(&|s| continuity(s, 0.0)), Engine::Gpu),
        c("continuity + diffusion 0.1", "density diffusion", with(&|s| continuity(s, 0.1)), Engine::Gpu),
        c("continuity + diffusion 0.2", "density diffusion", with(&|s| continuity(s, 0.2)), Engine::Gpu),
        c(
            "continuity + diffusion 0.1 + hydrostatic start",
            "initial state",
            with(&|s| {
                continuity(s, 0.1);
                s.physics.initial_pressure = InitialPressure::Hydrostatic;
            }),
            Engine::Gpu,
        ),
        c(
            "artificial viscosity 0.02 (no viscosity)",
            "viscosity model",
            with(&|s| {
                s.physics.viscosity = 0.0;
                s.physics.viscosity_schedule.clear();
                s.physics.artificial_viscosity = 0.02;
            }),
            Engine::Gpu,
        ),
        c("wall pressure: consistent", "boundary pressure", with(&|s| s.physics.boundary_pressure = BoundaryPressure::Consistent), Engine::Gpu),
        c("wall pressure: adami", "boundary pressure", with(&|s| s.physics.boundary_pressure = BoundaryPressure::Adami), Engine::Gpu),
        c(
            "continuity + diffusion 0.1 + hydrostatic start + adami walls",
            "boundary pressure",
            with(&|s| {
                continuity(s, 0.1);
                s.physics.initial_pressure = InitialPressure::Hydrostatic;
                s.physics.boundary_pressure = BoundaryPressure::Adami;
            }),
            Engine::Gpu,
        ),
    ]);
    if !weakly_compressible {
        // DFSPH has no equation of state, and carries no density by the continuity equation.
        all.retain(|c| {
            !matches!(c.knob, "equation of state" | "stiffness" | "density" | "density diffusion" | "initial state" | "viscosity model" | "boundary pressure") && c.name != "no pressure clamp"
        });
    }
    for tolerance in DFSPH_TOLERANCES {
        all.push(c(&format!("dfsph {}%", 100.0 * tolerance), "dfsph tolerance", with_dfsph(base, tolerance), Engine::Gpu));
    }
    // The wall pressure models act on wall particles: without them they would run the
    // baseline (or another row) again under another name.
    if base.boundary.iter().all(|b| matches!(b, Boundary::Plane { .. })) {
        all.retain(|c| c.knob != "boundary pressure");
    }
    // A knob the scene does not use (no planes to drop, a DFSPH tolerance that is already the
    // scene's) would run the baseline again under another name: left out. So is one the
    // scene cannot take (adaptive dt beside a viscosity schedule).
    all.retain(|c| matches!(c.knob, "reference" | "baseline" | "precision") || c.engine != Engine::Gpu || c.scene != *base);
    all.retain(|c| c.scene.validate(&SceneOrigin::Text).is_ok());
    all
}

/// The scene with continuity density and density diffusion `delta` (0: none); continuity
/// density needs a fixed dt, so an adaptive scene runs at its largest step.
fn continuity(s: &mut Scene, delta: f64) {
    s.physics.density = DensityMethod::Continuity;
    s.physics.density_diffusion = delta;
    if s.time.adaptive {
        s.time.adaptive = false;
        s.time.dt = s.time.dt_max.unwrap_or(s.time.dt);
        s.time.dt_min = None;
        s.time.dt_max = None;
    }
}

/// What one sample of a run measures.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sample {
    pub time: f64,
    pub front: f64,
    pub centre: [f64; 3],
    pub kinetic_energy: f64,
    pub compression_mean: f64,
    pub compression_max: f64,
}

impl Sample {
    pub fn of(s: &Snapshot, mass: f64, rest_density: f64) -> Sample {
        let n = s.len().max(1) as f64;
        let mut centre = [0.0; 3];
        for x in &s.positions {
            for k in 0..3 {
                centre[k] += x[k] / n;
            }
        }
        let compression: Vec<f64> = s.densities.iter().map(|&rho| (rho / rest_density - 1.0).max(0.0)).collect();
        Sample {
            time: s.time,
            front: s.positions.iter().map(|x| x[0]).fold(f64::NEG_INFINITY, f64::max),
            centre,
            kinetic_energy: s.kinetic_energy(mass),
            compression_mean: compression.iter().sum::<f64>() / n,
            compression_max: compression.iter().cloned().fold(0.0, f64::max),
        }
    }
}

/// A finished (or failed) run.
#[derive(Clone, Debug, Default)]
pub struct Record {
    pub adapter: String,
    pub fluid: usize,
    pub h: f64,
    pub spacing: f64,
    pub samples: Vec<Sample>,
    pub last: Option<Snapshot>,
    pub steps: u64,
    pub sim_time: f64,
    pub dt_mean: f64,
    pub busy: Duration,
    pub memory: Option<u64>,
    pub failure: Option<String>,
}

/// Runs `backend` to each of `times`, taking a sample there.
pub fn record(backend: &mut dyn Backend, scene: &Scene, times: &[f64]) -> anyhow::Result<Record> {
    let params = backend.params().clone();
    let mut r = Record {
        adapter: backend.adapter(),
        fluid: backend.fluid_count(),
        h: params.h,
        spacing: scene.physics.particle_spacing,
        memory: backend.memory_bytes(),
        ..Record::default()
    };
    let first = backend.snapshot()?;
    r.samples.push(Sample::of(&first, params.fluid_mass, params.rest_density));
    'outer: for &t in times {
        while backend.time() < t - 1e-12 {
            let left = t - backend.time();
            let n = if params.adaptive.is_some() {
                // About half the time left at the last step's dt (one step before any).
                let last = backend.dt_stats()?.last;
                if last > 0.0 { ((0.5 * left / last).floor() as u64).clamp(1, 200) } else { 1 }
            } else {
                ((left / params.dt) - 1e-9).ceil().max(1.0) as u64
            };
            let start = Instant::now();
            backend.step(n)?;
            // Reading the health waits for the GPU, so the time covers the work.
            let health = backend.health()?;
            r.busy += start.elapsed();
            if !health.is_ok() {
                r.failure = Some(crate::solver::backend::diagnose_failure(backend, scene)?);
                break 'outer;
            }
        }
        let s = backend.snapshot()?;
        r.samples.push(Sample::of(&s, params.fluid_mass, params.rest_density));
        r.last = Some(s);
    }
    r.steps = backend.steps_done();
    r.sim_time = backend.time();
    r.dt_mean = backend.dt_stats()?.mean;
    Ok(r)
}

/// One row of the table.
#[derive(Clone, Debug, Default)]
pub struct Row {
    pub name: String,
    pub knob: String,
    pub adapter: String,
    pub fluid: usize,
    pub steps: u64,
    pub dt_mean: f64,
    pub seconds_per_sim_second: f64,
    pub ns_per_particle_step: f64,
    pub memory_mib: Option<f64>,
    pub compression_mean: f64,
    pub compression_max: f64,
    pub front_error: f64,
    pub centre_error: f64,
    pub energy_error: f64,
    pub position_error: Option<f64>,
    pub failure: Option<String>,
    pub pareto: bool,
}


/// The errors and costs of `run` against `reference`.
pub fn row(config: &Config, run: &Record, reference: &Record) -> Row {
    let pairs = || run.samples.iter().zip(&reference.samples);
    let n = run.samples.len().max(1) as f64;
    let ke_scale = reference.samples.iter().map(|s| s.kinetic_energy).fold(0.0, f64::max).max(1e-300);
    let same_particles = run.fluid == reference.fluid && run.spacing == reference.spacing;
    let position_error = match (&run.last, &reference.last) {
        (Some(a), Some(b)) if same_particles && run.failure.is_none() => {
            Some(rms(a.positions.iter().zip(&b.positions).map(|(x, y)| distance(*x, *y))) / reference.h)
        }
        _ => None,
    };
    let busy = run.busy.as_secs_f64();
    Row {
        name: config.name.clone(),
        knob: config.knob.into(),
        adapter: run.adapter.clone(),
        fluid: run.fluid,
        steps: run.steps,
        dt_mean: run.dt_mean,
        seconds_per_sim_second: if run.sim_time > 0.0 { busy / run.sim_time } else { f64::NAN },
        ns_per_particle_step: 1e9 * busy / (run.steps.max(1) as f64 * run.fluid.max(1) as f64),
        memory_mib: run.memory.map(|b| b as f64 / (1u64 << 20) as f64),
        compression_mean: run.samples.iter().map(|s| s.compression_mean).sum::<f64>() / n,
        compression_max: run.samples.iter().map(|s| s.compression_max).fold(0.0, f64::max),
        front_error: rms(pairs().map(|(a, b)| a.front - b.front)),
        centre_error: rms(pairs().map(|(a, b)| distance(a.centre, b.centre))),
        energy_error: rms(pairs().map(|(a, b)| (a.kinetic_energy - b.kinetic_energy) / ke_scale)),
        position_error,
        failure: run.failure.clone(),
        pareto: false,
    }
}

/// Marks the rows no other row beats in both cost and error (the Pareto front), among the rows
/// given by `candidates`. `cost` and `error` give each row's two values.
pub fn mark_pareto(rows: &mut [Row], candidates: &[usize], cost: impl Fn(&Row) -> f64, error: impl Fn(&Row) -> f64) {
    for &i in candidates {
        let (ci, ei) = (cost(&rows[i]), error(&rows[i]));
        let dominated = candidates.iter().any(|&j| {
            let (cj, ej) = (cost(&rows[j]), error(&rows[j]));
            j != i && cj <= ci && ej <= ei && (cj < ci || ej < ei)
        });
        rows[i].pareto = !dominated;
    }
}

fn engine_backend(config: &Config) -> anyhow::Result<Box<dyn Backend>> {
    let choice = match config.engine {
        Engine::CpuF64 => BackendChoice::cpu(Precision::F64),
        Engine::CpuF32 => BackendChoice::cpu(Precision::F32),
        // The GPU's configurations run on any adapter, a software one too; without one, on
        // the CPU in f32, its arithmetic.
        Engine::Gpu if crate::solver::gpu::device::compute_adapters().is_empty() => BackendChoice::cpu(Precision::F32),
        Engine::Gpu => BackendChoice { device: Device::Gpu, precision: Precision::F32, ..Default::default() },
    };
    Ok(open(&config.scene, &choice)?.into_backend())
}

/// The sample times: `samples` steps of a whole number of base steps, so that the runs at dt,
/// dt/2, dt/4 and 2 dt sample at the same instants.
pub fn sample_times(base_dt: f64, time: f64, samples: u64) -> Vec<f64> {
    let per = (((time / samples as f64) / base_dt / 2.0).round().max(1.0) * 2.0) as u64;
    let steps = ((time / base_dt) - 1e-9).ceil() as u64;
    let mut out: Vec<f64> = (1..).map(|k| (k * per).min(steps)).take_while(|&s| s < steps).map(|s| s as f64 * base_dt).collect();
    out.push(steps as f64 * base_dt);
    out
}

/// Runs the study; prints one line per configuration.
pub fn study(base: &Scene, time: f64, samples: u64, mut progress: impl FnMut(&str)) -> anyhow::Result<Vec<Row>> {
    let times = sample_times(base.time.dt, time, samples);
    let configs = configs(base);
    let mut records = Vec::new();
    for config in &configs {
        let mut backend = engine_backend(config)?;
        let r = record(backend.as_mut(), &config.scene, &times)?;
        progress(&format!(
            "{:<24} {:>6} particles {:>7} steps in {:>7.2} s{}",
            config.name,
            r.fluid,
            r.steps,
            r.busy.as_secs_f64(),
            r.failure.as_ref().map(|f| format!("  FAILED: {f}")).unwrap_or_default()
        ));
        records.push(r);
    }
    let reference = &records[0];
    anyhow::ensure!(reference.failure.is_none(), "the reference run failed: {}", reference.failure.as_deref().unwrap_or(""));
    let mut rows: Vec<Row> = configs.iter().zip(&records).map(|(c, r)| row(c, r, reference)).collect();
    let candidates: Vec<usize> = (1..rows.len()).filter(|&i| rows[i].failure.is_none()).collect();
    mark_pareto(&mut rows, &candidates, |r| r.seconds_per_sim_second, |r| r.front_error);
    Ok(rows)
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map(|v| format!("{v:.digits$}")).unwrap_or_else(|| "-".into())
}

/// The markdown table.
pub fn table(rows: &[Row]) -> String {
    let mut s = String::from(
        "| configuration | knob | particles | steps | mean dt (s) | wall s per sim s | ns per particle-step | memory (MiB) | compression mean / max (%) | front error (mm) | centre-of-mass error (mm) | kinetic energy error (%) | position error (/h) | Pareto |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for (i, r) in rows.iter().enumerate() {
        if let Some(f) = &r.failure {
            s += &format!("| {} | {} | {} | {} | - | - | - | {} | - | failed: {} | | | | |\n", r.name, r.knob, r.fluid, r.steps, opt(r.memory_mib, 1), f.split(". ").next().unwrap_or(f));
            continue;
        }
        let reference = i == 0;
        let err = |v: f64, scale: f64, digits: usize| if reference { "0 (reference)".to_string() } else { format!("{:.digits$}", v * scale) };
        s += &format!(
            "| {} | {} | {} | {} | {:.2e} | {:.1} | {:.0} | {} | {:.3} / {:.2} | {} | {} | {} | {} | {} |\n",
            r.name,
            r.knob,
            r.fluid,
            r.steps,
            r.dt_mean,
            r.seconds_per_sim_second,
            r.ns_per_particle_step,
            opt(r.memory_mib, 1),
            100.0 * r.compression_mean,
            100.0 * r.compression_max,
            err(r.front_error, 1e3, 1),
            err(r.centre_error, 1e3, 2),
            err(r.energy_error, 100.0, 2),
            if reference { "0 (reference)".into() } else { opt(r.position_error, 3) },
            if r.pareto { "yes" } else { "" },
        );
    }
    s
}

/// The plot: log10 of the front error against log10 of the cost, every configuration labelled,
/// the Pareto front drawn through its points.
pub fn plot(rows: &[Row], title: &str) -> Plot {
    let usable: Vec<&Row> = rows.iter().skip(1).filter(|r| r.failure.is_none() && r.front_error > 0.0).collect();
    let point = |r: &Row| (r.seconds_per_sim_second.log10(), (r.front_error * 1e3).log10());
    let mut front: Vec<(f64, f64)> = usable.iter().filter(|r| r.pareto).map(|r| point(r)).collect();
    front.sort_by(|a, b| a.0.total_cmp(&b.0));
    Plot::new(title, "log10 wall seconds per simulated second", "log10 surge-front error (mm)")
        .labelled_points("configurations", usable.iter().map(|r| point(r)).collect(), usable.iter().map(|r| r.name.clone()).collect())
        .highlighted("Pareto front", front, Mark::LineAndPoints)
        .legend(Corner::UpperRight)
        .size(1200, 800)
}

/// `wgsph tradeoff`.
pub fn cmd_tradeoff(args: &TradeoffArgs) -> anyhow::Result<i32> {
    if !(args.time.is_finite() && args.time > 0.0) {
        return Err(InputError(format!("--time is {}; must be a finite number > 0", args.time)).into());
    }
    let base = super::args::load_scene(&args.scene, &args.overrides, Some(args.particles), false)?;
    // The coarsest configuration steps at 2 dt: a shorter time leaves it nothing to measure.
    if args.time < 2.0 * base.time.dt {
        return Err(InputError(format!(
            "--time is {} s; must be at least two of the scene's time steps (2 x time.dt = {} s), so that every configuration takes a step",
            short(args.time),
            short(2.0 * base.time.dt)
        ))
        .into());
    }
    // The GPU is opened before anything is written or run: an adapter that cannot run the
    // scene stops the study before the reference's long run, not after it.
    if let Some(gpu) = configs(&base).iter().find(|c| c.engine == Engine::Gpu) {
        engine_backend(gpu)?;
    }
    crate::io::rundir::prepare_report_dir("--out", &args.out)?;
    let started = Instant::now();
    // Samples fall on whole pairs of steps: a short time holds fewer than asked.
    let samples = sample_times(base.time.dt, args.time, args.samples).len();
    println!("tradeoff {}: {} fluid particles, {} s simulated, {samples} samples", base.name, base.fluid_particle_count(), short(args.time));
    let rows = study(&base, args.time, args.samples, |line| println!("  {line}"))?;
    let title = format!("{}: error against cost ({} fluid particles, {} s)", base.name, base.fluid_particle_count(), short(args.time));
    let md = format!(
        "# Speed against accuracy: {}\n\n{} fluid particles at the base resolution, {} s simulated, compared at {} times with the reference \
         (CPU f64, dt / 4). Study run in {:.0} s. The errors and costs are defined in `src/app/tradeoff.rs` and docs/performance.md.\n\n{}",
        base.name,
        base.fluid_particle_count(),
        short(args.time),
        samples,
        started.elapsed().as_secs_f64(),
        table(&rows)
    );
    write_atomic(&args.out.join("tradeoff.md"), |w| w.write_all(md.as_bytes()))?;
    plot(&rows, &title).write_png(&args.out.join("tradeoff.png"))?;
    print!("{}", table(&rows));
    println!("-> {} and {} in {:.0} s", args.out.join("tradeoff.md").display(), args.out.join("tradeoff.png").display(), started.elapsed().as_secs_f64());
    Ok(0)
}

/// For tests: the Pareto marks of plain (cost, error) pairs.
pub fn pareto_of(points: &[(f64, f64)]) -> Vec<bool> {
    let mut rows: Vec<Row> = points.iter().map(|&(c, e)| Row { seconds_per_sim_second: c, front_error: e, ..Row::default() }).collect();
    let all: Vec<usize> = (0..rows.len()).collect();
    mark_pareto(&mut rows, &all, |r| r.seconds_per_sim_second, |r| r.front_error);
    rows.iter().map(|r| r.pareto).collect()
}
