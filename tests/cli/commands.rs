//! The `wgsph` command end to end: outputs, backends, and a run that blows up.

use crate::common;
use crate::common::TestScene;

use std::path::Path;
use std::process::{Command, Output};
use wgsph::io::snapshot::csv::read_snapshot_csv;
use wgsph::io::summary::Summary;
use wgsph::io::snapshot::csv::SNAPSHOT_HEADER;

fn wgsph(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_wgsph")).args(args).current_dir(dir).output().unwrap()
}

fn summary(dir: &Path) -> Summary {
    serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap()
}

/// The snapshot files of a run (`snapshots/` also holds their index, `index.csv`).
fn snapshot_names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir.join("snapshots"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("step_"))
        .collect();
    v.sort();
    v
}

#[test]
fn run_writes_snapshots_and_a_summary() {
    let dir = tempfile::tempdir().unwrap();
    let out = wgsph(&["run", "hydrostatic", "--steps", "20", "--backend", "cpu", "--out", "o", "--snapshot-every", "10"], dir.path());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let o = dir.path().join("o");
    assert_eq!(snapshot_names(&o), ["step_000000.csv", "step_000010.csv", "step_000020.csv"]);
    let text = std::fs::read_to_string(o.join("snapshots/step_000020.csv")).unwrap();
    assert_eq!(text.lines().next(), Some(SNAPSHOT_HEADER));
    let s = summary(&o);
    assert_eq!((s.scene.as_str(), s.backend.as_str(), s.steps), ("hydrostatic", "cpu", 20));
    assert_eq!(s.fluid_particles, read_snapshot_csv(&o.join("snapshots/step_000020.csv")).unwrap().len());
    assert!(s.wall_particles > 0 && s.particle_steps_per_second > 0.0 && s.max_density_ratio > 0.9);
    assert_eq!((s.nan_count, s.escaped, s.failure), (0, 0, None));
    assert!((s.sim_time - 20.0 * s.dt).abs() < 1e-12);
    let line = String::from_utf8_lossy(&out.stdout);
    assert!(line.contains("hydrostatic") && line.contains("20 steps"), "{line}");
    // No temporary files are left beside the outputs.
    assert!(std::fs::read_dir(&o).unwrap().all(|e| {
        let n = e.unwrap().file_name();
        n == "summary.json" || n == "snapshots" || n == "scene.toml" || n == ".wgsph-run"
    }));
    assert!(snapshot_names_all(&o).iter().all(|n| n.starts_with("step_") || n == "index.csv"));
}

fn snapshot_names_all(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir.join("snapshots")).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect()
}

/// The pictures in a frames directory (it also holds the hidden marker of a run's outputs).
fn picture_names(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).filter(|n| !n.starts_with('.')).collect();
    names.sort();
    names
}

#[test]
fn scenes_lists_the_built_in_scenes() {
    let dir = tempfile::tempdir().unwrap();
    let out = wgsph(&["scenes"], dir.path());
    let text = String::from_utf8_lossy(&out.stdout);
    for name in ["seed", "dam_break", "hydrostatic"] {
        assert!(text.contains(name), "{text}");
    }
    assert!(text.contains("TOML file") && text.contains("SPlisHSPlasH JSON scene"), "{text}");
}

#[test]
fn gpu_run_writes_the_same_outputs_as_cpu() {
    if common::contexts().is_empty() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    for backend in ["cpu", "gpu"] {
        let out = wgsph(&["run", "dam_break", "--steps", "30", "--backend", backend, "--out", backend, "--snapshot-every", "15"], dir.path());
        assert!(out.status.success(), "{backend}: {}", String::from_utf8_lossy(&out.stderr));
    }
    let (c, g) = (dir.path().join("cpu"), dir.path().join("gpu"));
    assert_eq!(snapshot_names(&c), snapshot_names(&g));
    let (sc, sg) = (summary(&c), summary(&g));
    assert_eq!((sc.steps, sc.fluid_particles, sc.wall_particles), (sg.steps, sg.fluid_particles, sg.wall_particles));
    assert_eq!(sg.backend, "gpu");
    // The GPU run keeps the driver that ran it (as an adapter reports it); the CPU run none.
    assert!(common::contexts().iter().any(|c| c.driver() == sg.driver), "{}", sg.driver);
    assert_eq!(sc.driver, "");
    assert!((sc.max_density_ratio - sg.max_density_ratio).abs() < 1e-4);
    let (a, b) = (read_snapshot_csv(&c.join("snapshots/step_000030.csv")).unwrap(), read_snapshot_csv(&g.join("snapshots/step_000030.csv")).unwrap());
    assert_eq!(a.len(), b.len());
    for i in 0..a.len() {
        for k in 0..3 {
            assert!((a.positions[i][k] - b.positions[i][k]).abs() < 1e-5, "particle {i}");
        }
        assert!((a.densities[i] - b.densities[i]).abs() < 1e-3 * a.densities[i], "particle {i}");
    }
}

