//! Bad scene files are refused before any work, naming the file, the field and what is allowed;
//! the command line exits with code 2 for them.

use std::process::Command;
use wgsph::model::scene::Scene;
use wgsph::model::scene::SceneOrigin;
use wgsph::model::builtin::BUILTIN_SCENES;

const GOOD: &str = r#"
[domain]
min = [0.0, 0.0, 0.0]
max = [1.0, 1.0, 1.0]
[physics]
smoothing_length = 0.1
particle_spacing = 0.05
stiffness = 1000.0
[time]
dt = 0.001
end_time = 0.1
[[fluid]]
min = [0.2, 0.2, 0.2]
max = [0.4, 0.4, 0.4]
"#;

fn error_of(text: &str) -> String {
    let origin = SceneOrigin::File("tank.toml".into());
    Scene::from_toml_str(text, &origin).expect_err("must be refused").to_string()
}

#[test]
fn the_good_scene_and_the_built_in_scenes_are_accepted() {
    Scene::from_toml_str(GOOD, &SceneOrigin::Text).unwrap();
    for (name, _, _) in BUILTIN_SCENES {
        let s = Scene::builtin(name).unwrap();
        assert!(!s.initial_state().fluid_positions.is_empty());
    }
}

/// A scene built in code from `Physics::new(h, s)` gets what a scene file giving only h, s and
/// the stiffness gets (the defaults are written once, in the scene's reading).
#[test]
fn physics_built_in_code_takes_a_scene_files_defaults() {
    use wgsph::model::scene::Physics;
    let read = Scene::from_toml_str(GOOD, &SceneOrigin::Text).unwrap().physics;
    assert_eq!(Physics { stiffness: Some(1000.0), ..Physics::new(0.1, 0.05) }, read);
}

#[test]
fn built_in_scenes_match_the_files_in_scenes_dir() {
    for (name, _, text) in BUILTIN_SCENES {
        let path = format!("{}/scenes/{name}.toml", env!("CARGO_MANIFEST_DIR"));
        assert_eq!(std::fs::read_to_string(path).unwrap(), *text);
    }
}

#[test]
fn a_missing_field_is_named() {
    let e = error_of(&GOOD.replace("smoothing_length = 0.1\n", ""));
    assert!(e.contains("tank.toml") && e.contains("smoothing_length"), "{e}");
}

#[test]
fn a_wrong_type_or_unknown_field_is_named() {
    let e = error_of(&GOOD.replace("smoothing_length = 0.1", "smoothing_length = \"big\""));
    assert!(e.contains("tank.toml: line 6 (smoothing_length):"), "{e}");
    // Inside a table of an array (a probe): the key too, not the line alone.
    let e = error_of(&(GOOD.to_string() + "[[probe]]\nname = \"p\"\ntype = \"point\"\nposition = [0.3, 0.3, 0.3]\nevery_steps = -1\n"));
    assert!(e.contains("(every_steps): invalid value: integer `-1`"), "{e}");
    // In a [[boundary]] table, read through its type, the reader points at the whole table: the
    // key is the one line that holds the value the message quotes.
    let tank = GOOD.to_string() + "[[boundary]]\ntype = \"box\"\nmin = [0.5, 0.5, 0.5]\nmax = \"x\"\n";
    let e = error_of(&tank);
    assert!(e.contains("tank.toml: line 18 (max): invalid type: string \"x\""), "{e}");
    let e = error_of(&tank.replace("max = \"x\"", "max = [0.6, 0.6, 0.6]\nlayers = -2"));
    assert!(e.contains("line 19 (layers): invalid value: integer `-2`"), "{e}");
    let e = error_of(&GOOD.replace("smoothing_length = 0.1", "smoothing_lenght = 0.1"));
    assert!(e.contains("smoothing_lenght"), "{e}");
    let e = error_of(&GOOD.replace("stiffness = 1000.0", "stiffness = 1000.0\nequation_of_state = \"cubic\""));
    assert!(e.contains("linear") && e.contains("tait"), "{e}");
    // A value where a table belongs: said in the file's words, not by the reader's type.
    let e = error_of(&GOOD.replace("stiffness = 1000.0", "stiffness = 1000.0\ndfsph = 5"));
    assert!(e.contains("line") && e.contains("invalid type: integer `5`, expected a table of fields") && !e.contains("struct"), "{e}");
}

