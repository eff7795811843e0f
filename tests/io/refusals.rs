//! Scenes that cannot work are refused at load, naming the field, the value (huge values in
//! short form) and what is allowed: fluid inside solids, behind a plane or on top of other
//! fluid, a smoothing length below the spacing, constants beyond any liquid, too few particles,
//! more particles than the host's memory holds; and what the documentation promises is accepted
//! (a camera with only a field of view).
//! SPlisHSPlasH scenes are refused by their JSON keys.

use crate::common::TestScene;
use std::path::Path;
use std::process::{Command, Output};
use wgsph::model::import::splishsplash::scene_from_json;
use wgsph::model::scene::{Scene, SceneOrigin};
use wgsph::viz::render::{Bounds, Camera};

fn wgsph(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_wgsph")).args(args).current_dir(dir).output().unwrap()
}

/// A block of fluid in a closed tank of wall particles, with a plane under it: refusals change it.
fn tank() -> TestScene {
    TestScene::new().fluid([0.0; 3], [0.2, 0.3, 0.2]).closed_container([0.0; 3], [0.6, 0.5, 0.2]).plane([0.0; 3], [0.0, 1.0, 0.0], 0.0)
}

#[test]
fn fluid_in_a_solid_box_or_the_tank_walls_is_refused_naming_both() {
    let mut with_box = tank().build();
    with_box.boundary.push(wgsph::model::scene::Boundary::Box { min: [0.1, 0.0, 0.0], max: [0.3, 0.1, 0.2], walls: Default::default() });
    let e = TestScene::from(with_box).validation_error();
    assert!(e.contains("fluid[0]") && e.contains("overlaps boundary[2] (the box [0.1, 0, 0]..[0.3, 0.1, 0.2])") && e.contains("outside solids"), "{e}");
    // Through the tank's +x wall (which spans x 0.6..0.64).
    let e = tank().without_fluid().fluid([0.5, 0.0, 0.0], [0.62, 0.1, 0.1]).validation_error();
    assert!(e.contains("fluid[0]") && e.contains("the container's +x wall"), "{e}");
    // Touching faces are fine.
    tank().fluid([0.2, 0.0, 0.0], [0.6, 0.1, 0.2]).build();
}

#[test]
fn fluid_blocks_on_top_of_each_other_or_behind_a_plane_are_refused() {
    let e = tank().fluid([0.0; 3], [0.2, 0.3, 0.2]).validation_error();
    assert!(e.contains("fluid[1]") && e.contains("overlaps fluid[0]"), "{e}");
    let e = tank().plane([0.0, 0.1, 0.0], [0.0, 1.0, 0.0], 0.0).validation_error();
    assert!(e.contains("fluid[0]") && e.contains("0.1 behind boundary[2] (the plane"), "{e}");
}

#[test]
fn a_smoothing_length_below_the_particle_spacing_is_refused() {
    let e = tank().smoothing_length(0.015).validation_error();
    assert!(e.contains("physics.smoothing_length") && e.contains("is 0.015, below the particle spacing 0.02"), "{e}");
}

#[test]
fn absurd_constants_are_refused_with_the_value_in_short_form_and_the_range() {
    let cases: Vec<(TestScene, &str, &str)> = vec![
        (tank().speed_of_sound(1e300), "physics.speed_of_sound", "is 1e300; must be between 1e-6 and 1e8"),
        (tank().stiffness(1e300), "physics.stiffness", "is 1e300, a speed of sound of 3.16228e148; must be between"),
        (tank().gravity([0.0, -1e300, 0.0]), "physics.gravity", "of magnitude 1e300; must be at most 1e9"),
        (tank().viscosity(1e300), "physics.viscosity", "is 1e300; must be between 0 and 1e9"),
        (tank().viscosity(0.01).viscosity_change(0.5, 1e20), "physics.viscosity_schedule[0].viscosity", "is 1e20"),
    ];
    for (scene, field, what) in cases {
        let e = scene.validation_error();
        assert!(e.contains(field) && e.contains(what), "{field}: {e}");
        assert!(!e.contains("0000000000"), "{field}: a long number: {e}");
    }
    let mut s = tank().build();
    s.physics.rest_density = 1e300;
    let e = TestScene::from(s.clone()).validation_error();
    assert!(e.contains("physics.rest_density") && e.contains("is 1e300; must be between 1e-9 and 1e9"), "{e}");
    s.physics.rest_density = 1e-300;
    let e = TestScene::from(s).validation_error();
    assert!(e.contains("physics.rest_density") && e.contains("is 1e-300"), "{e}");
    // From a file, with the line of the huge number.
    let text = tank().build().to_toml().replace("rest_density = 1000.0", "rest_density = 1e300");
    let e = Scene::from_toml_str(&text, &SceneOrigin::File("big.toml".into())).unwrap_err().to_string();
    assert!(e.starts_with("big.toml: physics.rest_density: is 1e300"), "{e}");
}

