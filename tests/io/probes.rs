//! Probes in scene files: parsed with their defaults, refused with the probe's name when they
//! cannot work; and their time series across a checkpoint and `--resume`: the same lines as an
//! uninterrupted run, none lost or written twice.

use crate::common;
use std::path::Path;
use wgsph::app::resume::resume_with;
use wgsph::app::run::{run, RunOptions};
use wgsph::io::checkpoint::{read, CHECKPOINT_FILE};
use wgsph::model::probes::{ProbeGeometry, ProbeInterval};
use wgsph::model::scene::{ProbeSpec, ProbeType};
use wgsph::model::scene::{Scene, SceneOrigin};
use wgsph::solver::Backend;

/// The built-in hydrostatic tank (its container is boundary 0) with `probes` appended.
fn tank_with(probes: &str) -> Result<Scene, String> {
    let text = format!("{}\n{probes}", Scene::builtin("hydrostatic").unwrap().to_toml());
    Scene::from_toml_str(&text, &SceneOrigin::Text).map_err(|e| e.to_string())
}

#[test]
fn probe_tables_are_read_with_their_defaults() {
    let scene = tank_with(
        r#"
[[probe]]
name = "p1"
type = "point"
position = [0.2, 0.1, 0.05]
every_seconds = 0.01

[[probe]]
name = "gauge-A"
type = "gauge"
position = [0.2, 0.0, 0.05]

[[probe]]
name = "walls"
type = "force"
boundary = 0
every_steps = 3

[[probe]]
name = "front"
type = "front"
direction = [2.0, 0.0, 0.0]
"#,
    )
    .unwrap();
    let p = scene.params().probes;
    assert_eq!(p.probes.len(), 4);
    assert_eq!(p.probes[0].interval, ProbeInterval::Seconds(0.01));
    assert_eq!(p.probes[1].interval, ProbeInterval::Steps(1));
    assert_eq!(p.probes[2].interval, ProbeInterval::Steps(3));
    match &p.probes[1].geometry {
        ProbeGeometry::Gauge { top, bottom, step, .. } => {
            assert_eq!((*top, *bottom), (scene.domain.max[1], 0.0));
            assert_eq!(*step, scene.physics.particle_spacing / 4.0);
        }
        other => panic!("{other:?}"),
    }
    match &p.probes[2].geometry {
        // The moment about the container's centre by default.
        ProbeGeometry::Force { centre, .. } => assert_eq!(*centre, [0.2, 0.3, 0.05]),
        other => panic!("{other:?}"),
    }
    match &p.probes[3].geometry {
        ProbeGeometry::Front { direction, floor, height } => {
            assert_eq!((*direction, *floor, *height), ([1.0, 0.0, 0.0], 0.0, scene.physics.smoothing_length));
        }
        other => panic!("{other:?}"),
    }
    // A scene with probes survives its own copy (the run directory's scene.toml).
    assert_eq!(Scene::from_toml_str(&scene.to_toml(), &SceneOrigin::Text).unwrap(), scene);
    // Due: every 3 steps; every 0.01 s at the first step reaching each multiple.
    assert!(p.probes[2].due(6, 0.0, 0.0) && !p.probes[2].due(7, 0.0, 0.0));
    assert!(p.probes[0].due(34, 0.0102, 0.0099) && !p.probes[0].due(35, 0.0105, 0.0102));
}