#[test]
fn non_positive_h_dt_and_spacing_are_refused() {
    for (from, to, field) in [
        ("smoothing_length = 0.1", "smoothing_length = -0.1", "physics.smoothing_length"),
        ("smoothing_length = 0.1", "smoothing_length = 0.0", "physics.smoothing_length"),
        ("dt = 0.001", "dt = 0.0", "time.dt"),
        ("dt = 0.001", "dt = -1.0", "time.dt"),
        ("particle_spacing = 0.05", "particle_spacing = -0.05", "physics.particle_spacing"),
        ("particle_spacing = 0.05", "particle_spacing = 0.0", "physics.particle_spacing"),
        ("stiffness = 1000.0", "stiffness = -3.0", "physics.stiffness"),
    ] {
        let e = error_of(&GOOD.replace(from, to));
        assert!(e.contains("tank.toml") && e.contains(field) && e.contains("> 0"), "{to}: {e}");
    }
    // A step beyond what f32 products of it can hold.
    let e = error_of(&GOOD.replace("dt = 0.001", "dt = 1e39\nend_time = 1e40").replace("end_time = 0.1", ""));
    assert!(e.contains("time.dt") && e.contains("must be at most 1e8 s"), "{e}");
}

#[test]
fn a_fluid_block_outside_the_domain_is_refused() {
    let e = error_of(&GOOD.replace("max = [0.4, 0.4, 0.4]", "max = [1.4, 0.4, 0.4]"));
    assert!(e.contains("fluid[0]") && e.contains("domain"), "{e}");
}

#[test]
fn an_empty_scene_is_refused() {
    let text = GOOD.split("[[fluid]]").next().unwrap();
    let e = error_of(text);
    assert!(e.contains("fluid") && e.contains("at least one"), "{e}");
    let e = error_of("");
    assert!(e.contains("tank.toml"), "{e}");
}

#[test]
fn a_particle_count_that_does_not_fit_is_refused() {
    let e = error_of(
        &GOOD
            .replace("max = [1.0, 1.0, 1.0]", "max = [1000.0, 1000.0, 1000.0]")
            .replace("max = [0.4, 0.4, 0.4]", "max = [900.0, 900.0, 900.0]")
            .replace("smoothing_length = 0.1", "smoothing_length = 10.0"),
    );
    assert!(e.contains("particles") && (e.contains("at most") || e.contains("memory")), "{e}");
}

/// Spacings far below any count (1e-100, 1e-300, the smallest double) are refused by the
/// particle limit, naming the walls where the walls are what overflows; before, their lattice
/// sizes wrapped around and the program ran out of memory creating them.
#[test]
fn spacings_too_small_for_any_count_are_refused_not_allocated() {
    let tank = GOOD.to_string() + "[[boundary]]\ntype = \"container\"\nmin = [0.1, 0.1, 0.1]\nmax = [0.6, 0.6, 0.6]\n";
    for spacing in ["1e-7", "1e-100", "1e-300", "5e-324"] {
        let e = error_of(&tank.replace("max = [0.6, 0.6, 0.6]", &format!("max = [0.6, 0.6, 0.6]\nspacing = {spacing}")));
        assert!(e.contains("boundary: would create more than 1.8e19 particles; at most"), "{spacing}: {e}");
        let e = error_of(&GOOD.replace("particle_spacing = 0.05", &format!("particle_spacing = {spacing}")));
        assert!(e.contains("fluid: would create") && e.contains("at most"), "{spacing}: {e}");
    }
    let e = error_of(&tank.replace("max = [0.6, 0.6, 0.6]", "max = [0.6, 0.6, 0.6]\nspacing = 1e-4"));
    assert!(e.contains("boundary: would create") && !e.contains("1.8e19"), "{e}");
}