#[test]
fn a_run_that_blows_up_stops_with_a_diagnosis_and_keeps_its_outputs() {
    let dir = tempfile::tempdir().unwrap();
    // The hydrostatic tank with a time step 30x over its CFL limit.
    let unstable = TestScene::from(wgsph::Scene::builtin("hydrostatic").unwrap()).dt(0.01).build();
    std::fs::write(dir.path().join("unstable.toml"), unstable.to_toml()).unwrap();
    let mut backends = vec!["cpu"];
    if !common::contexts().is_empty() {
        backends.push("gpu");
    }
    for backend in backends {
        let out = wgsph(&["run", "unstable.toml", "--time", "5", "--backend", backend, "--out", backend, "--snapshot-every", "5", "--check-every", "5"], dir.path());
        assert_eq!(out.status.code(), Some(1), "{backend}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains("step") && err.contains("CFL") && err.contains("last good snapshot"), "{backend}: {err}");
        let o = dir.path().join(backend);
        let s = summary(&o);
        let failure = s.failure.expect("the summary records the failure");
        assert!(failure.contains("CFL"));
        assert!(s.steps < 500, "{backend}: detected after {} steps", s.steps);
        // Every snapshot written is finite, the last good one included.
        let last = s.last_snapshot.expect("a last good snapshot");
        assert_eq!(read_snapshot_csv(Path::new(&dir.path().join(&last))).unwrap().non_finite_count(), 0);
        for name in snapshot_names(&o) {
            assert_eq!(read_snapshot_csv(&o.join("snapshots").join(&name)).unwrap().non_finite_count(), 0, "{name}");
        }
    }
}

#[test]
fn particles_option_scales_the_scene() {
    let dir = tempfile::tempdir().unwrap();
    let out = wgsph(&["run", "hydrostatic", "--particles", "500", "--steps", "2", "--backend", "cpu", "--out", "o"], dir.path());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let s = summary(&dir.path().join("o"));
    assert!((350..=650).contains(&s.fluid_particles), "{}", s.fluid_particles);
    let out = wgsph(&["run", "hydrostatic", "--particles", "0"], dir.path());
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn run_writes_frames_of_the_asked_size() {
    let dir = tempfile::tempdir().unwrap();
    if common::contexts().is_empty() {
        return;
    }
    let out = wgsph(
        &["run", "hydrostatic", "--steps", "20", "--out", "o", "--frames", "f", "--frame-every", "10", "--resolution", "160x90", "--style", "surface"],
        dir.path(),
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(picture_names(&dir.path().join("f")), ["frame_00000.png", "frame_00001.png", "frame_00002.png"]);
    let img = image::open(dir.path().join("f/frame_00002.png")).unwrap();
    assert_eq!((img.width(), img.height()), (160, 90));
    assert_eq!(summary(&dir.path().join("o")).frames, 3);
}

#[test]
fn run_writes_frames_of_the_surface_mesh() {
    let dir = tempfile::tempdir().unwrap();
    if common::contexts().is_empty() {
        return;
    }
    let out = wgsph(
        &["run", "hydrostatic", "--steps", "10", "--out", "o", "--frames", "f", "--frame-every", "10", "--resolution", "160x90", "--style", "mesh"],
        dir.path(),
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(picture_names(&dir.path().join("f")), ["frame_00000.png", "frame_00001.png"]);
    let img = image::open(dir.path().join("f/frame_00001.png")).unwrap().to_rgb8();
    assert_eq!((img.width(), img.height()), (160, 90));
    // The fluid is drawn: a good share of the pixels are bluer than the background.
    let blue = img.pixels().filter(|p| p[2] as i32 > p[0] as i32 + 30).count();
    assert!(blue > 160 * 90 / 50, "only {blue} blue pixels");
}

#[cfg(feature = "view")]
#[test]
fn the_viewer_refuses_the_mesh_style() {
    let dir = tempfile::tempdir().unwrap();
    let out = wgsph(&["view", "hydrostatic", "--style", "mesh"], dir.path());
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--style mesh") && err.contains("particles or surface"), "{err}");
}

#[test]
fn bad_picture_options_are_refused_with_what_is_allowed() {
    let dir = tempfile::tempdir().unwrap();
    for (flag, value, expect) in [
        ("--resolution", "1280by720", "WIDTHxHEIGHT"),
        ("--resolution", "4x4", "between 16 and 8192"),
        ("--color-range", "3:1", "MIN < MAX"),
        ("--style", "cartoon", "particles"),
    ] {
        let out = wgsph(&["run", "hydrostatic", "--steps", "1", "--frames", "f", flag, value], dir.path());
        assert_eq!(out.status.code(), Some(2), "{flag} {value}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(expect) && err.contains(flag), "{flag} {value}: {err}");
    }
    assert!(!dir.path().join("f").exists());
    // Without --frames a run draws nothing, so how its pictures look is refused, not ignored.
    let out = wgsph(&["run", "hydrostatic", "--steps", "1", "--color-range", "0:1", "--style", "surface", "--out", "o"], dir.path());
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--style, --color-range set how the pictures look, and this run draws none: add --frames DIR"), "{err}");
    assert!(!dir.path().join("o").exists());
}

/// `wgsph compare` of the scene file `toml` over `steps` steps: its standard output, after
/// checking that it succeeded.
fn compare_passing(toml: &str, steps: &str) -> String {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("scene.toml"), toml).unwrap();
    let out = wgsph(&["compare", "scene.toml", "--steps", steps], dir.path());
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(out.status.success(), "{text}\n{}", String::from_utf8_lossy(&out.stderr));
    text
}

#[test]
fn compare_judges_a_dfsph_scene_by_its_iterations_and_again_with_them_held_fixed() {
    // A solve that stops at its tolerance stops one iteration apart on the two paths now and
    // then, and the flow amplifies that step's difference over 100 steps past the many-step
    // tolerances (this column's position and pressure errors do): the free run is judged after
    // one step and by its iteration counts, and its 100 steps again with the iterations held.
    if common::contexts().is_empty() {
        return;
    }
    let scene = "name = \"column\"\nseed = 3\n[domain]\nmin = [-0.07, -0.07, -0.07]\nmax = [0.67, 0.67, 0.17]\n\
        [physics]\nsmoothing_length = 0.04\nparticle_spacing = 0.02\nkernel = \"mueller\"\nsolver = \"dfsph\"\nviscosity = 0.01\n\
        [time]\ndt = 0.001\nend_time = 0.5\nadaptive = true\n\
        [[fluid]]\nmin = [0.0, 0.0, 0.0]\nmax = [0.2, 0.3, 0.1]\njitter = 0.02\n\
        [[boundary]]\ntype = \"container\"\nmin = [0.0, 0.0, 0.0]\nmax = [0.6, 0.6, 0.1]\n";
    let text = compare_passing(scene, "100");
    for line in ["after 1 step(s):", "(not judged:", "iterations per step over 100 steps:", "the same 100 steps with every solve held at", "compare: passed"] {
        assert!(text.contains(line), "no '{line}' in:\n{text}");
    }
    // The held run's table is judged against at least the f32 path's own errors.
    assert!(text.contains("(tolerances at least 3 times the cpu f32 path's own errors against cpu f64)"), "{text}");
    assert!(!text.contains("FAIL"), "{text}");
    assert!(text.contains("  divergence  ") && text.contains("and 2 divergence iterations on every path"), "{text}");
    // Without the divergence solve, neither its iterations nor its held count are reported.
    let text = compare_passing(&scene.replace("viscosity = 0.01\n", "viscosity = 0.01\n[physics.dfsph]\ndivergence_solve = false\n"), "100");
    assert!(text.contains("with every solve held at 3 constant-density iterations on every path:") && !text.contains("divergence"), "{text}");
}

#[test]
fn compare_gives_dfsph_solves_held_too_short_more_iterations() {
    // A jittered column thrown at a wall (Wendland's kernel at 3 spacings, Akinci's wall
    // volumes): its free solves take 2.05 and 1.07 iterations per step on average, and held
    // at 3 and 2 the fluid is pushed into the walls and out of the domain at step 56 on every
    // path, so the held comparison is made again with twice the iterations.
    if common::contexts().is_empty() {
        return;
    }
    let scene = "name = \"thrown\"\nseed = 9\n[domain]\nmin = [-0.1, -0.1, -0.1]\nmax = [0.7, 0.8, 0.2]\n\
        [physics]\nsmoothing_length = 0.06\nparticle_spacing = 0.02\nkernel = \"wendland\"\nsolver = \"dfsph\"\nviscosity = 0.01\n\
        boundary_friction = 0.0\nboundary_volume = \"akinci\"\n\
        [time]\ndt = 0.0005\nend_time = 0.5\n\
        [[fluid]]\nmin = [0.0, 0.0, 0.0]\nmax = [0.2, 0.3, 0.1]\njitter = 0.1\nvelocity = [0.5, 0.0, 0.0]\n\
        [[boundary]]\ntype = \"container\"\nmin = [0.0, 0.0, 0.0]\nmax = [0.6, 0.6, 0.1]\n";
    let text = compare_passing(scene, "60");
    let held_short = "every solve held at 3 constant-density and 2 divergence iterations on every path:\n  went bad on the gpu path at step ";
    assert!(text.contains(held_short) && text.contains("the solves were held too short\n  (again with 5 constant-density and 3 divergence iterations)"), "{text}");
    assert!(text.contains("every solve held at 5 constant-density and 3 divergence iterations") && text.ends_with("compare: passed\n"), "{text}");
}

#[test]
fn compare_of_a_run_that_goes_bad_says_where_and_why() {
    // One particle rising at 1 m/s out through the top of a domain with no wall.
    let dir = tempfile::tempdir().unwrap();
    let scene = TestScene::new().domain([-0.1; 3], [0.3, 0.1, 0.3]).gravity([0.0; 3]).fluid([0.0; 3], [0.02; 3]).jitter(0.0).moving_at([0.0, 1.0, 0.0]).named("rising").build();
    std::fs::write(dir.path().join("rising.toml"), scene.to_toml()).unwrap();
    if common::contexts().is_empty() {
        return;
    }
    let out = wgsph(&["compare", "rising.toml", "--steps", "400"], dir.path());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains("rising went bad within 400 steps, on the gpu path at step ") && err.contains("on the cpu f64 path at step "), "{err}");
    assert!(err.contains("beyond the domain's +y face") && err.contains("compare fewer steps (--steps)"), "{err}");
}

/// Every command that takes a scene takes `--set` and `--unset` too, checked as `run` checks
/// them: a bad override is refused by name before anything runs, and a good one reaches the
/// scene the command works on (here `compare` of the still tank switched to DFSPH from the
/// command line, which reports DFSPH's iterations).
#[test]
fn every_command_that_takes_a_scene_takes_its_overrides() {
    let dir = tempfile::tempdir().unwrap();
    let mut commands = vec![vec!["compare", "hydrostatic"], vec!["profile", "hydrostatic"], vec!["tradeoff", "hydrostatic", "--out", "t"]];
    if cfg!(feature = "view") {
        commands.push(vec!["view", "hydrostatic"]);
    }
    for command in commands {
        for (flags, says) in [(["--set", "time.dt=-1"], "with --set time.dt=-1: time.dt: is -1"), (["--unset", "time.dt"], "with --unset time.dt: time.dt: is required")] {
            let o = wgsph(&[&command[..], &flags[..]].concat(), dir.path());
            let err = String::from_utf8_lossy(&o.stderr);
            assert_eq!(o.status.code(), Some(2), "{command:?} {flags:?}: {err}");
            assert!(err.contains(says) && !err.contains("panicked"), "{command:?} {flags:?}: {err}");
        }
    }
    assert!(!dir.path().join("t").exists(), "a refused study wrote nothing");
    if common::contexts().is_empty() {
        return;
    }
    let o = wgsph(&["compare", "hydrostatic", "--steps", "5", "--set", "physics.solver=dfsph", "--unset", "physics.speed_of_sound"], dir.path());
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success() && text.contains("iterations per step over 5 steps:") && text.ends_with("compare: passed\n"), "{text}\n{}", String::from_utf8_lossy(&o.stderr));
}

/// A strong surface tension's cohesion sums terms far larger than their sum, which f32
/// rounding cannot keep to the usual one-step tolerance on any path: compare judges the GPU
/// against the CPU's own f32 path's error there, and says which tolerance it raised.
#[test]
fn compare_judges_a_strong_surface_tension_against_f32_rounding() {
    if common::contexts().is_empty() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let o = wgsph(&["compare", "hydrostatic", "--steps", "1", "--set", "physics.surface_tension=0.5"], dir.path());
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success() && text.ends_with("compare: passed\n"), "{text}\n{}", String::from_utf8_lossy(&o.stderr));
    assert!(text.contains("(tolerance of acceleration") && text.contains("raised to 3 times the cpu f32 path's own error"), "{text}");
    let o = wgsph(&["compare", "hydrostatic", "--steps", "1"], dir.path());
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success() && !text.contains("raised"), "{text}");
}

/// A `WGPU_BACKEND` that names no backend is named as why no adapter was found, not a driver
/// to install.
#[test]
fn a_wgpu_backend_that_names_no_backend_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_wgsph"))
        .args(["run", "hydrostatic", "--particles", "300", "--steps", "1", "--backend", "gpu", "--out", "o"])
        .current_dir(dir.path())
        .env("WGPU_BACKEND", "foo")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("WGPU_BACKEND='foo' names no backend") && !err.contains("install a GPU driver"), "{err}");
    assert!(!dir.path().join("o").exists());
}