#[test]
fn probes_that_cannot_work_are_refused_naming_the_probe() {
    let point = |name: &str, at: &str| format!("[[probe]]\nname = \"{name}\"\ntype = \"point\"\nposition = {at}\n");
    let cases = [
        (point("p", "[0.2, 0.1, 0.05]") + "colour = 1\n", vec!["unknown field", "colour"]),
        (point("far", "[0.2, 3.0, 0.05]"), vec!["probe[0] ('far').position", "outside the domain"]),
        // Inside the container's floor layers (the wall particles lie below y = 0).
        (point("buried", "[0.2, -0.03, 0.05]"), vec!["probe[0] ('buried').position", "inside boundary[0]", "on a solid's face is allowed"]),
        (point("twice", "[0.2, 0.1, 0.05]") + &point("twice", "[0.1, 0.1, 0.05]"), vec!["probe[1].name", "the probe 'twice', which probe[0] declares too"]),
        (point("a/b", "[0.2, 0.1, 0.05]"), vec!["probe[0].name", "'a/b'", "letters, digits"]),
        (point("both", "[0.2, 0.1, 0.05]") + "every_steps = 2\nevery_seconds = 0.1\n", vec!["probe[0] ('both').every_steps", "both given"]),
        (point("never", "[0.2, 0.1, 0.05]") + "every_steps = 0\n", vec!["('never').every_steps", "is 0"]),
        (point("odd", "[0.2, 0.1, 0.05]") + "boundary = 0\n", vec!["('odd').boundary", "does not apply to a probe of type \"point\""]),
        ("[[probe]]\nname = \"g\"\ntype = \"gauge\"\n".into(), vec!["('g').position", "is missing"]),
        ("[[probe]]\nname = \"f\"\ntype = \"force\"\nboundary = 40\n".into(), vec!["('f').boundary", "is 40", "[[boundary]] tables (indices from 0)"]),
        ("[[probe]]\nname = \"f\"\ntype = \"force\"\n".into(), vec!["('f').boundary", "is missing"]),
        ("[[probe]]\nname = \"d\"\ntype = \"front\"\ndirection = [0.0, 0.0, 0.0]\n".into(), vec!["('d').direction", "non-zero"]),
    ];
    for (probes, expected) in cases {
        let e = tank_with(&probes).expect_err(&probes);
        for part in expected {
            assert!(e.contains(part), "'{part}' is not in the error for\n{probes}\n{e}");
        }
    }
    // A plane has no wall particles to feel a force.
    let planes = common::TestScene::new().fluid([0.0; 3], [0.2, 0.2, 0.2]).plane([0.0; 3], [0.0, 1.0, 0.0], 0.0);
    let e = planes.probe(ProbeSpec { boundary: Some(0), ..ProbeSpec::of("on_plane", ProbeType::Force) }).validation_error();
    assert!(e.contains("an analytic plane"), "{e}");
    // DFSPH has every probe type.
    let dfsph = || common::TestScene::small_tank().dfsph();
    assert!(dfsph().probe(ProbeSpec { boundary: Some(0), ..ProbeSpec::of("walls", ProbeType::Force) }).build().params().probes.force_count() == 1);
    assert!(dfsph().probe(ProbeSpec::point("inside", [0.1, 0.1, 0.1], 5)).build().params().probes.probes.len() == 1);
}