/// Values beyond any fluid (a particle mass a thousand times off its lattice cell's, a wall
/// friction or density of 1e300, a block thrown faster than any speed of sound, a force probe's
/// moment taken about a point 1e300 away, a thousand wall layers, a step f32 cannot hold) are
/// refused at load, naming the field and the range; before, they ran into NaN, a misleading
/// diagnosis or a hang.
#[test]
fn values_beyond_any_fluid_are_refused_with_their_range() {
    let tank = GOOD.to_string() + "[[boundary]]\ntype = \"container\"\nmin = [0.1, 0.1, 0.1]\nmax = [0.6, 0.6, 0.6]\n";
    let probe = "[[probe]]\nname = \"load\"\ntype = \"force\"\nboundary = 0\n";
    for (change, says) in [
        (GOOD.replace("particle_spacing = 0.05", "particle_spacing = 0.05\nparticle_mass = 1e-300"), "physics.particle_mass: is 1e-300; must be between 0.000125 and 125 (within a factor of 1000"),
        (GOOD.replace("particle_spacing = 0.05", "particle_spacing = 0.05\nparticle_mass = 1e30"), "physics.particle_mass: is 1e30; must be between"),
        (GOOD.replace("particle_spacing = 0.05", "particle_spacing = 0.05\nboundary_friction = 1e300"), "physics.boundary_friction: is 1e300; must be from 0 to 100"),
        (GOOD.replace("max = [0.4, 0.4, 0.4]", "max = [0.4, 0.4, 0.4]\nvelocity = [1e300, 0, 0]"), "fluid[0].velocity: is [1e300, 0, 0]; each component must be at most 1e8"),
        (tank.replace("max = [0.6, 0.6, 0.6]", "max = [0.6, 0.6, 0.6]\nrest_density = 1e300"), "boundary[0].rest_density: is 1e300; must be between"),
        (tank.replace("max = [0.6, 0.6, 0.6]", "max = [0.6, 0.6, 0.6]\nlayers = 1000"), "boundary[0].layers: is 1000; must be from 1 to 16"),
        (GOOD.to_string() + "[[boundary]]\ntype = \"plane\"\npoint = [0, 0, 0]\nnormal = [1e300, 1e300, 0]\n", "boundary[0].normal: is [1e300, 1e300, 0], of length 1.41421e300; must be a direction of length from 1e-6 to 1e150"),
        (GOOD.to_string() + "[[boundary]]\ntype = \"plane\"\npoint = [0, 0, 0]\nnormal = [1e-300, 0, 0]\n", "boundary[0].normal: is [1e-300, 0, 0], of length 1e-300; must be a direction"),
        (GOOD.replace("dt = 0.001", "dt = 1e-46"), "time.dt: is 1e-46; must be at least 1e-30"),
        (GOOD.replace("dt = 0.001", "dt = 1e-28\nadaptive = true"), "time.dt: gives a smallest adaptive step of 1e-31; must be at least 1e-30"),
        (GOOD.replace("dt = 0.001", "dt = 0.001\nadaptive = true\ndt_min = 1e-40"), "time.dt_min: gives a smallest adaptive step of 1e-40"),
        (tank.clone() + probe + "moment_about = [1e300, 0, 0]\n", "probe[0] ('load').moment_about: is [1e300, 0, 0]; must lie within 1000 domain sizes (1000) of the domain"),
    ] {
        let e = error_of(&change);
        assert!(e.contains(says), "{says}: {e}");
    }
    // Within the ranges: accepted.
    let origin = SceneOrigin::File("tank.toml".into());
    for fine in [
        GOOD.replace("particle_spacing = 0.05", "particle_spacing = 0.05\nparticle_mass = 0.2"),
        tank.replace("max = [0.6, 0.6, 0.6]", "max = [0.6, 0.6, 0.6]\nlayers = 16").replace("[domain]\nmin = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]", "[domain]\nmin = [-1.0, -1.0, -1.0]\nmax = [2.0, 2.0, 2.0]"),
        tank.clone() + probe + "moment_about = [500, 0, 0]\n",
    ] {
        Scene::from_toml_str(&fine, &origin).unwrap_or_else(|e| panic!("{e}\n{fine}"));
    }
}

/// A scene path that names an endless file (`/dev/zero`) is refused once past the most read,
/// not read until memory runs out.
#[cfg(unix)]
#[test]
fn an_endless_scene_file_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    std::os::unix::fs::symlink("/dev/zero", dir.path().join("zero.toml")).unwrap();
    let out = wgsph(&["run", "zero.toml", "--backend", "cpu", "--steps", "1"], dir.path());
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("zero.toml: scene: cannot read the file: it is longer than 64 MiB"), "{}", String::from_utf8_lossy(&out.stderr));
}

