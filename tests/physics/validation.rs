//! The validation cases at the coarse resolution, on the GPU path (the CPU path where there is
//! no adapter), against the coarse tolerances stated in docs/validation.md. Each case runs on
//! one adapter: the first found, and the hydrostatic case on the last, so that both of CI's
//! Mesa adapters carry a whole case (OpenGL's llvmpipe steps about three times slower than
//! Vulkan's lavapipe). What a case would add on a second adapter (the same WGSL through another
//! driver) the shorter tests and tests/parity check on every adapter, and running every case on
//! each would take the suite past its time budget (docs/testing.md).

use crate::common;

use wgsph::model::initial::InitialState;
use wgsph::model::scene::Scene;
use wgsph::solver::gpu::GpuContext;
use wgsph::solver::{open_with, Backend, BackendChoice, Precision};
use wgsph::app::validate::case::particles_inside_solids;
use wgsph::app::validate::run_case;
use wgsph::app::validate::write_markdown;
use wgsph::app::validate::Case;
use wgsph::app::validate::CaseReport;
use wgsph::app::validate::Resolution;

/// Which of the adapters found a case runs on (the same one where only one is found).
#[derive(Clone, Copy)]
enum Adapters {
    First,
    Last,
}

/// The adapter chosen, or `None` (the CPU path) where there is none.
fn chosen_adapter(which: Adapters) -> Option<wgpu::Adapter> {
    let mut contexts = common::contexts();
    let ctx = match which {
        Adapters::First => contexts.into_iter().next(),
        Adapters::Last => contexts.pop(),
    };
    ctx.map(|c| c.adapter)
}

/// A backend for `scene` on `adapter` (a device of its own), or on the f64 CPU path.
fn open_on(adapter: Option<&wgpu::Adapter>, scene: &Scene, init: Option<InitialState>) -> anyhow::Result<Box<dyn Backend>> {
    let choice = match adapter {
        Some(a) => BackendChoice::gpu_on(GpuContext::from_adapter(a.clone())?),
        None => BackendChoice::cpu(Precision::F64),
    };
    Ok(open_with(scene, init, &choice)?.into_backend())
}

/// Runs `case` on the adapter chosen (or the CPU when there is none) and returns the backend's
/// name, the report and the directory it wrote.
fn run_on(case: Case, which: Adapters) -> (String, CaseReport, tempfile::TempDir) {
    let adapter = chosen_adapter(which);
    let dir = tempfile::tempdir().unwrap();
    let r = run_case(case, Resolution::Coarse, dir.path(), &mut |scene, init| open_on(adapter.as_ref(), scene, init)).unwrap();
    let name = adapter.as_ref().map(|a| format!("{:?}", a.get_info().backend)).unwrap_or_else(|| "cpu".into());
    eprintln!("{} on {name}: {}", case.name(), r.markdown_row());
    (name, r, dir)
}

fn check_outputs(r: &CaseReport, dir: &std::path::Path) {
    let png = image::open(&r.plot).expect("the plot is a PNG");
    assert!(png.width() >= 600 && png.height() >= 400);
    let csv = std::fs::read_to_string(&r.csv).unwrap();
    assert!(csv.lines().count() > 5, "{}", r.csv.display());
    write_markdown(dir, std::slice::from_ref(r)).unwrap();
    let md = std::fs::read_to_string(dir.join("validation.md")).unwrap();
    assert!(md.contains(&format!("| {} | coarse |", r.case.name())), "{md}");
}

fn assert_passed_on(case: Case, which: Adapters) -> (String, CaseReport, tempfile::TempDir) {
    let (backend, r, dir) = run_on(case, which);
    assert!(r.failure.is_none(), "{} on {backend}: {:?}", case.name(), r.failure);
    for f in &r.figures {
        assert!(f.passed(), "{} on {backend}: {} = {} over the tolerance {}", case.name(), f.name, f.value, f.tolerance);
    }
    assert_eq!(r.wall_leaks, 0, "{} on {backend}: fluid particles inside walls", case.name());
    assert!(r.passed());
    check_outputs(&r, dir.path());
    (backend, r, dir)
}

#[test]
fn hydrostatic_pressure_matches_rho_g_depth() {
    assert_passed_on(Case::Hydrostatic, Adapters::Last);
}

#[test]
fn martin_moyce_front_and_height() {
    assert_passed_on(Case::DamBreakMartinMoyce, Adapters::First);
}