/// A point or gauge table with `to` and `count` is a row of probes: evenly spaced, both ends
/// included, named NAME_0.. (zero-padded), each checked as a probe of its own, each counted
/// towards the 64 a scene may hold; a run writes a file and a plot for each.
#[test]
fn a_row_of_probes_is_probes_evenly_spaced_from_position_to_to() {
    let scene = tank_with("[[probe]]\nname = \"row\"\ntype = \"point\"\nposition = [0.1, 0.1, 0.05]\nto = [0.3, 0.1, 0.05]\ncount = 3\nevery_steps = 2\n\n[[probe]]\nname = \"g\"\ntype = \"gauge\"\nposition = [0.0, 0.0, 0.05]\nto = [0.4, 0.0, 0.05]\ncount = 11\ntop = 0.5\n").unwrap();
    let p = scene.params().probes;
    let names: Vec<&str> = p.probes.iter().map(|q| q.name.as_str()).collect();
    assert_eq!(names[..4], ["row_0", "row_1", "row_2", "g_00"]);
    assert_eq!((names.len(), names[13]), (14, "g_10"));
    let xs: Vec<[f64; 3]> = p.probes[..3]
        .iter()
        .map(|q| match q.geometry {
            ProbeGeometry::Point { position } => position,
            ref other => panic!("{other:?}"),
        })
        .collect();
    assert_eq!(xs, [[0.1, 0.1, 0.05], [0.2, 0.1, 0.05], [0.3, 0.1, 0.05]]);
    assert!(p.probes[..3].iter().all(|q| q.interval == ProbeInterval::Steps(2)));
    match p.probes[13].geometry {
        ProbeGeometry::Gauge { x, z, bottom, top, .. } => assert_eq!((x, z, bottom, top), (0.4, 0.05, 0.0, 0.5)),
        ref other => panic!("{other:?}"),
    }
    // The table round-trips as a row.
    assert_eq!(Scene::from_toml_str(&scene.to_toml(), &SceneOrigin::Text).unwrap(), scene);

    let row = |at: &str, to: &str, count: &str| format!("[[probe]]\nname = \"r\"\ntype = \"point\"\nposition = {at}\n{to}{count}");
    let cases = [
        (row("[0.1, 0.1, 0.05]", "to = [0.3, 0.1, 0.05]\n", ""), vec!["probe[0] ('r').to", "without count"]),
        (row("[0.1, 0.1, 0.05]", "", "count = 3\n"), vec!["probe[0] ('r').count", "without to"]),
        (row("[0.1, 0.1, 0.05]", "to = [0.3, 0.1, 0.05]\n", "count = 1\n"), vec!["('r').count", "is 1; a row holds 2 to 64"]),
        (
            row("[0.1, 0.1, 0.05]", "to = [0.3, 0.1, 0.05]\n", "count = 3\n").replace("\"r\"", &format!("\"{}\"", "r".repeat(63))),
            vec!["probe[0].name", "65 characters; a probe's name is at most 64"],
        ),
        (row("[0.1, 0.1, 0.05]", "to = [0.3, 3.0, 0.05]\n", "count = 3\n"), vec!["probe[0] ('r').to", "outside the domain"]),
        (row("[0.1, 0.1, 0.05]", "to = [0.3, 0.1, 0.05]\n", "count = 60\n") + &row("[0.1, 0.2, 0.05]", "to = [0.3, 0.2, 0.05]\n", "count = 5\n").replace("\"r\"", "\"s\""), vec!["declares 65 probes", "at most 64"]),
        (row("[0.1, 0.1, 0.05]", "to = [0.3, 0.1, 0.05]\n", "count = 2\n") + "\n[[probe]]\nname = \"r_1\"\ntype = \"point\"\nposition = [0.2, 0.2, 0.05]\n", vec!["probe[1].name", "the probe 'r_1', which probe[0] declares too"]),
        ("[[probe]]\nname = \"f\"\ntype = \"force\"\nboundary = 0\ncount = 2\n".into(), vec!["('f').count", "does not apply to a probe of type \"force\""]),
    ];
    for (probes, expected) in cases {
        let e = tank_with(&probes).expect_err(&probes);
        for part in expected {
            assert!(e.contains(part), "'{part}' is not in the error for\n{probes}\n{e}");
        }
    }
    // A gauge row whose top is below one of its bottoms names that gauge.
    let e = tank_with("[[probe]]\nname = \"g\"\ntype = \"gauge\"\nposition = [0.1, 0.0, 0.05]\nto = [0.3, 0.4, 0.05]\ncount = 3\ntop = 0.3\n").unwrap_err();
    assert!(e.contains("('g').top") && e.contains("the gauge 'g_2'"), "{e}");

    // A run writes each probe's series and plot.
    let dir = tempfile::tempdir().unwrap();
    let set = "probe=[{name=\"row\",type=\"point\",position=[0.1,0.1,0.05],to=[0.3,0.1,0.05],count=3}]";
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_wgsph"))
        .args(["run", "hydrostatic", "--particles", "300", "--steps", "3", "--backend", "cpu", "--quiet", "--set", set, "--out", "o"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let files: Vec<String> = probe_files(&dir.path().join("o")).into_iter().map(|(name, _)| name).collect();
    assert_eq!(files, ["row_0.csv", "row_1.csv", "row_2.csv"]);
    assert!((0..3).all(|k| dir.path().join(format!("o/probes/row_{k}.png")).exists()));
}

fn probe_files(dir: &Path) -> Vec<(String, String)> {
    let mut v: Vec<(String, String)> = std::fs::read_dir(dir.join("probes"))
        .unwrap()
        .map(|e| e.unwrap())
        .filter(|e| e.path().extension().is_some_and(|x| x == "csv"))
        .map(|e| (e.file_name().to_string_lossy().into_owned(), std::fs::read_to_string(e.path()).unwrap()))
        .collect();
    v.sort();
    v
}

/// Runs 40 steps whole, and 40 steps stopped at step 27 (after a checkpoint at step 20 and a
/// write of the series up to step 26) and resumed: every probe's file is the same text, each
/// sample once, with the same plot beside it.
fn series_continue_across_a_resume(make: &mut dyn FnMut() -> Box<dyn Backend>, scene: &Scene, what: &str) {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    let opts = |out: &Path, steps, checkpoint_every| RunOptions { steps, out: out.to_path_buf(), snapshot_every: 20, check_every: 9, checkpoint_every, ..Default::default() };
    let whole = run(make().as_mut(), scene, &opts(&a, 40, 0)).unwrap();
    assert!(whole.failure.is_none(), "{what}");
    // The first run stops at step 27 with its series written on to step 26, past its checkpoint.
    run(make().as_mut(), scene, &opts(&b, 27, 20)).unwrap();
    let c = read(&b.join(CHECKPOINT_FILE)).unwrap();
    assert_eq!(c.state.step, 20, "{what}");
    let resumed = resume_with(make().as_mut(), &b, &c, 40, false, true).unwrap();
    assert!(resumed.failure.is_none(), "{what}");
    let (x, y) = (probe_files(&a), probe_files(&b));
    assert_eq!(x.len(), scene.probe.len(), "{what}");
    for ((name, whole), (_, resumed)) in x.iter().zip(&y) {
        assert_eq!(whole, resumed, "{what}: {name} differs after the resume");
        let steps: Vec<u64> = whole.lines().skip(1).map(|l| l.split(',').nth(1).unwrap().parse().unwrap()).collect();
        assert!(steps.windows(2).all(|w| w[0] < w[1]) && steps.first() == Some(&0), "{what}: {name} steps {steps:?}");
        // The plot is drawn from the numbers as the file holds them: the same picture.
        let png = |dir: &Path| std::fs::read(dir.join("probes").join(name.replace(".csv", ".png")));
        assert!(png(&b).is_ok(), "{what}: no plot of {name}");
        assert!(png(&a).unwrap() == png(&b).unwrap(), "{what}: the plot of {name} differs after the resume");
    }
}

/// The hydrostatic tank, small, with a point probe every 4 steps and a gauge every 2 ms, at a
/// fixed dt and with adaptive dt (whose probes timed in seconds keep the first sample of each
/// multiple, on the device's own clock).
fn scenes() -> Vec<(Scene, &'static str)> {
    let mut fixed = Scene::builtin("hydrostatic").unwrap().with_fluid_particles(400);
    let gauge = ProbeSpec { position: Some([0.2, 0.0, 0.05]), every_seconds: Some(0.002), ..ProbeSpec::of("gauge", ProbeType::Gauge) };
    fixed.probe = vec![ProbeSpec::point("mid", [0.2, 0.2, 0.05], 4), gauge];
    let mut adaptive = fixed.clone();
    adaptive.time.adaptive = true;
    vec![(fixed, "fixed dt"), (adaptive, "adaptive dt")]
}

#[test]
fn cpu_probe_series_continue_across_a_resume() {
    for (scene, how) in scenes() {
        series_continue_across_a_resume(&mut || Box::new(common::cpu::<f64>(&scene)), &scene, &format!("cpu f64, {how}"));
    }
}

#[test]
fn gpu_probe_series_continue_across_a_resume_on_every_adapter() {
    for (scene, how) in scenes() {
        for (i, ctx) in common::contexts().into_iter().enumerate() {
            let name = format!("{}, {how}", ctx.describe());
            drop(ctx);
            let mut make = || -> Box<dyn Backend> { Box::new(common::gpu(common::contexts().into_iter().nth(i).unwrap(), &scene)) };
            series_continue_across_a_resume(&mut make, &scene, &name);
        }
    }
}