fn wgsph(args: &[&str], dir: &std::path::Path) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_wgsph")).args(args).current_dir(dir).output().unwrap()
}

#[test]
fn the_command_line_exits_with_2_on_bad_input_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, GOOD.replace("dt = 0.001", "dt = 0.0")).unwrap();
    let out = wgsph(&["run", bad.to_str().unwrap(), "--backend", "cpu", "--out", "o"], dir.path());
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bad.toml") && err.contains("time.dt"), "{err}");
    assert!(!dir.path().join("o").exists(), "no output before the scene is valid");
    let out = wgsph(&["run", "no_such_scene", "--backend", "cpu"], dir.path());
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("built-in"));
    let out = wgsph(&["run", "--steps", "-3"], dir.path());
    assert_eq!(out.status.code(), Some(2));
    // A count of zero or not a count: said without the type's largest value as a bound.
    for (command, flag, value, says) in [
        ("compare", "--steps", "0", "0 is not allowed: give a whole number of at least 1"),
        ("run", "--particles", "1.5", "'1.5' is not a whole number of at least 1"),
        ("run", "--steps", "abc", "'abc' is not a whole number of 0 or more"),
        ("run", "--checkpoint-every", "-1", "'-1' is not a whole number of 0 or more"),
        ("run", "--time", "0.01 ms", "'0.01 ms' is not a time in seconds"),
    ] {
        let out = wgsph(&[command, &format!("{flag}={value}")], dir.path());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.code() == Some(2) && err.contains(says) && !err.contains("18446744073709551615"), "{command} {flag} {value}: {err}");
    }
    let out = wgsph(&["run", "--backend", "tpu"], dir.path());
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("cpu"));
    // A time with its unit, as --snapshot-every takes one.
    let out = wgsph(&["run", "hydrostatic", "--particles", "300", "--time", "0.001s", "--backend", "cpu", "--out", "t", "--quiet"], dir.path());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

#[test]
fn camera_fields_are_checked() {
    let with = |camera: &str| format!("{GOOD}\n[camera]\n{camera}\n");
    Scene::from_toml_str(&with("eye = [0.5, 0.5, 3.0]\ntarget = [0.5, 0.5, 0.5]"), &SceneOrigin::Text).unwrap();
    for (camera, field, allowed) in [
        ("eye = [0.5, 0.5, 0.5]\ntarget = [0.5, 0.5, 0.5]", "camera.target", "must differ"),
        ("eye = [0.5, 3.0, 0.5]\ntarget = [0.5, 0.5, 0.5]", "camera.up", "not parallel"),
        ("eye = [0.5, 0.5, 3.0]\ntarget = [0.5, 0.5, 0.5]\nfov_degrees = 180.0", "camera.fov_degrees", "between 1 and 170"),
        ("eye = [0.5, 0.5, nan]\ntarget = [0.5, 0.5, 0.5]", "camera.eye", "finite"),
    ] {
        let e = error_of(&with(camera));
        assert!(e.contains("tank.toml") && e.contains(field) && e.contains(allowed), "{camera}: {e}");
    }
}

#[test]
fn boundary_pressure_is_mirror_by_default_and_checked() {
    use wgsph::model::scene::BoundaryPressure;
    assert_eq!(Scene::from_toml_str(GOOD, &SceneOrigin::Text).unwrap().params().boundary_pressure, BoundaryPressure::Mirror);
    let consistent = GOOD.replace("stiffness = 1000.0", "stiffness = 1000.0\nboundary_pressure = \"consistent\"");
    assert_eq!(Scene::from_toml_str(&consistent, &SceneOrigin::Text).unwrap().params().boundary_pressure, BoundaryPressure::Consistent);
    let e = error_of(&GOOD.replace("stiffness = 1000.0", "stiffness = 1000.0\nboundary_pressure = \"mirrored\""));
    assert!(e.contains("tank.toml") && e.contains("mirrored") && e.contains("mirror") && e.contains("consistent"), "{e}");
}

fn wgsph_in(dir: &std::path::Path, args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_wgsph")).args(args).current_dir(dir).env_remove("RUST_LOG").output().unwrap()
}

