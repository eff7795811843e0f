//! `wgsph tradeoff`: the Pareto front, the sample times, and a small study end to end.

use std::process::Command;
use wgsph::app::tradeoff::pareto_of;
use wgsph::app::tradeoff::sample_times;

#[test]
fn the_pareto_front_holds_exactly_the_undominated_points() {
    // (cost, error): (2, 5) is beaten by (1, 4); (3, 3) and (3, 4): the latter is beaten.
    let marks = pareto_of(&[(1.0, 4.0), (2.0, 5.0), (3.0, 3.0), (3.0, 4.0), (10.0, 0.5), (0.5, 9.0)]);
    assert_eq!(marks, vec![true, false, true, false, true, true]);
    // Equal points do not dominate each other.
    assert_eq!(pareto_of(&[(1.0, 1.0), (1.0, 1.0)]), vec![true, true]);
}

#[test]
fn sample_times_fall_on_whole_even_numbers_of_base_steps_and_end_at_the_run_end() {
    let dt = 2.5e-4;
    let t = sample_times(dt, 0.4, 20);
    assert_eq!(t.len(), 20);
    assert!((t.last().unwrap() - 0.4).abs() < 1e-12);
    for w in t.windows(2) {
        let steps = (w[1] - w[0]) / dt;
        assert!(w[1] > w[0]);
        assert!((steps - steps.round()).abs() < 1e-6 && (steps.round() as u64) % 2 == 0 || w[1] == *t.last().unwrap(), "{w:?}");
    }
    // More samples than steps: one per pair of steps at most.
    let t = sample_times(0.1, 0.3, 100);
    assert_eq!(t.len(), 2);
}

#[test]
fn a_study_leaves_out_the_knobs_its_scene_does_not_use() {
    use wgsph::app::tradeoff::configs;
    use wgsph::model::scene::{Boundary, PressureSolver, Scene};
    let names = |scene: &Scene| configs(scene).into_iter().map(|c| c.name).collect::<Vec<_>>();
    // The dam break has planes and runs weakly compressible: every knob changes it.
    let dam_break = Scene::builtin("dam_break").unwrap();
    let all = names(&dam_break);
    assert!(all.iter().any(|n| n == "no planes") && all.iter().any(|n| n == "dfsph 0.01%"), "{all:?}");
    // Without its planes, and with DFSPH at the default tolerance: no row that would run the
    // baseline again, the other tolerances still there.
    let mut dfsph = wgsph::app::tradeoff::with_dfsph(&dam_break, 1e-4);
    dfsph.boundary.retain(|b| !matches!(b, Boundary::Plane { .. }));
    assert_eq!(dfsph.physics.solver, PressureSolver::Dfsph);
    let some = names(&dfsph);
    for left_out in ["no planes", "dfsph 0.01%"] {
        assert!(!some.iter().any(|n| n == left_out), "{left_out}: {some:?}");
    }
    for kept in ["baseline (gpu f32)", "cpu f64", "cpu f32", "dfsph 0.1%", "dfsph 1%", "no wall particles"] {
        assert!(some.iter().any(|n| n == kept), "{kept}: {some:?}");
    }
    for c in configs(&dfsph).iter().filter(|c| !matches!(c.knob, "baseline" | "precision")) {
        assert!(c.scene != dfsph || c.engine != wgsph::app::tradeoff::Engine::Gpu, "{} runs the baseline again", c.name);
    }
    // The seed scene's viscosity schedule cannot run with adaptive dt, and without wall
    // particles the wall pressure models change nothing: both left out, every row valid.
    let seed = Scene::builtin("seed").unwrap();
    let seeds = names(&seed);
    assert!(!seeds.iter().any(|n| n == "adaptive dt") && seeds.iter().any(|n| n == "dt x2"), "{seeds:?}");
    let mut planes_only = dam_break.clone();
    planes_only.boundary.retain(|b| matches!(b, Boundary::Plane { .. }));
    assert!(!names(&planes_only).iter().any(|n| n.starts_with("wall pressure")), "{:?}", names(&planes_only));
    for scene in [&dam_break, &seed, &planes_only, &dfsph] {
        for c in configs(scene) {
            assert!(c.scene.validate(&wgsph::model::scene::SceneOrigin::Text).is_ok(), "{}", c.name);
        }
    }
}

