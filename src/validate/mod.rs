//! `wgsph validate`: the simulator against measurements and exact solutions.
//!
//! Every case builds its scenes in code (so that one description serves every resolution), runs
//! them on the backend the caller supplies (the GPU path in the command and in the tests),
//! samples the state, writes a PNG plot and a CSV of the simulated series, and returns error
//! figures, each with the tolerance it is judged against. The tolerances are stated in the
//! README; `Resolution::Coarse` (the test suite's) has looser ones.

pub mod conservation;
pub mod dam_break;
pub mod data;
pub mod hydrostatic;
pub mod scenes;
pub mod sloshing;

use crate::cli::{BackendChoice, InputError};
use crate::output::write_atomic;
use crate::scene::{InitialState, Params, Scene, SolidRegion};
use crate::sim::{Backend, Snapshot};
use clap::{Args, ValueEnum};
use std::path::{Path, PathBuf};

#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum)]
pub enum Resolution {
    /// The test suite's: about 2 k particles per case, looser tolerances.
    Coarse,
    /// `wgsph validate`'s: a few minutes for all cases on a software adapter.
    Default,
    /// Twice the default's linear resolution (8x the particles).
    Fine,
}

impl Resolution {
    pub fn name(self) -> &'static str {
        match self {
            Resolution::Coarse => "coarse",
            Resolution::Default => "default",
            Resolution::Fine => "fine",
        }
    }
    /// Linear refinement relative to the default resolution.
    pub fn refinement(self) -> f64 {
        match self {
            Resolution::Coarse => 0.5,
            Resolution::Default => 1.0,
            Resolution::Fine => 2.0,
        }
    }
}

#[derive(Copy, Clone, Debug, PartialEq, Eq, ValueEnum)]
pub enum Case {
    Hydrostatic,
    DamBreakMartinMoyce,
    DamBreakKoshizukaOka,
    Conservation,
}

impl Case {
    pub const ALL: [Case; 4] = [Case::Hydrostatic, Case::DamBreakMartinMoyce, Case::DamBreakKoshizukaOka, Case::Conservation];
    pub fn name(self) -> &'static str {
        match self {
            Case::Hydrostatic => "hydrostatic",
            Case::DamBreakMartinMoyce => "dam_break_martin_moyce",
            Case::DamBreakKoshizukaOka => "dam_break_koshizuka_oka",
            Case::Conservation => "conservation",
        }
    }
    pub fn from_name(name: &str) -> Option<Case> {
        Case::ALL.into_iter().find(|c| c.name() == name)
    }
}

/// One error figure of a case and the tolerance it must stay within (value <= tolerance).
#[derive(Clone, Debug, PartialEq)]
pub struct Figure {
    pub name: String,
    pub value: f64,
    pub tolerance: f64,
}

impl Figure {
    pub fn new(name: impl Into<String>, value: f64, tolerance: f64) -> Self {
        Figure { name: name.into(), value, tolerance }
    }
    /// NaN never passes.
    pub fn passed(&self) -> bool {
        self.value <= self.tolerance
    }
}

/// What a case found.
#[derive(Clone, Debug)]
pub struct CaseReport {
    pub case: Case,
    pub resolution: Resolution,
    pub fluid_particles: usize,
    pub adapter: String,
    pub figures: Vec<Figure>,
    /// Fluid particles found inside a solid region, summed over the checked steps.
    pub wall_leaks: u64,
    /// Steps at which the leak count was checked.
    pub checked_steps: Vec<u64>,
    /// The deepest a fluid particle came past a wall's face, in particle spacings.
    pub deepest_spacings: f64,
    pub plot: PathBuf,
    pub csv: PathBuf,
    pub wall_seconds: f64,
    /// Why the run failed before it could be judged (a blow-up, an escaped particle).
    pub failure: Option<String>,
}

impl CaseReport {
    pub fn passed(&self) -> bool {
        self.failure.is_none() && self.wall_leaks == 0 && !self.figures.is_empty() && self.figures.iter().all(Figure::passed)
    }
    pub fn figure(&self, name: &str) -> Option<&Figure> {
        self.figures.iter().find(|f| f.name == name)
    }
    /// The case's row of validation.md.
    pub fn markdown_row(&self) -> String {
        let figs: Vec<String> = self
            .figures
            .iter()
            // A '|' would end the table cell.
            .map(|f| format!("{} = {} (<= {}{})", f.name.replace('|', "\\|"), fmt_num(f.value), fmt_num(f.tolerance), if f.passed() { "" } else { ", FAILED" }))
            .collect();
        let mut notes = figs.join("; ");
        notes += &format!(
            "; fluid particles inside walls: {} over {} checked steps (deepest past a face: {} spacings)",
            self.wall_leaks,
            self.checked_steps.len(),
            fmt_num(self.deepest_spacings)
        );
        if let Some(f) = &self.failure {
            notes += &format!("; run failed: {f}");
        }
        format!(
            "| {} | {} | {} | {} | {} | {:.0} s | {} |",
            self.case.name(),
            self.resolution.name(),
            self.fluid_particles,
            notes,
            if self.passed() { "pass" } else { "FAIL" },
            self.wall_seconds,
            self.plot.file_name().map(|n| n.to_string_lossy().to_string()).unwrap_or_default()
        )
    }
}