/// Also the walls test: the front reaches the far wall (the impact) and at every checked step,
/// every 5 ms through and after the impact, no fluid particle is inside a wall.
#[test]
fn koshizuka_oka_front_and_walls_that_hold_through_the_impact() {
    let (backend, r, _dir) = assert_passed_on(Case::DamBreakKoshizukaOka, Adapters::First);
    let csv = std::fs::read_to_string(&r.csv).unwrap();
    let rows: Vec<Vec<f64>> = csv.lines().skip(1).map(|l| l.split(',').map(|v| v.parse().unwrap()).collect()).collect();
    let impact = rows.iter().find(|r| r[1] >= 3.9).map(|r| r[0]).expect("the front reaches the far wall");
    let after: Vec<_> = rows.iter().filter(|r| r[0] > impact).collect();
    assert!(after.len() >= 10, "{backend}: {} samples after the impact at t = {impact}", after.len());
    assert!(r.checked_steps.len() >= rows.len() - 1, "{backend}: every sample is a checked step");
    assert_eq!(r.wall_leaks, 0);
}

/// Also the sloshing tank: with the consistent wall pressure its energy never rises and decays
/// faster with more viscosity; with the mirrored one (the CSV's fifth column) it rises.
#[test]
fn conservation_of_mass_momentum_and_energy() {
    let (backend, r, _dir) = assert_passed_on(Case::Conservation, Adapters::First);
    for name in ["sloshing: largest rise of E above E(0) / K(0)", "sloshing: largest change without viscosity / K(0)"] {
        assert!(r.figure(name).is_some(), "{backend}: no figure {name}");
    }
    let csv = std::fs::read_to_string(&r.csv).unwrap();
    assert!(csv.lines().next().unwrap().split(',').nth(4) == Some("dE_over_K0_mirrored_walls_alpha_0"));
    let mirrored_rise = csv.lines().skip(1).filter_map(|l| l.split(',').nth(4).unwrap().parse::<f64>().ok()).fold(f64::MIN, f64::max);
    assert!(mirrored_rise > 1.0, "{backend}: with mirrored wall pressure the energy rose by only {mirrored_rise} K(0)");
}

/// The wall pressure at Buchner's P1 through a point probe on the wall (Adami wall pressure,
/// continuity density with diffusion): the coarse run's guard bounds (docs/validation.md).
#[test]
fn buchner_p1_wall_pressure() {
    let (backend, r, _dir) = assert_passed_on(Case::BuchnerP1, Adapters::First);
    let csv = std::fs::read_to_string(&r.csv).unwrap();
    // Every step sampled, from t = 0 past the last measured time, 7.3 sqrt(H/g).
    let rows: Vec<Vec<f64>> = csv.lines().skip(1).map(|l| l.split(',').map(|v| v.parse().unwrap()).collect()).collect();
    assert!(rows.len() > 1000 && rows.last().unwrap()[1] > 7.3, "{backend}: {} rows", rows.len());
    // Dry before the surge arrives.
    assert!(rows.iter().filter(|r| r[1] < 2.0).all(|r| r[2] == 0.0 && r[4] == 0.0), "{backend}: pressure on the wall before the surge");
    // The surge wets the wall from the floor up: 0.2 H (0.12 m) no later than P1 (0.16 m).
    let first_wet = |column: usize| rows.iter().find(|r| r[column] > 0.0).map(|r| r[1]).unwrap();
    assert!(first_wet(4) <= first_wet(2), "{backend}: 0.2 H wet at {}, P1 at {}", first_wet(4), first_wet(2));
    let lower = r.figure("at 0.2 H: arrival (first p > 0.1 rho g H), t sqrt(g/H)").unwrap();
    assert!(lower.value < r.figure("simulated arrival, t sqrt(g/H)").unwrap().value, "{backend}: {lower:?}");
    // The window's RMS is a weighted mean of its two parts' squares, so it lies between them.
    let rms = |name: &str| r.figure(name).unwrap().value;
    let (first, after) = (rms("RMS difference over the first impact (t sqrt(g/H) < 4) / rho g H (20 ms mean)"), rms("RMS difference after the first impact (t sqrt(g/H) >= 4) / rho g H (20 ms mean)"));
    let whole = rms("RMS difference over the measured window / rho g H (20 ms mean)");
    assert!(first.min(after) <= whole && whole <= first.max(after), "{backend}: {first} {after} {whole}");
}

/// DFSPH in the still tank: the pressure against depth, and the density error within the set
/// tolerance (the figures of the case, docs/validation.md).
#[test]
fn hydrostatic_pressure_with_dfsph() {
    let (backend, r, _dir) = assert_passed_on(Case::HydrostaticDfsph, Adapters::First);
    for name in ["last constant-density solve's average error / set density_error", "largest mean compression over the window / set density_error"] {
        assert!(r.figure(name).is_some_and(|f| f.tolerance.is_finite()), "{backend}: no bounded figure {name}");
    }
}