/// `--set KEY=VALUE` changes a scene field without editing the file: checked like the file
/// (the same error for the same value), and recorded in the run's scene.toml.
#[test]
fn set_changes_a_scene_field_checked_like_the_file_and_recorded() {
    let dir = tempfile::tempdir().unwrap();
    let run = ["run", "hydrostatic", "--particles", "300", "--steps", "2", "--backend", "cpu"];
    let o = wgsph_in(
        dir.path(),
        &[&run[..], &["--out", "o", "--set", "time.dt=1e-4", "--set", "physics.viscosity=0", "--set", "fluid.0.velocity=[0.5, 0, 0]", "--set", "physics.kernel=cubic_spline"]].concat(),
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let copy = Scene::load(dir.path().join("o/scene.toml").to_str().unwrap()).unwrap();
    assert_eq!((copy.physics.viscosity, copy.fluid[0].velocity), (0.0, [0.5, 0.0, 0.0]));
    assert_eq!(copy.physics.kernel, wgsph::model::scene::Kernel::CubicSpline);
    // --particles scales the changed scene: dt with h, from 1e-4.
    let mut expected = Scene::builtin("hydrostatic").unwrap();
    expected.time.dt = 1e-4;
    assert_eq!(copy.time.dt, expected.with_fluid_particles(300).time.dt);
    let summary: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.path().join("o/summary.json")).unwrap()).unwrap();
    assert_eq!(summary["dt"].as_f64(), Some(copy.time.dt));

    // The same value in the file and by --set: the same error, naming the override.
    let file_error = error_of(&GOOD.replace("dt = 0.001", "dt = -1.0"));
    let message = file_error.split_once(": ").unwrap().1;
    let o = wgsph_in(dir.path(), &["run", "hydrostatic", "--steps", "1", "--set", "time.dt=-1.0"]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains(message) && err.contains("--set time.dt=-1.0"), "{err}\nthe file's: {file_error}");
    for (set, says) in [
        ("time.dtt=1", "unknown field `dtt`"),
        ("physics.viscosity=fast", "invalid type"),
        ("physics.dfsph=5", "physics.dfsph: invalid type: integer `5`, expected a table of fields"),
        ("physics.equation_of_state=cubic", "tait"),
        ("fluid.3.jitter=0", "fluid has 1 entry; 3 is not one"),
        ("probe.0.name=p", "the scene has no probe list, so it has no entry 0 to set"),
        ("time.dt.x=1", "is a value"),
        ("nonsense", "KEY=VALUE"),
        ("physics.viscosity=0.1\nstiffness=3", "the value holds a line break"),
        ("physics.viscosity=1e400", "1e400 is beyond the largest number a scene holds"),
    ] {
        let o = wgsph_in(dir.path(), &["run", "hydrostatic", "--steps", "1", "--set", set]);
        assert_eq!(o.status.code(), Some(2), "{set}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(says), "--set {set}: {err}");
        assert!(!err.contains("panicked"), "{err}");
    }
    assert!(!dir.path().join("out").exists(), "a refused run wrote nothing");
}

/// `--unset KEY` removes a field or a list's entry; the overrides are validated together, so a
/// change of several fields passes through no half-made scene: a built-in weakly compressible
/// scene switched to DFSPH from the command line.
#[test]
fn unset_removes_a_field_so_that_a_scene_can_change_its_solver_from_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let run = ["run", "dam_break", "--particles", "500", "--steps", "2", "--backend", "cpu"];
    // The solver alone: refused, naming the field to remove and how.
    let o = wgsph_in(dir.path(), &[&run[..], &["--out", "refused", "--set", "physics.solver=dfsph"]].concat());
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("with --set physics.solver=dfsph: physics.speed_of_sound: is not used with solver") && err.contains("remove it (--unset physics.speed_of_sound)"), "{err}");
    // With the speed of sound removed (given after the --set: removals apply first), and the
    // last plane dropped.
    let o = wgsph_in(dir.path(), &[&run[..], &["--out", "dfsph", "--set", "physics.solver=dfsph", "--unset", "physics.speed_of_sound", "--unset", "boundary.6"]].concat());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let copy = Scene::load(dir.path().join("dfsph/scene.toml").to_str().unwrap()).unwrap();
    assert_eq!(copy.physics.solver, wgsph::model::scene::PressureSolver::Dfsph);
    assert_eq!((copy.physics.speed_of_sound, copy.physics.stiffness), (None, None));
    let built_in = Scene::builtin("dam_break").unwrap();
    assert_eq!((copy.boundary.len(), &copy.boundary[..6]), (6, &built_in.with_fluid_particles(500).boundary[..6]));
    // Bad removals: named, with what is there.
    for (unset, says) in [
        ("physics.speed_of_sond", "physics.speed_of_sond: is not set in the scene"),
        ("boundary.9", "boundary has 7 entries; '9' is not one"),
        ("time.dt", "with --unset time.dt: time.dt: is required in every scene and has no default, so it cannot be removed (--set time.dt=VALUE changes it)"),
        ("physics", "with --unset physics: physics: is required in every scene"),
        ("physics.gravity.x", "physics.gravity has 3 entries; 'x' is not one"),
        ("time.dt.x", "time.dt is a value, not a table"),
        ("nowhere.x", "the scene has no nowhere, so it has no x to remove"),
        ("a..b", "must be a dotted path"),
    ] {
        let o = wgsph_in(dir.path(), &["run", "dam_break", "--steps", "1", "--out", "bad", "--unset", unset]);
        assert_eq!(o.status.code(), Some(2), "{unset}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(says) && !err.contains("panicked"), "--unset {unset}: {err}");
    }
    assert!(!dir.path().join("refused").exists() && !dir.path().join("bad").exists(), "a refused run wrote nothing");
}