pub fn fmt_num(v: f64) -> String {
    if v == 0.0 {
        "0".into()
    } else if !v.is_finite() {
        format!("{v}")
    } else if v.abs() >= 0.01 && v.abs() < 1e4 {
        format!("{v:.4}").trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        format!("{v:.2e}")
    }
}

/// Makes a backend for a scene's parameters and initial particles (the GPU path, or the CPU).
pub type MakeBackend<'a> = dyn FnMut(&Params, &InitialState) -> anyhow::Result<Box<dyn Backend>> + 'a;

/// How deep (in particle spacings) a fluid particle must be inside a solid region to count as a
/// leak: far below any real penetration, above the f32 rounding of a particle put back on a plane.
pub const LEAK_DEPTH_SPACINGS: f64 = 1e-3;

/// Fluid particles deeper than `depth` inside any of the solid regions.
pub fn particles_inside_solids(positions: &[[f64; 3]], solids: &[SolidRegion], depth: f64) -> u64 {
    positions
        .iter()
        .filter(|x| solids.iter().any(|r| (0..3).all(|a| x[a] > r.min[a] + depth && x[a] < r.max[a] - depth)))
        .count() as u64
}

/// How deep a point lies inside a solid region (0 when outside).
pub fn depth_inside(x: [f64; 3], r: &SolidRegion) -> f64 {
    (0..3).map(|a| (x[a] - r.min[a]).min(r.max[a] - x[a])).fold(f64::INFINITY, f64::min).max(0.0)
}

/// Steps a backend to each of `sample_steps` (increasing), checking health and leaks at every
/// one, and hands each snapshot to `visit`. Returns the leaks, the checked steps, and a failure.
pub struct Sampler {
    pub solids: Vec<SolidRegion>,
    pub leak_depth: f64,
    pub wall_leaks: u64,
    /// The deepest any fluid particle was inside a solid region, at any checked step.
    pub deepest: f64,
    pub checked_steps: Vec<u64>,
}

impl Sampler {
    pub fn new(scene: &Scene) -> Self {
        Sampler {
            solids: scene.solid_regions(),
            leak_depth: LEAK_DEPTH_SPACINGS * scene.physics.particle_spacing,
            wall_leaks: 0,
            deepest: 0.0,
            checked_steps: Vec::new(),
        }
    }

    /// Runs to every step of `sample_steps` and calls `visit` with the snapshot there.
    pub fn run(
        &mut self,
        backend: &mut dyn Backend,
        sample_steps: impl IntoIterator<Item = u64>,
        mut visit: impl FnMut(&Snapshot),
    ) -> anyhow::Result<Result<(), String>> {
        for target in sample_steps {
            let now = backend.steps_done();
            if target > now {
                backend.step(target - now)?;
            }
            let health = backend.health()?;
            if !health.is_ok() {
                let s = backend.snapshot().map(|s| s.max_speed()).unwrap_or(f64::NAN);
                return Ok(Err(crate::run::diagnose(backend.params(), &health, s)));
            }
            let snap = backend.snapshot()?;
            self.wall_leaks += particles_inside_solids(&snap.positions, &self.solids, self.leak_depth);
            for x in &snap.positions {
                for r in &self.solids {
                    self.deepest = self.deepest.max(depth_inside(*x, r));
                }
            }
            self.checked_steps.push(snap.step);
            visit(&snap);
        }
        Ok(Ok(()))
    }
}

/// Runs one case, writing `out/CASE.png` and `out/CASE.csv`.
pub fn run_case(case: Case, resolution: Resolution, out: &Path, make: &mut MakeBackend) -> anyhow::Result<CaseReport> {
    std::fs::create_dir_all(out)?;
    let t0 = std::time::Instant::now();
    let mut report = match case {
        Case::Hydrostatic => hydrostatic::run(resolution, out, make)?,
        Case::DamBreakMartinMoyce => dam_break::run_martin_moyce(resolution, out, make)?,
        Case::DamBreakKoshizukaOka => dam_break::run_koshizuka_oka(resolution, out, make)?,
        Case::Conservation => conservation::run(resolution, out, make)?,
    };
    report.wall_seconds = t0.elapsed().as_secs_f64();
    Ok(report)
}

