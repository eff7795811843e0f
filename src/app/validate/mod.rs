//! `wgsph validate`: the simulator against measurements and exact solutions.
//!
//! Every case builds its scenes in code (so that one description serves every resolution), runs
//! them on the backend the caller supplies (the GPU path in the command and in the tests),
//! samples the state, writes a PNG plot and a CSV of the simulated series, and returns error
//! figures, each with the tolerance it is judged against. The tolerances are stated in
//! docs/validation.md; `Resolution::Coarse` (the test suite's) has looser ones.

pub mod buchner;
pub mod case;
pub mod conservation;
pub mod dam_break;
pub mod data;
pub mod hydrostatic;
pub mod scenes;
pub mod sloshing;

pub use case::{Case, CaseReport, Figure, MakeBackend, Resolution};

use super::args::ValidateArgs;
use super::errors::InputError;
use crate::io::atomic::write_atomic;
use crate::model::initial::InitialState;
use crate::model::scene::Scene;
use crate::solver::{open_with, BackendChoice, Device, Precision};
use case::fmt_num;
use std::path::Path;

/// Runs one case, writing `out/CASE.png` and `out/CASE.csv`.
pub fn run_case(case: Case, resolution: Resolution, out: &Path, make: &mut MakeBackend) -> anyhow::Result<CaseReport> {
    std::fs::create_dir_all(out)?;
    let t0 = std::time::Instant::now();
    let mut report = match case {
        Case::Hydrostatic | Case::HydrostaticDfsph | Case::HydrostaticDiffusion => hydrostatic::run(case, resolution, out, make)?,
        Case::DamBreakMartinMoyce | Case::DamBreakMartinMoyceDfsph => dam_break::run_martin_moyce(case, resolution, out, make)?,
        Case::DamBreakKoshizukaOka | Case::DamBreakKoshizukaOkaDfsph => dam_break::run_koshizuka_oka(case, resolution, out, make)?,
        Case::Conservation => conservation::run(resolution, out, make)?,
        Case::BuchnerP1 => buchner::run(resolution, out, make)?,
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
    crate::io::rundir::prepare_report_dir("--out", &args.out)?;
    // `auto` is resolved once, and said once, for every case.
    let device = match args.backend.device() {
        Device::Auto => {
            let (device, why) = crate::solver::simulation::auto_device();
            match device {
                Device::Cpu => eprintln!("validate: the CPU path in f64: {why}"),
                _ => eprintln!("validate: {why}"),
            }
            device
        }
        d => d,
    };
    let choice = BackendChoice { device, precision: Precision::F64, ..Default::default() };
    let mut make = |scene: &Scene, initial: Option<InitialState>| Ok(open_with(scene, initial, &choice)?.into_backend());
    let mut reports = Vec::new();
    for case in cases {
        eprintln!("validate: {} ({} resolution) ...", case.name(), args.resolution.name());
        let r = run_case(case, args.resolution, &args.out, &mut make)?;
        println!("{}: {} ({:.0} s)", case.name(), if r.passed() { "pass" } else { "FAIL" }, r.wall_seconds);
        for f in &r.figures {
            println!("  {} = {} ({}){}", f.name, fmt_num(f.value), f.bound(), if f.passed() { "" } else { "  FAILED" });
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
