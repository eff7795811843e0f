//! `wgsph bench`: the block workload that the CPU peers were measured on
//! (docs/performance.md), on every path, in fluid particle-steps per second, with the bytes per
//! fluid particle and the ratio to the recorded SPlisHSPlasH figure, so that anyone can repeat
//! the comparison with one command.
//!
//! The workload: n^3 fluid particles of spacing 0.02 m at (i+1, j+1, k+1) 0.02 in a closed box
//! with walls at x = 0 and 2L, y = 0 and 1.5L, z = 0 and L + 0.02 (L = n 0.02), gravity -9.81
//! in y, rho0 = 1000, kernel support 0.04 m (the cubic spline), Tait with stiffness 50 kPa and
//! negative pressure clamped (as SPlisHSPlasH's WCSPH), no viscosity, 200 steps of 0.4 ms.
//! The DFSPH paths run the same block with DFSPH (average density error 0.01 %, as
//! SPlisHSPlasH's DFSPH was measured) and steps of 1 ms, with one layer of wall particles and
//! Akinci's wall volumes, as SPlisHSPlasH (see [`dfsph_block_scene`]).

use super::args::{BenchArgs, BenchPath};
use super::errors::InputError;
use anyhow::Context;
use std::io::Write;
use crate::model::scene::{Boundary, BoundaryVolume, Domain, EquationOfState, FluidBlock, Kernel, Physics, PressureSolver, Scene, Time, WallParticles};
use crate::solver::gpu::device::compute_adapters;
use crate::solver::gpu::{GpuContext, GpuOptions};
use crate::solver::{open, BackendChoice, Precision};
use serde::Serialize;
use std::time::Instant;

/// SPlisHSPlasH 2.16's WCSPH on the workload, fluid particle-steps per second, measured on a
/// 2-core x86-64 machine with AVX2 (2 OpenMP threads), 2026-11-23, by n.
pub const SPLISHSPLASH_WCSPH: [(u32, f64); 3] = [(20, 1.00e6), (30, 1.10e6), (40, 1.10e6)];

/// SPlisHSPlasH 2.16's DFSPH on the workload at dt = 1 ms (its Akinci boundaries, average density
/// error 0.01 %), fluid particle-steps per second on the same kind of 2-core machine, by n
/// (issue 16's reference figure), and its iterations per step (constant density + divergence).
pub const SPLISHSPLASH_DFSPH: [(u32, f64); 1] = [(30, 0.59e6)];
pub const SPLISHSPLASH_DFSPH_ITERATIONS: (f64, f64) = (5.9, 1.05);

/// The workload with DFSPH: the same block and box, steps of 1 ms and the default tolerances
/// (average density error 0.01 %, divergence error 0.1 %), walls of one layer of particles
/// with Akinci's volumes, as SPlisHSPlasH samples the box's faces once.
pub fn dfsph_block_scene(n: u32) -> Scene {
    let mut scene = block_scene(n);
    scene.name = format!("block_n{n}_dfsph");
    scene.physics.solver = PressureSolver::Dfsph;
    scene.physics.stiffness = None;
    scene.physics.boundary_volume = BoundaryVolume::Akinci;
    for b in &mut scene.boundary {
        if let Boundary::Container { walls, .. } = b {
            walls.layers = Some(1);
        }
    }
    scene.time = Time::fixed(0.001, 0.2);
    scene
}

/// The workload's scene at n^3 fluid particles.
pub fn block_scene(n: u32) -> Scene {
    let dx = 0.02;
    let l = n as f64 * dx;
    // wgsph's lattice sits at min + (i + 1/2) s: the block [dx/2, dx/2 + L] puts particles at
    // (i + 1) dx; the container [dx/2, wall - dx/2] puts the first wall layer on the wall.
    let half = dx / 2.0;
    let walls = [2.0 * l, 1.5 * l, l + dx];
    Scene {
        name: format!("block_n{n}"),
        description: format!("dam-break block, {n}^3 fluid particles, the peers' benchmark workload"),
        seed: 1,
        domain: Domain { min: [-3.0 * dx; 3], max: [walls[0] + 3.0 * dx, walls[1] + 3.0 * dx, walls[2] + 3.0 * dx] },
        physics: Physics {
            kernel: Kernel::CubicSpline,
            equation_of_state: EquationOfState::Tait,
            stiffness: Some(50_000.0),
            clamp_negative_pressure: true,
            boundary_friction: 0.0,
            ..Physics::new(2.0 * dx, dx)
        },
        time: Time::fixed(0.0004, 0.08),
        fluid: vec![FluidBlock { jitter: 0.0, ..FluidBlock::new([half; 3], [half + l; 3]) }],
        boundary: vec![Boundary::Container {
            min: [half; 3],
            max: [walls[0] - half, walls[1] - half, walls[2] - half],
            open_top: false,
            walls: WallParticles::default(),
        }],
        camera: None,
        limits: Default::default(),
        probe: Vec::new(),
    }
}