/// GOOD with DFSPH: no stiffness, and `extra` added to [physics] (`[physics.dfsph]` goes last).
fn dfsph_scene(extra: &str, dfsph: &str) -> String {
    let text = GOOD.replace("stiffness = 1000.0", &format!("solver = \"dfsph\"\n{extra}"));
    text.replace("[time]", &format!("{dfsph}\n[time]"))
}

#[test]
fn dfsph_scenes_are_read_and_checked() {
    let s = Scene::from_toml_str(&dfsph_scene("", ""), &SceneOrigin::Text).unwrap();
    let d = s.params().dfsph.expect("DFSPH");
    assert_eq!((d.density_error, d.divergence_error, d.min_iterations, d.max_iterations), (1e-4, 1e-3, 2, 100));
    assert!(d.warm_start && d.divergence_solve);
    let s = Scene::from_toml_str(&dfsph_scene("", "[physics.dfsph]\ndensity_error = 0.001\nmax_iterations = 20\nwarm_start = false"), &SceneOrigin::Text).unwrap();
    let d = s.params().dfsph.unwrap();
    assert_eq!((d.density_error, d.max_iterations, d.warm_start), (1e-3, 20, false));
    // A DFSPH scene's copy (the run directory's scene.toml) reads back the same.
    assert_eq!(Scene::from_toml_str(&s.to_toml(), &SceneOrigin::Text).unwrap(), s);
    // A WCSPH scene's copy is unchanged by the new options.
    assert!(!Scene::from_toml_str(GOOD, &SceneOrigin::Text).unwrap().to_toml().contains("solver"));
    for (text, field, allowed) in [
        (dfsph_scene("stiffness = 1000.0", ""), "physics.stiffness", "not used"),
        (dfsph_scene("speed_of_sound = 20.0", ""), "physics.speed_of_sound", "not used"),
        (dfsph_scene("", "[physics.dfsph]\ndensity_error = 0.0"), "physics.dfsph.density_error", "(0, 1)"),
        (dfsph_scene("", "[physics.dfsph]\ndivergence_error = 1.5"), "physics.dfsph.divergence_error", "(0, 1)"),
        (dfsph_scene("", "[physics.dfsph]\nmax_iterations = 0"), "physics.dfsph.max_iterations", "from 1 to"),
        (dfsph_scene("", "[physics.dfsph]\nmin_iterations = 5\nmax_iterations = 4"), "physics.dfsph.min_iterations", "<="),
        (dfsph_scene("", "[physics.dfsph]\nmax_divergence_iterations = 100000"), "physics.dfsph.max_divergence_iterations", "from 1 to"),
        (dfsph_scene("", "[physics.dfsph]\ntolerance = 0.1"), "line", "tolerance"),
        (GOOD.replace("[time]", "[physics.dfsph]\ndensity_error = 0.001\n[time]"), "physics.dfsph", "solver = \"dfsph\""),
        (GOOD.replace("stiffness = 1000.0", "stiffness = 1000.0\nsolver = \"iisph\""), "line", "dfsph"),
    ] {
        let e = error_of(&text);
        assert!(e.contains("tank.toml") && e.contains(field) && e.contains(allowed), "{field}: {e}");
    }
}

