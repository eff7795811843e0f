//! SPlisHSPlasH scene import: what maps onto a wgsph scene, and clear refusals of the rest.

use std::path::Path;
use std::process::{Command, Output};
use wgsph::model::scene::Boundary;
use wgsph::model::scene::EquationOfState;
use wgsph::model::scene::Kernel;
use wgsph::model::scene::SceneOrigin;
use wgsph::model::import::splishsplash::scene_from_json;
use wgsph::model::scene::Scene;

const DAM_BREAK: &str = include_str!("../data/splishsplash_dam_break.json");

fn wgsph(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_wgsph")).args(args).current_dir(dir).output().unwrap()
}

fn import(text: &str) -> Result<Scene, wgsph::SceneError> {
    scene_from_json(text, "test", &SceneOrigin::Text).map(|(scene, _)| scene)
}

#[test]
fn a_wcsph_dam_break_maps_onto_a_scene() {
    let s = import(DAM_BREAK).unwrap();
    let p = &s.physics;
    // Particle radius r = 0.01: spacing 2r, support radius 4r.
    assert_eq!((p.particle_spacing, p.smoothing_length), (0.02, 0.04));
    assert_eq!((p.rest_density, p.stiffness, p.speed_of_sound), (1000.0, Some(50000.0), None));
    assert_eq!((p.equation_of_state, p.kernel), (EquationOfState::Tait, Kernel::CubicSpline));
    assert_eq!((p.viscosity, p.boundary_friction, p.gravity), (0.01, 0.0, [0.0, -9.81, 0.0]));
    assert_eq!((s.time.dt, s.time.end_time), (0.0002, 0.5));
    // The block's corners scaled by 2; a regular lattice with the initial velocity.
    assert_eq!(s.fluid.len(), 1);
    assert_eq!((s.fluid[0].min, s.fluid[0].max, s.fluid[0].jitter, s.fluid[0].velocity), ([0.0; 3], [0.2, 0.4, 0.1], 0.0, [0.5, 0.0, 0.0]));
    assert_eq!(s.fluid_particle_count(), 10 * 20 * 5);
    // The unit box around the fluid is a closed tank backed by six planes; the small one is an obstacle.
    let tank = s.boundary.iter().find_map(|b| match b {
        Boundary::Container { min, max, open_top, .. } => Some((*min, *max, *open_top)),
        _ => None,
    });
    assert_eq!(tank, Some(([0.0, 0.0, 0.0], [1.0, 0.6, 0.1], false)));
    let obstacle = s.boundary.iter().find_map(|b| match b {
        Boundary::Box { min, max, .. } => Some((*min, *max)),
        _ => None,
    });
    let (min, max) = obstacle.unwrap();
    for a in 0..3 {
        assert!((min[a] - [0.65, 0.0, 0.0][a]).abs() < 1e-12 && (max[a] - [0.75, 0.1, 0.1][a]).abs() < 1e-12, "{min:?} {max:?}");
    }
    assert_eq!(s.boundary.iter().filter(|b| matches!(b, Boundary::Plane { .. })).count(), 6);
    for a in 0..3 {
        assert!(s.domain.min[a] < 0.0 && s.domain.max[a] > [1.0, 0.6, 0.1][a]);
    }
}

#[test]
fn a_json_scene_runs_from_the_command_line_and_is_recorded_as_toml() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("dam.json"), DAM_BREAK).unwrap();
    let o = wgsph(&["run", "dam.json", "--steps", "10", "--backend", "cpu", "--out", "o"], dir.path());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let recorded = Scene::load(dir.path().join("o/scene.toml").to_str().unwrap()).unwrap();
    let mut imported = import(DAM_BREAK).unwrap();
    imported.name = "dam".into();
    imported.description = recorded.description.clone();
    assert_eq!(recorded, imported);
    let s: wgsph::io::summary::Summary = serde_json::from_str(&std::fs::read_to_string(dir.path().join("o/summary.json")).unwrap()).unwrap();
    assert_eq!((s.scene.as_str(), s.fluid_particles, s.steps, s.failure), ("dam", 1000, 10, None));
}