/// One path's figures.
#[derive(Serialize, Clone, Debug)]
pub struct BenchRow {
    pub path: String,
    pub adapter: String,
    /// The GPU driver and its version (empty on the CPU paths).
    pub driver: String,
    pub fluid_particles: usize,
    pub wall_particles: usize,
    pub steps: u64,
    pub seconds: f64,
    pub particle_steps_per_second: f64,
    /// Processor time of all the process's threads (the solver's, and a software adapter's)
    /// over the timed steps, where the system says (Linux): on a loaded machine the wall clock
    /// counts the time other programs ran, this does not.
    pub cpu_seconds: Option<f64>,
    /// The 1-minute load average when the steps ended (Linux), to judge the wall clock by.
    pub load_average: Option<f64>,
    pub bytes_per_fluid_particle: Option<f64>,
    /// Over SPlisHSPlasH's figure for the same method at the same n, where one was measured.
    pub ratio_to_splishsplash: Option<f64>,
    /// DFSPH: the timed steps' mean iterations of the constant-density and the divergence solve.
    pub pressure_iterations_per_step: Option<f64>,
    pub divergence_iterations_per_step: Option<f64>,
}

/// Runs the workload on one backend: the steps are timed from the first submission to the end
/// of the last (a health read waits for the GPU), after one warm-up step (pipeline caches,
/// first-touch of the buffers).
fn measure(path: &str, scene: &Scene, choice: &BackendChoice, steps: u64, n: u32) -> anyhow::Result<BenchRow> {
    let mut sim = open(scene, choice)?;
    let backend = sim.backend();
    backend.step(1)?;
    let before = backend.health()?.iterations;
    let cpu_before = process_cpu_seconds();
    let t = Instant::now();
    backend.step(steps)?;
    let health = backend.health()?;
    let seconds = t.elapsed().as_secs_f64();
    let cpu_seconds = cpu_before.zip(process_cpu_seconds()).map(|(a, b)| b - a);
    anyhow::ensure!(health.is_ok(), "{path}: the workload went bad at step {:?}", health.first_bad_step);
    let fluid = backend.fluid_count();
    let rate = steps as f64 * fluid as f64 / seconds;
    let per_step = |total: fn(&crate::model::state::IterationStats) -> u64| match (before, health.iterations) {
        (Some(a), Some(b)) => Some((total(&b) - total(&a)) as f64 / steps as f64),
        _ => None,
    };
    let reference = if scene.physics.solver == PressureSolver::Dfsph { &SPLISHSPLASH_DFSPH[..] } else { &SPLISHSPLASH_WCSPH[..] };
    Ok(BenchRow {
        path: path.into(),
        adapter: backend.adapter(),
        driver: backend.driver(),
        fluid_particles: fluid,
        wall_particles: backend.wall_count(),
        steps,
        seconds,
        particle_steps_per_second: rate,
        cpu_seconds,
        load_average: std::fs::read_to_string("/proc/loadavg").ok().and_then(|s| s.split_whitespace().next()?.parse().ok()),
        bytes_per_fluid_particle: backend.memory_bytes().map(|b| b as f64 / fluid as f64),
        ratio_to_splishsplash: reference.iter().find(|r| r.0 == n).map(|r| rate / r.1),
        pressure_iterations_per_step: per_step(|i| i.pressure.total),
        divergence_iterations_per_step: per_step(|i| i.divergence.total),
    })
}

/// Processor seconds used so far by the threads of this process that are alive: the sum of
/// the first field of each `/proc/self/task/*/schedstat` (nanoseconds on a processor); `None`
/// where there is no such file.
fn process_cpu_seconds() -> Option<f64> {
    let mut total = 0u64;
    for task in std::fs::read_dir("/proc/self/task").ok()? {
        let stat = std::fs::read_to_string(task.ok()?.path().join("schedstat")).ok()?;
        total += stat.split_whitespace().next()?.parse::<u64>().ok()?;
    }
    Some(total as f64 * 1e-9)
}