#[test]
fn akinci_walls_are_read_and_checked() {
    let walls = "[[boundary]]\ntype = \"container\"\nmin = [0.1, 0.1, 0.1]\nmax = [0.9, 0.8, 0.9]\nlayers = 1\n";
    let akinci = format!("{}\n{walls}", GOOD.replace("stiffness = 1000.0", "stiffness = 1000.0\nboundary_volume = \"akinci\""));
    let s = Scene::from_toml_str(&akinci, &SceneOrigin::Text).unwrap();
    let initial = s.initial_state();
    let p = &s.physics;
    let raw = wgsph::model::initial::akinci_volumes(&initial.wall_positions, p.kernel, p.smoothing_length, &s.grid(), p.rest_density);
    // Akinci's volumes, scaled by one factor for the one wall, below 1: a thin wall's own
    // volumes give the fluid beside it more than the fluid it stands for.
    let gamma = initial.wall_masses[0] / raw[0];
    assert!(gamma > 0.5 && gamma < 1.0, "{gamma}");
    for (m, r) in initial.wall_masses.iter().zip(&raw) {
        assert!((m / r - gamma).abs() < 1e-12 * gamma, "{m} {r} {gamma}");
    }
    // The volumes follow the sampling: a corner particle of a one-layer container has fewer wall
    // neighbours than one in a face, and a larger volume.
    let (lightest, heaviest) = initial.wall_masses.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &m| (lo.min(m), hi.max(m)));
    assert!(lightest < 0.9 * heaviest, "{lightest} {heaviest}");
    let e = error_of(&akinci.replace("layers = 1", "layers = 1\nrest_density = 2500.0"));
    assert!(e.contains("tank.toml") && e.contains("boundary[0].rest_density") && e.contains("akinci"), "{e}");
    let e = error_of(&GOOD.replace("stiffness = 1000.0", "stiffness = 1000.0\nboundary_volume = \"psi\""));
    assert!(e.contains("lattice") && e.contains("akinci"), "{e}");
}

/// The adaptive step's CFL number defaults by method: 0.25 where the speed of sound bounds the
/// step, 0.4 with DFSPH, whose condition is on the flow speed alone; a scene's own value is
/// kept for both, and an out-of-range one is refused naming the field.
#[test]
fn the_cfl_number_defaults_by_method_and_a_given_one_is_kept() {
    let cfl = |text: &str| Scene::from_toml_str(text, &SceneOrigin::Text).unwrap().params().adaptive.expect("adaptive dt").cfl_number;
    let adaptive = |text: String, extra: &str| text.replace("dt = 0.001", &format!("dt = 0.001\nadaptive = true\n{extra}"));
    assert_eq!(cfl(&adaptive(GOOD.to_string(), "")), 0.25);
    assert_eq!(cfl(&adaptive(dfsph_scene("", ""), "")), 0.4);
    assert_eq!(cfl(&adaptive(GOOD.to_string(), "cfl_number = 0.3")), 0.3);
    assert_eq!(cfl(&adaptive(dfsph_scene("", ""), "cfl_number = 0.6")), 0.6);
    let e = Scene::from_toml_str(&adaptive(dfsph_scene("", ""), "cfl_number = 1.5"), &SceneOrigin::Text).unwrap_err().to_string();
    assert!(e.contains("time.cfl_number") && e.contains("1.5"), "{e}");
}