#[test]
fn a_small_study_writes_the_table_and_the_plot() {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_wgsph"))
        .args(["tradeoff", "dam_break", "--particles", "300", "--time", "0.02", "--samples", "4", "--out", "study"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    // Marked as a report's directory, which the next study may write into again.
    assert!(dir.path().join("study/.wgsph-report").is_file());
    wgsph::io::rundir::prepare_report_dir("--out", &dir.path().join("study")).unwrap();
    let md = std::fs::read_to_string(dir.path().join("study/tradeoff.md")).unwrap();
    let rows: Vec<&str> = md.lines().filter(|l| l.starts_with("| ") && !l.starts_with("| configuration")).collect();
    // The reference and one row per configuration, each with its knob.
    assert_eq!(rows.len(), 30, "{md}");
    for knob in [
        "reference",
        "baseline",
        "precision",
        "time step",
        "resolution",
        "kernel",
        "equation of state",
        "stiffness",
        "neighbour grid",
        "model term",
        "density",
        "density diffusion",
        "initial state",
        "viscosity model",
        "boundary pressure",
        "dfsph tolerance",
    ] {
        assert!(rows.iter().any(|r| r.split('|').nth(2).unwrap().trim() == knob), "no row for {knob}:\n{md}");
    }
    assert!(rows[0].contains("0 (reference)"));
    // At least one configuration is on the Pareto front, and a finer time step is more exact
    // than a coarser one.
    assert!(rows.iter().any(|r| r.trim_end().ends_with("| yes |")), "{md}");
    let front_error = |name: &str| -> f64 {
        let r = rows.iter().find(|r| r.starts_with(&format!("| {name} |"))).unwrap();
        r.split('|').nth(10).unwrap().trim().parse().unwrap()
    };
    assert!(front_error("dt x0.5") <= front_error("dt x2"), "{md}");
    // DFSPH at each tolerance ran to the end, with steps longer than the base scene's.
    let mean_dt = |r: &str| -> f64 { r.split('|').nth(5).unwrap().trim().parse().unwrap() };
    let baseline = rows.iter().find(|r| r.starts_with("| baseline")).unwrap();
    for tolerance in ["0.01%", "0.1%", "1%"] {
        let r = rows.iter().find(|r| r.starts_with(&format!("| dfsph {tolerance} |"))).unwrap_or_else(|| panic!("no dfsph {tolerance} row:\n{md}"));
        assert!(!r.contains("failed"), "{r}");
        assert!(mean_dt(r) > mean_dt(baseline), "{r}");
    }
    let png = image::open(dir.path().join("study/tradeoff.png")).unwrap();
    assert_eq!((png.width(), png.height()), (1200, 800));
    // Bad input: exit 2 naming the flag.
    let out = Command::new(env!("CARGO_BIN_EXE_wgsph")).args(["tradeoff", "--time=0"]).current_dir(dir.path()).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--time"));
    // A time shorter than the coarsest configuration's step leaves nothing to measure.
    let out = Command::new(env!("CARGO_BIN_EXE_wgsph")).args(["tradeoff", "hydrostatic", "--time", "1e-300", "--out", "short"]).current_dir(dir.path()).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("--time is 1e-300 s; must be at least two of the scene's time steps (2 x time.dt = 0.0006 s)"), "{err}");
    assert!(!dir.path().join("short").exists());
}

/// `tradeoff` and `validate` write only into a new or empty directory, or one such a command
/// wrote (its `.wgsph-report`): a folder of the user's, even one holding a `tradeoff.md`, is
/// refused before any work and left as it was.
#[test]
fn report_commands_refuse_a_folder_of_the_users() {
    let dir = tempfile::tempdir().unwrap();
    let mine = dir.path().join("mine");
    std::fs::create_dir(&mine).unwrap();
    std::fs::write(mine.join("tradeoff.md"), "my notes").unwrap();
    std::fs::write(mine.join("validation.md"), "my notes").unwrap();
    let plain = dir.path().join("file");
    std::fs::write(&plain, "mine").unwrap();
    for args in [&["tradeoff", "hydrostatic", "--time", "0.001", "--samples", "1"][..], &["validate", "hydrostatic", "--resolution", "coarse"][..]] {
        for (out, says) in [("mine", "the directory is not empty (it holds tradeoff.md, validation.md (2 entries)) and no wgsph report was written there"), ("file", "is a file, not a directory")] {
            let o = Command::new(env!("CARGO_BIN_EXE_wgsph")).args(args).args(["--out", out]).current_dir(dir.path()).output().unwrap();
            let err = String::from_utf8_lossy(&o.stderr);
            assert_eq!(o.status.code(), Some(2), "{args:?} {out}: {err}");
            assert!(err.contains(&format!("--out {out}: {says}")), "{args:?}: {err}");
        }
    }
    assert_eq!(std::fs::read_to_string(mine.join("tradeoff.md")).unwrap(), "my notes");
    assert_eq!(std::fs::read_dir(&mine).unwrap().count(), 2);
    assert_eq!(std::fs::read_to_string(&plain).unwrap(), "mine");
}