/// The table `wgsph bench` prints.
pub fn table(rows: &[BenchRow]) -> String {
    let mut s = format!(
        "{:<15} {:<48} {:>8} {:>6} {:>9} {:>12} {:>9} {:>8} {:>13} {:>9} {:>12} {:>6}\n",
        "path", "adapter", "fluid", "steps", "seconds", "p-steps/s", "B/fluid", "x SPH", "iterations", "CPU s", "p-steps/CPUs", "load"
    );
    for r in rows {
        let bytes = r.bytes_per_fluid_particle.map_or("-".into(), |b| format!("{b:.2}"));
        let ratio = r.ratio_to_splishsplash.map_or("-".into(), |x| format!("{x:.2}"));
        let iterations = match (r.pressure_iterations_per_step, r.divergence_iterations_per_step) {
            (Some(p), Some(d)) => format!("{p:.2} + {d:.2}"),
            _ => "-".into(),
        };
        let cpu = r.cpu_seconds.map_or("-".into(), |c| format!("{c:.3}"));
        let per_cpu = r.cpu_seconds.map_or("-".into(), |c| format!("{:.3e}", r.steps as f64 * r.fluid_particles as f64 / c));
        let load = r.load_average.map_or("-".into(), |l| format!("{l:.2}"));
        s += &format!(
            "{:<15} {:<48} {:>8} {:>6} {:>9.3} {:>12.3e} {:>9} {:>8} {:>13} {:>9} {:>12} {:>6}\n",
            r.path, r.adapter, r.fluid_particles, r.steps, r.seconds, r.particle_steps_per_second, bytes, ratio, iterations, cpu, per_cpu, load
        );
    }
    // Two drivers of one adapter share its name (two Mesa releases' llvmpipe, say): each
    // adapter's driver once, under the table.
    let mut drivers: Vec<(&str, &str)> = Vec::new();
    for r in rows.iter().filter(|r| !r.driver.is_empty()) {
        if !drivers.contains(&(r.adapter.as_str(), r.driver.as_str())) {
            drivers.push((&r.adapter, &r.driver));
        }
    }
    for (adapter, driver) in drivers {
        s += &format!("driver of {adapter}: {driver}\n");
    }
    s
}

/// Flags that tune paths `--paths` does not ask for change nothing: refused by name.
fn check_flags_have_paths(args: &BenchArgs) -> Result<(), InputError> {
    let paths = args.paths.iter().map(|p| p.name()).collect::<Vec<_>>().join(",");
    if let Some(twice) = args.paths.iter().enumerate().find(|(i, p)| args.paths[..*i].contains(p)).map(|(_, p)| p) {
        return Err(InputError(format!("--paths {paths} names {} twice; name each path once", twice.name())));
    }
    let has = |wanted: &[BenchPath]| args.paths.iter().any(|p| wanted.contains(p));
    let checks: [(bool, &str, &[BenchPath]); 6] = [
        (args.threads.is_some(), "--threads sets the CPU paths' threads", &[BenchPath::CpuF32, BenchPath::CpuF64, BenchPath::DfsphCpuF32, BenchPath::DfsphCpuF64]),
        (args.every_adapter, "--every-adapter runs the GPU paths on every adapter", &[BenchPath::Gpu, BenchPath::DfsphGpu]),
        (args.no_subgroup_tiles, "--no-subgroup-tiles tunes the GPU paths", &[BenchPath::Gpu, BenchPath::DfsphGpu]),
        (args.no_neighbour_lists, "--no-neighbour-lists tunes the GPU paths", &[BenchPath::Gpu, BenchPath::DfsphGpu]),
        (args.neighbour_skin.is_some(), "--neighbour-skin tunes the weakly compressible GPU path", &[BenchPath::Gpu]),
        (args.solver_loop.is_some(), "--solver-loop tunes DFSPH's GPU path", &[BenchPath::DfsphGpu]),
    ];
    for (given, what, wanted) in checks {
        if given && !has(wanted) {
            let names = wanted.iter().map(|p| p.name()).collect::<Vec<_>>().join(", ");
            return Err(InputError(format!("{what}, and --paths {paths} has no such path ({names}): leave it out or add one")));
        }
    }
    Ok(())
}