/// Writes `out/validation.md`: one table row per case.
pub fn write_markdown(out: &Path, reports: &[CaseReport]) -> anyhow::Result<()> {
    write_atomic(&out.join("validation.md"), |w| {
        writeln!(w, "# Validation")?;
        writeln!(w)?;
        if let Some(r) = reports.first() {
            writeln!(w, "Backend: {}.", r.adapter)?;
            writeln!(w)?;
        }
        writeln!(w, "| case | resolution | fluid particles | error figures (tolerance) | result | time | plot |")?;
        writeln!(w, "|---|---|---|---|---|---|---|")?;
        for r in reports {
            writeln!(w, "{}", r.markdown_row())?;
        }
        Ok(())
    })
}

/// Writes a CSV with a header and rows of numbers, atomically.
pub fn write_csv(path: &Path, header: &[&str], rows: &[Vec<f64>]) -> anyhow::Result<()> {
    write_atomic(path, |w| {
        writeln!(w, "{}", header.join(","))?;
        for r in rows {
            let cells: Vec<String> = r.iter().map(|v| if v.is_finite() { format!("{v}") } else { String::new() }).collect();
            writeln!(w, "{}", cells.join(","))?;
        }
        Ok(())
    })
}

#[derive(Args, Debug, Clone)]
pub struct ValidateArgs {
    /// A case (hydrostatic, dam_break_martin_moyce, dam_break_koshizuka_oka, conservation) or `all`.
    #[arg(default_value = "all")]
    pub case: String,
    /// Output directory: CASE.png, CASE.csv per case and validation.md.
    #[arg(long, default_value = "validation")]
    pub out: PathBuf,
    #[arg(long, value_enum, default_value_t = Resolution::Default)]
    pub resolution: Resolution,
    /// The GPU path by default (the CPU when no adapter exists, with a warning).
    #[arg(long, value_enum, default_value_t = BackendChoice::Auto)]
    pub backend: BackendChoice,
}

/// `wgsph validate`: exit code 0 when every case passed, 1 when one failed, 2 for bad input.
pub fn cmd_validate(args: &ValidateArgs) -> anyhow::Result<i32> {
    let cases: Vec<Case> = if args.case == "all" {
        Case::ALL.to_vec()
    } else {
        match Case::from_name(&args.case) {
            Some(c) => vec![c],
            None => {
                let names: Vec<&str> = Case::ALL.iter().map(|c| c.name()).collect();
                return Err(InputError(format!("case '{}' is not known; allowed: {} or all", args.case, names.join(", "))).into());
            }
        }
    };
    // Probe once: with no adapter, `auto` warns once and runs every case on the CPU.
    let choice = match args.backend {
        BackendChoice::Auto if crate::gpu::device::compute_adapters().is_empty() => {
            eprintln!("warning: no GPU adapter with compute shaders was found; validating the cpu backend");
            BackendChoice::Cpu
        }
        c => c,
    };
    let mut make = |params: &Params, initial: &InitialState| make_backend_from(params, initial, choice);
    let mut reports = Vec::new();
    for case in cases {
        eprintln!("validate: {} ({} resolution) ...", case.name(), args.resolution.name());
        let r = run_case(case, args.resolution, &args.out, &mut make)?;
        println!("{}: {} ({:.0} s)", case.name(), if r.passed() { "pass" } else { "FAIL" }, r.wall_seconds);
        for f in &r.figures {
            println!("  {} = {} (tolerance {}){}", f.name, fmt_num(f.value), fmt_num(f.tolerance), if f.passed() { "" } else { "  FAILED" });
        }
        println!("  fluid particles inside walls: {} over {} checked steps", r.wall_leaks, r.checked_steps.len());
        if let Some(f) = &r.failure {
            println!("  run failed: {f}");
        }
        reports.push(r);
        write_markdown(&args.out, &reports)?;
    }
    let ok = reports.iter().all(CaseReport::passed);
    println!("validate: {} -> {}", if ok { "all passed" } else { "FAILED" }, args.out.join("validation.md").display());
    Ok(if ok { 0 } else { 1 })
}

/// A backend for explicit parameters and particles (`cli::make_backend` takes a scene).
pub fn make_backend_from(params: &Params, initial: &InitialState, choice: BackendChoice) -> anyhow::Result<Box<dyn Backend>> {
    use crate::cpu::CpuSolver;
    use crate::gpu::{GpuContext, GpuSolver};
    match choice {
        BackendChoice::Cpu => Ok(Box::new(CpuSolver::<f64>::new(params, initial))),
        BackendChoice::Gpu => Ok(Box::new(GpuSolver::new(GpuContext::new()?, params, initial)?)),
        BackendChoice::Auto => match GpuContext::new() {
            Ok(ctx) => Ok(Box::new(GpuSolver::new(ctx, params, initial)?)),
            Err(e) => {
                eprintln!("warning: {e:#}; falling back to the cpu backend");
                Ok(Box::new(CpuSolver::<f64>::new(params, initial)))
            }
        },
    }
}