/// The still tank with continuity density, delta-SPH diffusion and a hydrostatic start, read
/// through its point probes: within 1 % of rho g H, and its pressure noise below that of the
/// same tank without diffusion (the figures of the case, docs/validation.md).
#[test]
fn hydrostatic_pressure_read_by_probes_with_diffusion() {
    let (backend, r, _dir) = assert_passed_on(Case::HydrostaticDiffusion, Adapters::First);
    let probes = r.figure("point-probe pressure error / rho g H").expect("the probes' figure");
    assert!(probes.tolerance <= 0.01 && probes.value > 0.0, "{backend}: {probes:?}");
    let ratio = r.figure("pressure noise with diffusion / without").expect("the noise ratio");
    assert!(ratio.tolerance < 1.0 && ratio.value > 0.0, "{backend}: {ratio:?}");
}

#[test]
fn martin_moyce_front_and_height_with_dfsph() {
    assert_passed_on(Case::DamBreakMartinMoyceDfsph, Adapters::First);
}

#[test]
fn koshizuka_oka_front_with_dfsph() {
    assert_passed_on(Case::DamBreakKoshizukaOkaDfsph, Adapters::First);
}

#[test]
fn the_leak_count_sees_a_particle_inside_a_wall() {
    // The checker itself: a particle inside a container's wall shell is counted, one on the
    // face or in the cavity is not.
    let scene = wgsph::model::scene::Scene::builtin("dam_break").unwrap();
    let solids = scene.solid_regions();
    let depth = 1e-6;
    assert_eq!(particles_inside_solids(&[[0.5, 0.5, 0.05]], &solids, depth), 0);
    assert_eq!(particles_inside_solids(&[[1.6, 0.5, 0.05]], &solids, depth), 0);
    assert_eq!(particles_inside_solids(&[[1.61, 0.5, 0.05], [0.5, -0.01, 0.05], [0.5, 0.5, 0.11]], &solids, depth), 3);
}

/// Wall particles alone, without the planes behind them: at the Koshizuka & Oka impact on the
/// far wall (about 6 m/s) no fluid particle reaches the first layer of wall particles (half a
/// spacing behind the tank's face), at any checked step. Particle centres do cross the nominal
/// face by a fraction of a spacing; the validation scenes add planes on the faces, which keep
/// them on the fluid's side (the other tests: 0 particles inside a solid region).
#[test]
fn wall_particles_alone_stop_every_particle_before_their_first_layer() {
    let mut tank = wgsph::app::validate::dam_break::column_tank("walls_only", 1.0, 4.0, Resolution::Coarse, 0.8);
    tank.planes = false;
    // The first adapter: the walls' hold is the stages' arithmetic, which tests/parity checks
    // on every adapter (docs/testing.md: the suite's time budget).
    let adapter = chosen_adapter(Adapters::First);
    let run = wgsph::app::validate::dam_break::collapse(&tank, 0.005, &mut |scene, init| open_on(adapter.as_ref(), scene, init)).unwrap();
    assert!(run.failure.is_none(), "{:?}", run.failure);
    assert!(run.samples.iter().any(|s| s.front >= 3.9), "the front reaches the far wall");
    assert!(run.sampler.checked_steps.len() >= 150);
    let deepest = run.sampler.deepest / tank.spacing;
    eprintln!("wall particles alone: deepest {deepest:.3} spacings past a face, {} particle-steps past a face", run.sampler.wall_leaks);
    assert!(deepest < 0.5, "a particle reached the first wall layer: {deepest} spacings past the face");
}

#[test]
fn validate_refuses_an_unknown_case_with_exit_code_2() {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_wgsph")).args(["validate", "dam_brake"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("case 'dam_brake' is not known") && err.contains("dam_break_martin_moyce"), "{err}");
}

#[test]
fn the_pressure_noise_is_the_scatter_around_the_moving_mean() {
    use wgsph::app::validate::case::noise_around_moving_mean;
    // A pressure rising steadily (the flow's own change) with +-a alternating on top (the
    // noise), sampled every ms: the noise figure is a, the ramp takes no part in it. Near the
    // ends the centred window is lopsided, so the ramp adds a little there: within 5 %.
    let a = 30.0;
    let series: Vec<(f64, f64)> = (0..2000).map(|i| (i as f64 * 1e-3, 1000.0 + 5e3 * i as f64 * 1e-3 + if i % 2 == 0 { a } else { -a })).collect();
    let noise = noise_around_moving_mean(&series, 0.02);
    assert!((noise - a).abs() < 0.05 * a, "noise {noise}, expected {a}");
    // A steady pressure has none; a single sample gives no figure.
    let steady: Vec<(f64, f64)> = (0..100).map(|i| (i as f64 * 1e-3, 500.0)).collect();
    assert!(noise_around_moving_mean(&steady, 0.02) < 1e-9);
    assert!(noise_around_moving_mean(&[(0.0, 1.0)], 0.02).is_nan());
}