#[test]
fn everything_unsupported_is_named_in_one_clear_error() {
    // Another solver (IISPH), the iteration-count step rule, volume maps (the default), a
    // dynamic body, an emitter.
    let text = r#"{
        "Configuration": { "particleRadius": 0.025, "stopAt": 2, "sim2D": true, "fancyOption": 3, "simulationMethod": 3, "cflMethod": 2 },
        "Fluid": { "viscosity": 0.01, "viscosityMethod": 6, "surfaceTensionMethod": 5 },
        "RigidBodies": [ { "geometryFile": "../models/bunny.obj", "isDynamic": true, "rotationAngle": 1.5 } ],
        "FluidBlocks": [ { "start": [0,0,0], "end": [1,1,1], "denseMode": 2 } ],
        "Emitters": [ { "width": 5 } ],
        "TriangleModels": {}
    }"#;
    let e = import(text).unwrap_err().to_string();
    for field in [
        "Configuration.simulationMethod: is 3; wgsph has WCSPH (0) and DFSPH (4)",
        "Configuration.cflMethod: is 2",
        "Configuration.sim2D",
        "Configuration.fancyOption",
        "Fluid.viscosityMethod: is 6",
        "Fluid.surfaceTensionMethod: is 5; wgsph supports 0 (none) and 2 (Akinci et al. 2013",
        "RigidBodies[0].isDynamic",
        "FluidBlocks[0].denseMode",
        "Emitters",
        "TriangleModels",
    ] {
        assert!(e.contains(field), "missing {field} in: {e}");
    }
    // Each supported value alone is accepted; each refused one alone is named.
    let cases = [
        (r#""exponent": 7"#, r#""exponent": 3"#, "Configuration.exponent"),
        (r#""pause": true"#, r#""kernel": 1"#, "Configuration.kernel"),
        (r#""stopAt": 0.5"#, r#""stopAt": 0"#, "Configuration.stopAt: is 0"),
        (r#""boundaryHandlingMethod": 0"#, r#""boundaryHandlingMethod": 3"#, "Configuration.boundaryHandlingMethod: is 3"),
        (r#""pause": true"#, r#""maxIterations": 0"#, "Configuration.maxIterations"),
        (r#""pause": true"#, r#""maxIterations": 2.5"#, "Configuration.maxIterations"),
        (r#""isDynamic": false"#, r#""particleFile": "walls.bgeo""#, "RigidBodies[0].particleFile"),
        (r#""translation": [0.7, 0.05, 0.05]"#, r#""translation": [0.15, 0.05, 0.05]"#, "RigidBodies[1]: the box neither contains"),
    ];
    for (from, to, field) in cases {
        let text = DAM_BREAK.replacen(from, to, 1);
        assert_ne!(text, DAM_BREAK);
        let e = import(&text).unwrap_err();
        assert!(e.to_string().contains(field), "{to}: {e}");
    }
    assert!(import(&DAM_BREAK.replacen(r#""exponent": 7"#, r#""exponent": 1"#, 1)).unwrap().physics.equation_of_state == EquationOfState::Linear);
    let mueller = DAM_BREAK.replacen(r#""pause": true"#, r#""kernel": 2, "gradKernel": 3"#, 1);
    assert_eq!(import(&mueller).unwrap().physics.kernel, Kernel::Mueller);
    let wendland = DAM_BREAK.replacen(r#""pause": true"#, r#""kernel": 1, "gradKernel": 1"#, 1);
    assert_eq!(import(&wendland).unwrap().physics.kernel, Kernel::Wendland);
    // From the command line: exit 2 before any work.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("bad.json"), text).unwrap();
    let o = wgsph(&["run", "bad.json", "--out", "o"], dir.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("bad.json") && !dir.path().join("o").exists());
    std::fs::write(dir.path().join("broken.json"), "{ \"Configuration\": ").unwrap();
    let o = wgsph(&["run", "broken.json"], dir.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("not valid JSON"));
}

const DFSPH_TANK: &str = include_str!("../data/splishsplash_dfsph_tank.json");

/// SPlisHSPlasH's default solver, DFSPH, with its CFL-adaptive step: the tolerances (in per cent
/// there) and iteration limits become `[physics.dfsph]`, the CFL factor wgsph's CFL number on h.
#[test]
fn a_dfsph_scene_with_adaptive_steps_maps_onto_a_scene_and_runs() {
    use wgsph::model::scene::PressureSolver;
    let s = import(DFSPH_TANK).unwrap();
    let d = &s.physics.dfsph;
    assert_eq!(s.physics.solver, PressureSolver::Dfsph);
    assert_eq!((d.density_error, d.divergence_error), (0.05 / 100.0, 0.2 / 100.0));
    assert_eq!((d.max_iterations, d.max_divergence_iterations, d.divergence_solve), (50, 40, true));
    // dt = cflFactor 0.4 (2r) / |v| there; dt = C h / |v| here with h = 4r: C = 0.2 cflFactor.
    assert!(s.time.adaptive);
    assert!((s.time.cfl_number.unwrap() - 0.2).abs() < 1e-12, "{:?}", s.time.cfl_number);
    assert_eq!((s.time.dt, s.time.dt_min, s.time.dt_max), (0.002, Some(0.0001), Some(0.004)));
    // SPlisHSPlasH's defaults where the file says nothing: 0.01 % and 0.1 %, 100 iterations,
    // cflFactor 0.5, the divergence solve on.
    let bare = DFSPH_TANK
        .lines()
        .filter(|l| !["maxIterations", "maxError", "enableDivergence", "cflFactor", "cflMax"].iter().any(|k| l.contains(k)))
        .collect::<Vec<_>>()
        .join("\n");
    let s0 = import(&bare).unwrap();
    let d0 = &s0.physics.dfsph;
    assert_eq!((d0.density_error, d0.divergence_error, d0.max_iterations, d0.max_divergence_iterations), (0.0001, 0.001, 100, 100));
    assert!((s0.time.cfl_number.unwrap() - 0.1).abs() < 1e-12 && s0.time.dt_max == Some(0.005));
    // The divergence solve off; a weakly compressible scene with adaptive steps keeps wgsph's
    // own CFL rule (with the speed of sound).
    let off = import(&DFSPH_TANK.replacen(r#""enableDivergenceSolver": true"#, r#""enableDivergenceSolver": false"#, 1)).unwrap();
    assert!(!off.physics.dfsph.divergence_solve);
    let wcsph = import(&DFSPH_TANK.replacen(r#""simulationMethod": 4"#, r#""simulationMethod": 0"#, 1)).unwrap();
    assert_eq!((wcsph.physics.solver, wcsph.time.adaptive, wcsph.time.cfl_number), (PressureSolver::Wcsph, true, None));
    // It runs, with DFSPH's iterations in its summary.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("tank.json"), DFSPH_TANK).unwrap();
    let o = wgsph(&["run", "tank.json", "--steps", "5", "--backend", "cpu", "--out", "o"], dir.path());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.path().join("o/summary.json")).unwrap()).unwrap();
    assert_eq!(summary["status"], "completed");
    assert!(summary["dfsph"]["pressure_iterations_mean"].as_f64().unwrap() >= 2.0, "{summary}");
    assert!(summary["dt_max"].as_f64().unwrap() <= 0.004 + 1e-12, "{summary}");
}

const NAMESPACED_TANK: &str = include_str!("../data/splishsplash_namespaced_tank.json");

/// SPlisHSPlasH's current scene files keep each solver's settings in a block of its own
/// (`Configuration.DFSPH`, `Configuration.WCSPH`) and each fluid method's coefficients in one
/// named after the method (`"Standard viscosity"`); its default walls are volume maps, and a
/// scene without `stopAt` runs until stopped. The blocks are read, the other solvers' and
/// unchosen methods' blocks skipped, and the walls and the end time imported as the nearest
/// wgsph has, each with a note.
#[test]
fn a_scene_of_the_current_format_with_its_solver_and_method_blocks_is_imported_with_notes() {
    use wgsph::model::scene::PressureSolver;
    let (s, notes) = scene_from_json(NAMESPACED_TANK, "tank", &SceneOrigin::Text).unwrap();
    let (p, d) = (&s.physics, &s.physics.dfsph);
    assert_eq!(p.solver, PressureSolver::Dfsph);
    assert_eq!((d.min_iterations, d.max_iterations, d.max_divergence_iterations, d.divergence_solve), (3, 60, 40, true));
    assert_eq!((d.density_error, d.divergence_error), (0.05 / 100.0, 0.2 / 100.0));
    assert_eq!((p.rest_density, p.viscosity, p.boundary_friction), (998.0, 0.02, 0.5));
    assert_eq!(s.time.end_time, 5.0);
    assert_eq!(notes.len(), 2, "{notes:?}");
    assert!(notes[0].contains("boundaryHandlingMethod is 2 (volume maps") && notes[0].contains("wall particles"), "{notes:?}");
    assert!(notes[1].contains("stopAt is not given") && notes[1].contains("t = 5 s"), "{notes:?}");
    assert!(s.boundary.iter().any(|b| matches!(b, Boundary::Container { .. })));
    // The same settings at the top of Configuration and of the material (the older format)
    // give the same scene; particles for walls and an end time give no note.
    let flat = NAMESPACED_TANK
        .replace("\"WCSPH\":\n\t\t{\n\t\t\t\"stiffness\": 20000,\n\t\t\t\"exponent\": 7\n\t\t},", "")
        .replace("\"IISPH\":\n\t\t{\n\t\t\t\"maxIterations\": 80\n\t\t},", "")
        .replace("\"DFSPH\":\n\t\t{", "")
        .replace("\"enableDivergenceSolver\": true\n\t\t}", "\"enableDivergenceSolver\": true")
        .replace("\"Standard viscosity\":\n\t\t\t{", "")
        .replace("\"viscosityBoundary\": 0.01\n\t\t\t},", "\"viscosityBoundary\": 0.01,")
        .replace("\"boundaryHandlingMethod\": 2", "\"boundaryHandlingMethod\": 0, \"stopAt\": 5");
    assert!(!flat.contains("DFSPH") && !flat.contains("Standard viscosity"), "{flat}");
    let (f, flat_notes) = scene_from_json(&flat, "tank", &SceneOrigin::Text).unwrap();
    assert_eq!((f, flat_notes), (s, vec![]));

    // A key a block does not hold, an XSPH filter, a refused value in a block: named by their
    // place in the blocks.
    for (from, to, named) in [
        ("\"minIterations\": 3", "\"minIterations\": 3, \"omega\": 1", "Configuration.DFSPH.omega: is not a parameter of SPlisHSPlasH's DFSPH block"),
        ("\"exponent\": 7", "\"exponent\": 7, \"gamma\": 2", "Configuration.WCSPH.gamma"),
        ("\"xsph\": 0.0", "\"xsph\": 0.1", "Materials[0].XSPH.xsph: is 0.1; wgsph has no XSPH"),
        ("\"viscosity\": 0.02", "\"viscosity\": 0.02, \"kinematic\": 1", "Materials[0].Standard viscosity.kinematic"),
        ("\"maxIterations\": 60", "\"maxIterations\": 2", "Configuration.DFSPH.minIterations, Configuration.DFSPH.maxIterations"),
        ("\"viscosity\": 0.02", "\"viscosity\": 1e300", "Materials[0].Standard viscosity.viscosity"),
        // A key at the top and in its method's block: one value would be dropped unseen.
        ("\"density0\": 998,", "\"density0\": 998, \"viscosity\": -0.01,", "viscosity again, as Materials[0].Standard viscosity.viscosity does; give it in one place"),
    ] {
        let text = NAMESPACED_TANK.replacen(from, to, 1);
        assert_ne!(text, NAMESPACED_TANK);
        let e = scene_from_json(&text, "tank", &SceneOrigin::Text).unwrap_err().to_string();
        assert!(e.contains(named), "{to}: {e}");
    }

    // From the command line the notes are warnings (not with --quiet), and the scene runs.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("tank.json"), NAMESPACED_TANK).unwrap();
    let o = wgsph(&["run", "tank.json", "--steps", "3", "--backend", "cpu", "--out", "o"], dir.path());
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(stderr.contains("warning: Configuration.boundaryHandlingMethod is 2") && stderr.contains("warning: Configuration.stopAt is not given"), "{stderr}");
    let o = wgsph(&["run", "tank.json", "--steps", "3", "--backend", "cpu", "--out", "q", "--quiet"], dir.path());
    assert!(o.status.success() && !String::from_utf8_lossy(&o.stderr).contains("warning"), "{}", String::from_utf8_lossy(&o.stderr));
}

/// SPlisHSPlasH's "Akinci et al. 2013" surface tension becomes wgsph's surface tension and
/// adhesion: its coefficients from the top of the fluid's block or from the method's own block,
/// SPlisHSPlasH's defaults where absent; a value wgsph refuses is named by its JSON key.
#[test]
fn akinci_surface_tension_maps_onto_surface_tension_and_adhesion() {
    let with = |keys: &str| DAM_BREAK.replacen("\"viscosityMethod\": 1,", &format!("\"viscosityMethod\": 1, {keys}"), 1);
    let p = import(&with(r#""surfaceTensionMethod": 2, "surfaceTension": 0.3, "surfaceTensionBoundary": 0.2,"#)).unwrap().physics;
    assert_eq!((p.surface_tension, p.wall_adhesion), (0.3, 0.2));
    let p = import(&with(r#""surfaceTensionMethod": 2, "Akinci et al. 2013": { "surfaceTension": 0.4 },"#)).unwrap().physics;
    assert_eq!((p.surface_tension, p.wall_adhesion), (0.4, 0.01));
    let p = import(&with(r#""surfaceTensionMethod": 2,"#)).unwrap().physics;
    assert_eq!((p.surface_tension, p.wall_adhesion), (0.05, 0.01));
    // A coefficient of another method's (here none) is not used.
    let p = import(&with(r#""surfaceTensionMethod": 0, "surfaceTension": 0.3,"#)).unwrap().physics;
    assert_eq!((p.surface_tension, p.wall_adhesion), (0.0, 0.0));
    let e = import(&with(r#""surfaceTensionMethod": 2, "surfaceTension": -1,"#)).unwrap_err().to_string();
    assert!(e.contains("Fluid.surfaceTension") && e.contains("must be between 0"), "{e}");
    let e = import(&with(r#""surfaceTensionMethod": 2, "Akinci et al. 2013": { "surfaceTensionBoundary": 1e9 },"#)).unwrap_err().to_string();
    assert!(e.contains("Fluid.Akinci et al. 2013.surfaceTensionBoundary"), "{e}");
}

/// A rigid body of another mesh (or a turned unit box) becomes a mesh boundary: its file read
/// from the scene file's folder, turned by rotationAngle (radians there) about rotationAxis,
/// scaled and moved, the fluid inside it where mapInvert says so. A file that cannot be read
/// is named by its JSON key.
#[test]
fn a_rigid_body_of_another_mesh_becomes_a_mesh_boundary() {
    let dir = tempfile::tempdir().unwrap();
    let cube = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nv 1 1 1\nv 0 1 1\n\
        f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 4 8 7 3\nf 1 5 8 4\nf 2 3 7 6\n";
    std::fs::create_dir_all(dir.path().join("models")).unwrap();
    std::fs::create_dir_all(dir.path().join("scenes")).unwrap();
    std::fs::write(dir.path().join("models/cube.obj"), cube).unwrap();
    let obstacle = r#""geometryFile": "../models/UnitBox.obj",
			"translation": [0.7, 0.05, 0.05],
			"scale": [0.1, 0.1, 0.1],"#;
    let mesh = r#""geometryFile": "../models/cube.obj",
			"translation": [0.7, 0.0, 0.03],
			"rotationAxis": [0, 1, 0],
			"rotationAngle": 0.5,
			"scale": [0.05, 0.05, 0.05],"#;
    let text = DAM_BREAK.replacen(obstacle, mesh, 1);
    assert_ne!(text, DAM_BREAK);
    let path = dir.path().join("scenes/mesh.json");
    std::fs::write(&path, &text).unwrap();
    let scene = Scene::load(path.to_str().unwrap()).unwrap();
    let m = scene.boundary.iter().find_map(|b| match b { Boundary::Mesh(m) => Some(m.clone()), _ => None }).expect("a mesh boundary");
    assert!(m.file.ends_with("cube.obj") && Path::new(&m.file).is_absolute(), "{}", m.file);
    assert!((m.rotation_degrees - 0.5f64.to_degrees()).abs() < 1e-12 && m.rotation_axis == [0.0, 1.0, 0.0]);
    assert_eq!((m.scale, m.translate, m.fluid_inside), ([0.05; 3], [0.7, 0.0, 0.03], false));
    let walls = scene.initial_walls();
    let index = scene.boundary.iter().position(|b| matches!(b, Boundary::Mesh(_))).unwrap() as u32;
    assert!(walls.wall_boundaries.iter().filter(|&&b| b == index).count() > 5);
    // The import runs.
    let o = wgsph(&["run", "scenes/mesh.json", "--steps", "5", "--backend", "cpu", "--quiet", "--out", "o"], dir.path());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // A mesh file that is not there.
    std::fs::write(&path, text.replace("cube.obj", "bunny.obj")).unwrap();
    let e = Scene::load(path.to_str().unwrap()).unwrap_err().to_string();
    assert!(e.contains("RigidBodies[1].geometryFile") && e.contains("bunny.obj") && e.contains("cannot read"), "{e}");
    // A turn that cannot place walls, named by its own field.
    for (from, to, says) in [
        (r#""rotationAngle": 0.5"#, r#""rotationAngle": 1e308"#, "RigidBodies[1].rotationAngle: is 1e308; must be a finite angle in radians"),
        (r#""rotationAxis": [0, 1, 0]"#, r#""rotationAxis": [0, 0, 0]"#, "RigidBodies[1].rotationAxis: is [0, 0, 0]; a rotation needs a finite, non-zero axis"),
    ] {
        std::fs::write(&path, text.replace(from, to)).unwrap();
        let e = Scene::load(path.to_str().unwrap()).unwrap_err().to_string();
        assert!(e.contains(says), "{e}");
    }
}