pub fn cmd_bench(args: &BenchArgs) -> anyhow::Result<i32> {
    check_flags_have_paths(args)?;
    // An earlier `wgsph bench --out`: a list of rows (a bench measures at least one path),
    // each naming its path and its rate. An empty list is no one's benchmark.
    let ours = |text: &str| {
        serde_json::from_str::<Vec<serde_json::Map<String, serde_json::Value>>>(text)
            .is_ok_and(|rows| !rows.is_empty() && rows.iter().all(|row| row.contains_key("path") && row.contains_key("particle_steps_per_second")))
    };
    let file = args.out.as_deref().map(|p| super::errors::output_file("--out", p, "a benchmark", &ours)).transpose()?;
    if let Some(t) = args.threads {
        // The CPU paths' pool; set once, before any parallel work.
        rayon::ThreadPoolBuilder::new().num_threads(t as usize).build_global().map_err(|e| anyhow::anyhow!("--threads {t}: {e}"))?;
    }
    let (scene, dfsph) = (block_scene(args.n), dfsph_block_scene(args.n));
    println!("{}: {} fluid particles, {} steps of {} s (DFSPH: {} s)", scene.name, scene.fluid_particle_count(), args.steps, scene.time.dt, dfsph.time.dt);
    let mut rows = Vec::new();
    for path in &args.paths {
        let (name, scene) = match path {
            BenchPath::CpuF32 | BenchPath::CpuF64 | BenchPath::Gpu => (path.name(), &scene),
            BenchPath::DfsphCpuF32 | BenchPath::DfsphCpuF64 | BenchPath::DfsphGpu => (path.name(), &dfsph),
        };
        match path {
            BenchPath::CpuF32 | BenchPath::DfsphCpuF32 => rows.push(measure(name, scene, &BackendChoice::cpu(Precision::F32), args.steps, args.n)?),
            BenchPath::CpuF64 | BenchPath::DfsphCpuF64 => rows.push(measure(name, scene, &BackendChoice::cpu(Precision::F64), args.steps, args.n)?),
            BenchPath::Gpu | BenchPath::DfsphGpu => {
                let options = GpuOptions {
                    solver_loop: args.solver_loop.unwrap_or_default(),
                    subgroup_tiles: if args.no_subgroup_tiles { Some(false) } else { None },
                    neighbour_lists: if args.no_neighbour_lists { Some(false) } else { None },
                    // DFSPH records its lists every step: the skin is the weakly compressible path's.
                    neighbour_skin: if *path == BenchPath::Gpu { args.neighbour_skin } else { None },
                    ..Default::default()
                };
                let adapters = if args.every_adapter { compute_adapters() } else { Vec::new() };
                if adapters.is_empty() {
                    rows.push(measure(name, scene, &BackendChoice::gpu().with_gpu_options(options), args.steps, args.n)?);
                }
                for a in adapters {
                    // A listed adapter that cannot open a device is passed over with a word.
                    match GpuContext::from_adapter(a) {
                        Ok(ctx) => rows.push(measure(name, scene, &BackendChoice::gpu_on(ctx).with_gpu_options(options), args.steps, args.n)?),
                        Err(e) => eprintln!("warning: passed over: {e:#}"),
                    }
                }
            }
        }
    }
    print!("{}", table(&rows));
    let ran = |paths: &[BenchPath]| args.paths.iter().any(|p| paths.contains(p));
    if SPLISHSPLASH_WCSPH.iter().any(|r| r.0 == args.n) && ran(&[BenchPath::CpuF32, BenchPath::CpuF64, BenchPath::Gpu]) {
        println!("x SPH: over SPlisHSPlasH 2.16 WCSPH on the same workload (2 cores, AVX2; docs/performance.md)");
    }
    if SPLISHSPLASH_DFSPH.iter().any(|r| r.0 == args.n) && ran(&[BenchPath::DfsphCpuF32, BenchPath::DfsphCpuF64, BenchPath::DfsphGpu]) {
        let (p, d) = SPLISHSPLASH_DFSPH_ITERATIONS;
        println!("x SPH of the dfsph paths: over SPlisHSPlasH 2.16 DFSPH ({p} + {d} iterations per step; docs/dfsph.md)");
    }
    if let Some(mut file) = file {
        let path = file.path().to_path_buf();
        let json = serde_json::to_string_pretty(&rows)?;
        writeln!(file, "{json}").with_context(|| format!("cannot write {}", path.display()))?;
        file.commit()?;
        println!("wrote {}", path.display());
    }
    Ok(0)
}