/// A force probe whose box holds none of its boundary's wall particles would read zero for the
/// whole run: refused at load (exit 2) with the box and where the walls lie; a box around part
/// of the walls runs.
#[test]
fn a_force_probe_box_that_misses_the_walls_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let tank = Scene::builtin("hydrostatic").unwrap().to_toml();
    let force = |min: &str, max: &str| format!("{tank}\n[[probe]]\nname = \"floor\"\ntype = \"force\"\nboundary = 0\nmin = {min}\nmax = {max}\n");
    std::fs::write(dir.path().join("missed.toml"), force("[0.05, 0.05, 0.05]", "[0.06, 0.06, 0.06]")).unwrap();
    std::fs::write(dir.path().join("floor.toml"), force("[-0.1, -0.1, -0.1]", "[0.5, 0.0, 0.2]")).unwrap();
    let o = wgsph_in(dir.path(), &["run", "missed.toml", "--particles", "300", "--steps", "1", "--backend", "cpu"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("missed.toml: probe[0] ('floor'): the box min = [0.05, 0.05, 0.05] .. max = [0.06, 0.06, 0.06] holds none of boundary[0]'s wall particles"), "{err}");
    assert!(!dir.path().join("out").exists());
    let o = wgsph_in(dir.path(), &["run", "floor.toml", "--particles", "300", "--steps", "1", "--backend", "cpu"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn a_boundary_given_twice_is_refused() {
    let wall = "[[boundary]]\ntype = \"container\"\nmin = [0.1, 0.1, 0.1]\nmax = [0.9, 0.9, 0.9]\n";
    let e = error_of(&format!("{GOOD}{wall}{wall}"));
    assert!(e.contains("boundary[1]") && e.contains("repeats boundary[0]"), "{e}");
}

/// A setting that the scene's other settings leave unused is said to be, by name, so that it
/// is never silently ignored; a scene that uses what it sets gets no such warning.
#[test]
fn settings_the_scene_does_not_use_are_named() {
    let scene = |text: &str| Scene::from_toml_str(text, &SceneOrigin::Text).unwrap();
    assert!(scene(GOOD).unused_settings().is_empty());
    let dfsph = GOOD.replace("stiffness = 1000.0", "solver = \"dfsph\"\nequation_of_state = \"tait\"\nclamp_negative_pressure = true\n[physics.dfsph]\ndivergence_solve = false\ndivergence_error = 0.5\n[limits]\nmax_mach = 2.0");
    let unused = scene(&dfsph).unused_settings();
    for field in ["physics.equation_of_state = \"tait\"", "physics.clamp_negative_pressure = true", "physics.dfsph.divergence_error = 0.5", "limits.max_mach = 2"] {
        assert!(unused.iter().any(|w| w.starts_with(field) && w.contains("is not used")), "{field}: {unused:?}");
    }
    let fixed = GOOD.replace("dt = 0.001", "dt = 0.001\ncfl_number = 0.3");
    assert!(scene(&fixed).unused_settings().iter().any(|w| w.starts_with("time.cfl_number = 0.3") && w.contains("time.adaptive = false")));
    let planes = GOOD.replace("stiffness = 1000.0", "stiffness = 1000.0\nboundary_volume = \"akinci\"\nboundary_friction = 0.5")
        + "[[boundary]]\ntype = \"plane\"\npoint = [0.0, 0.0, 0.0]\nnormal = [0.0, 1.0, 0.0]\n";
    let unused = scene(&planes).unused_settings();
    assert!(unused.len() == 2 && unused.iter().all(|w| w.contains("no wall particles")), "{unused:?}");
    let walls = planes + "[[boundary]]\ntype = \"container\"\nmin = [0.1, 0.1, 0.1]\nmax = [0.9, 0.9, 0.9]\n";
    assert!(scene(&walls).unused_settings().is_empty());
    // Two viscosity changes at one time: one of them would never act.
    let twice = GOOD.replace("stiffness = 1000.0", "stiffness = 1000.0\nviscosity_schedule = [{ time = 0.01, viscosity = 0.1 }, { time = 0.01, viscosity = 0.2 }]");
    let e = error_of(&twice);
    assert!(e.contains("physics.viscosity_schedule[1].time") && e.contains("increasing"), "{e}");
}

/// A wall's default layers (h / spacing) are bounded too: a smoothing length of 1e300 names
/// itself, not a wall span of saturated numbers.
#[test]
fn a_smoothing_length_that_would_need_over_64_wall_layers_is_refused() {
    let wall = "[[boundary]]\ntype = \"container\"\nmin = [0.1, 0.1, 0.1]\nmax = [0.9, 0.9, 0.9]\n";
    for h in ["0.65", "1e300"] {
        let e = error_of(&format!("{GOOD}{wall}").replace("smoothing_length = 0.1", &format!("smoothing_length = {h}")).replace("particle_spacing = 0.05", "particle_spacing = 0.01"));
        assert!(e.contains("physics.smoothing_length") && e.contains("at most 64 are made"), "{h}: {e}");
    }
}