#[test]
fn the_limits_are_checked() {
    let mut s = tank().build();
    s.limits.max_density_ratio = 0.9;
    let e = TestScene::from(s.clone()).validation_error();
    assert!(e.contains("limits.max_density_ratio") && e.contains("must be a number > 1"), "{e}");
    s.limits.max_density_ratio = 1.5;
    s.limits.warn_density_ratio = 2.0;
    let e = TestScene::from(s).validation_error();
    assert!(e.contains("limits.warn_density_ratio") && e.contains("above the stop level 1.5"), "{e}");
    // In a file: a table of its own, inf for no limit.
    let text = tank().build().to_toml() + "\n[limits]\nmax_mach = inf\nwarn_mach = inf\n";
    let s = Scene::from_toml_str(&text, &SceneOrigin::Text).unwrap();
    assert_eq!((s.limits.max_mach, s.limits.max_density_ratio), (f64::INFINITY, 1.5));
}

#[test]
fn too_few_particles_are_refused_with_the_fewest_the_scene_allows() {
    let dir = tempfile::tempdir().unwrap();
    let fewest = Scene::builtin("hydrostatic").unwrap().fewest_fluid_particles();
    assert_eq!(fewest, 128);
    for n in ["1", "127"] {
        let out = wgsph(&["run", "hydrostatic", "--particles", n, "--backend", "cpu", "--out", "o"], dir.path());
        assert_eq!(out.status.code(), Some(2), "{n}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(&format!("--particles {n}: the scene 'hydrostatic' allows at least 128 fluid particles")), "{err}");
        assert!(!err.contains("thinner than one particle spacing"), "{err}");
        assert!(!dir.path().join("o").exists());
    }
    let out = wgsph(&["run", "hydrostatic", "--particles", "128", "--steps", "2", "--backend", "cpu", "--out", "o", "--quiet"], dir.path());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

#[test]
fn a_camera_with_only_a_field_of_view_is_accepted_and_framed_automatically() {
    let text = tank().build().to_toml() + "\n[camera]\nfov_degrees = 60.0\n";
    let scene = Scene::from_toml_str(&text, &SceneOrigin::File("cam.toml".into())).unwrap();
    let camera = Camera::for_scene(&scene, 1.5);
    let bounds = Bounds::of_scene(&scene);
    assert!((camera.fov_y - 60f32.to_radians()).abs() < 1e-6);
    assert!((camera.target - bounds.center()).length() < 1e-6, "{camera:?}");
    // Every corner of what the scene shows is in the picture.
    for corner in [bounds.min, bounds.max] {
        assert!(camera.project(corner, 300, 200, &bounds).is_some_and(|(x, y)| (0.0..300.0).contains(&x) && (0.0..200.0).contains(&y)), "{camera:?}");
    }
    // An eye alone looks at the middle; a target alone is looked at from the automatic side.
    let eye_only = Scene::from_toml_str(&(tank().build().to_toml() + "\n[camera]\neye = [0.3, 0.3, 2.0]\n"), &SceneOrigin::Text).unwrap();
    let c = Camera::for_scene(&eye_only, 1.5);
    assert!((c.target - bounds.center()).length() < 1e-6 && (c.eye.z - 2.0).abs() < 1e-6, "{c:?}");
    let target_only = Scene::from_toml_str(&(tank().build().to_toml() + "\n[camera]\ntarget = [0.1, 0.1, 0.1]\n"), &SceneOrigin::Text).unwrap();
    let c = Camera::for_scene(&target_only, 1.5);
    assert!((c.target - glam::Vec3::splat(0.1)).length() < 1e-6, "{c:?}");
}

const JSON: &str = include_str!("../data/splishsplash_dam_break.json");

#[test]
fn a_splishsplash_scene_wgsph_refuses_is_refused_by_its_json_keys() {
    let import = |text: &str| scene_from_json(text, "t", &SceneOrigin::Text).unwrap_err().to_string();
    for (from, to, key) in [
        ("\"particleRadius\": 0.01", "\"particleRadius\": -0.01", "Configuration.particleRadius"),
        ("\"timeStepSize\": 0.0002", "\"timeStepSize\": 0", "Configuration.timeStepSize"),
        ("\"stiffness\": 50000", "\"stiffness\": 1e300", "Configuration.stiffness"),
        ("\"density0\": 1000", "\"density0\": 1e300", "Fluid.density0"),
        ("\"viscosity\": 0.01", "\"viscosity\": 1e300", "Fluid.viscosity"),
        ("\"gravitation\": [0, -9.81, 0]", "\"gravitation\": [0, -1e300, 0]", "Configuration.gravitation"),
        ("\"initialVelocity\": [0.5, 0, 0]", "\"initialVelocity\": [0.5, 0, 0]}, {\"start\": [0.0, 0.0, 0.0], \"end\": [0.1, 0.1, 0.05]", "FluidBlocks[1]"),
    ] {
        let text = JSON.replace(from, to);
        assert_ne!(text, JSON, "{from}");
        let e = import(&text);
        assert!(e.contains(key), "{to}: {e}");
        // The value named is the file's, not what the import made of it.
        if key == "Configuration.particleRadius" {
            assert!(e.contains("is -0.01; must be"), "{e}");
        }
        for internal in ["physics.", "time.", "fluid[", "boundary["] {
            assert!(!e.contains(internal), "{to}: names a wgsph field: {e}");
        }
    }
}

/// The host memory a scene needs is checked before any particle exists: building any scene asks
/// `SCENE_BYTES_PER_PARTICLE` per particle (fluid and walls), the CPU backend its own, larger
/// figure when it opens; each refusal names the counts and the memory. (Before, the scene check
/// asked the CPU backend's figure of every backend, and refused GPU runs that fit.)
#[test]
fn the_host_memory_a_scene_needs_is_checked_before_any_particle_exists() {
    use wgsph::model::check::{available_memory_bytes, CPU_BYTES_PER_PARTICLE, MAX_PARTICLES, SCENE_BYTES_PER_PARTICLE};
    use wgsph::solver::{open, BackendChoice, Precision};
    let Some(available) = available_memory_bytes() else {
        eprintln!("this platform gives no figure of available memory: nothing to check");
        return;
    };
    let dam_break = Scene::load("dam_break").unwrap();
    // Between the two figures (the walls add a fifth or so to the fluid): a scene to build, too
    // big for the CPU backend, which refuses it before generating a particle.
    let between = dam_break.with_fluid_particles(available / ((SCENE_BYTES_PER_PARTICLE + CPU_BYTES_PER_PARTICLE) / 2));
    let count = between.estimated_particle_count();
    assert!(count * SCENE_BYTES_PER_PARTICLE < available && count * CPU_BYTES_PER_PARTICLE > available, "{count} particles");
    between.validate(&SceneOrigin::Text).expect("a scene that fits the host is accepted");
    let e = open(&between, &BackendChoice::cpu(Precision::F32)).err().expect("the CPU backend refuses it");
    let e = format!("{e:#}");
    assert!(e.contains("of host memory on the cpu backend") && e.contains(&format!("{count} particles")) && e.contains("MiB are available"), "{e}");
    // Twice what the host has, at the scene's own figure: refused at load, naming the field.
    let over = dam_break.with_fluid_particles(2 * available / SCENE_BYTES_PER_PARTICLE);
    if over.estimated_particle_count() > MAX_PARTICLES {
        eprintln!("this host's memory is beyond {MAX_PARTICLES} particles: that limit refuses first");
        return;
    }
    let e = over.validate(&SceneOrigin::File("big.toml".into())).expect_err("refused").to_string();
    assert!(e.contains("big.toml") && e.contains("fluid") && e.contains("of host memory") && e.contains("MiB are available"), "{e}");
}

/// The CPU path's neighbour lists grow as (h / spacing)^3: a scene of 216,000 fluid particles
/// with h = 40 spacings (268,000 neighbours each, about 1 MB of lists per particle) fits the
/// host at the per-particle figure alone, and is refused when the CPU backend opens, naming
/// the lists, instead of being killed for memory mid-step.
#[test]
fn the_cpu_paths_neighbour_lists_are_counted_in_its_memory() {
    use wgsph::model::check::{available_memory_bytes, cpu_list_bytes_per_fluid_particle, CPU_BYTES_PER_PARTICLE};
    use wgsph::solver::{open, BackendChoice, Precision};
    let Some(available) = available_memory_bytes() else {
        eprintln!("this platform gives no figure of available memory: nothing to check");
        return;
    };
    let wide = Scene::from_toml_str(
        "[domain]\nmin = [0.0, 0.0, 0.0]\nmax = [2.0, 2.0, 2.0]\n[physics]\nsmoothing_length = 0.4\nparticle_spacing = 0.01\nspeed_of_sound = 10.0\n[time]\ndt = 0.0001\nend_time = 0.01\n[[fluid]]\nmin = [0.5, 0.5, 0.5]\nmax = [1.1, 1.1, 1.1]\n",
        &SceneOrigin::Text,
    )
    .unwrap();
    let fluid = wide.fluid_particle_count();
    assert_eq!(fluid, 216_000);
    let lists = fluid * cpu_list_bytes_per_fluid_particle(0.4, 0.01);
    if lists < available {
        eprintln!("this host holds {} MiB: the lists of {fluid} particles fit", available >> 20);
        return;
    }
    assert!(fluid * CPU_BYTES_PER_PARTICLE < available);
    let e = format!("{:#}", open(&wide, &BackendChoice::cpu(Precision::F32)).err().expect("the CPU backend refuses it"));
    assert!(e.contains("of host memory on the cpu backend (with its neighbour lists)") && e.contains("MiB are available"), "{e}");
}

/// A kernel and smoothing length whose sum over the particle lattice is off by more than 2 %
/// start the fluid away from its rest density: the scene loads with a warning that says so and
/// what would start it at rest (Wendland's function needs about 3 spacings, the cubic spline 2).
#[test]
fn a_lattice_that_does_not_start_at_rest_density_is_warned_of() {
    use wgsph::model::kernels::lattice_kernel_sum;
    use wgsph::model::scene::Kernel;
    // The sums the warning's advice rests on (simple cubic lattice, m = rho0 s^3).
    for (kernel, over, want) in [(Kernel::CubicSpline, 2.0, 1.0000), (Kernel::Mueller, 2.0, 1.0098), (Kernel::Wendland, 2.0, 1.0338), (Kernel::Wendland, 3.0, 1.0031), (Kernel::CubicSpline, 1.5, 1.0932)] {
        let got = lattice_kernel_sum(kernel, over);
        assert!((got - want).abs() < 1e-4, "{kernel:?} at {over} spacings: {got}");
    }
    let dam_break = Scene::load("dam_break").unwrap();
    assert_eq!(dam_break.rest_density_warning(), None, "the built-in dam break starts at rest (1.0098 rho0)");
    let mut wendland = dam_break.clone();
    wendland.physics.kernel = Kernel::Wendland;
    let w = wendland.rest_density_warning().expect("2 spacings are too few for Wendland's function");
    assert!(w.contains("\"wendland\"") && w.contains("1.03") && w.contains("apart") && w.contains("3 spacings") && w.contains("physics.particle_mass"), "{w}");
    // The mass it proposes starts the lattice at rest, and then nothing is said.
    let mass = dam_break.physics.rest_density * dam_break.physics.particle_spacing.powi(3) / lattice_kernel_sum(Kernel::Wendland, 2.0);
    wendland.physics.particle_mass = Some(mass);
    assert!((wendland.lattice_rest_density_ratio() - 1.0).abs() < 1e-12 && wendland.rest_density_warning().is_none());
    wendland.physics.particle_mass = None;
    wendland.physics.smoothing_length = 3.0 * wendland.physics.particle_spacing;
    assert_eq!(wendland.rest_density_warning(), None);
    // Too few neighbours the other way: a lattice that starts too light is pulled together.
    let mut thin = dam_break.clone();
    thin.physics.smoothing_length = 1.5 * thin.physics.particle_spacing;
    let w = thin.rest_density_warning().expect("Mueller's kernels at 1.5 spacings");
    assert!(w.contains("0.949") && w.contains("together"), "{w}");
    // And the command line prints it.
    let dir = tempfile::tempdir().unwrap();
    let out = wgsph(&["run", "dam_break", "--set", "physics.kernel=wendland", "--backend", "cpu", "--steps", "1", "--particles", "500", "--out", "o"], dir.path());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success() && err.contains("warning: physics.kernel = \"wendland\""), "{err}");
}
