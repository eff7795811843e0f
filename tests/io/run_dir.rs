//! The run directory: the copy of the scene, --overwrite, --quiet and RUST_LOG.

use std::path::Path;
use std::process::{Command, Output};
use wgsph::model::scene::SceneOrigin;
use wgsph::model::builtin::BUILTIN_SCENES;
use wgsph::model::scene::Scene;

fn wgsph(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_wgsph")).args(args).current_dir(dir).env_remove("RUST_LOG").output().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn every_built_in_scene_round_trips_through_toml() {
    for (name, _, _) in BUILTIN_SCENES {
        let scene = Scene::builtin(name).unwrap();
        for s in [scene.clone(), scene.with_fluid_particles(777)] {
            let back = Scene::from_toml_str(&s.to_toml(), &SceneOrigin::Text).unwrap();
            assert_eq!(back, s, "{name}");
        }
    }
}

#[test]
fn the_run_directory_holds_the_exact_scene_that_reruns_identically() {
    let dir = tempfile::tempdir().unwrap();
    let args = ["--steps", "3", "--snapshot-every", "3", "--backend", "cpu"];
    let o = wgsph(&[&["run", "hydrostatic", "--particles", "500", "--out", "a"], &args[..]].concat(), dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let copy = Scene::load(dir.path().join("a/scene.toml").to_str().unwrap()).unwrap();
    assert_eq!(copy, Scene::builtin("hydrostatic").unwrap().with_fluid_particles(500));
    let o = wgsph(&[&["run", "a/scene.toml", "--out", "b"], &args[..]].concat(), dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let read = |d: &str| std::fs::read(dir.path().join(d).join("snapshots/step_000003.csv")).unwrap();
    assert_eq!(read("a"), read("b"));
}

#[test]
fn an_existing_output_directory_is_refused_without_overwrite_and_replaced_with_it() {
    let dir = tempfile::tempdir().unwrap();
    let run = |extra: &[&str]| wgsph(&[&["run", "hydrostatic", "--steps", "1", "--backend", "cpu", "--out", "o"], extra].concat(), dir.path());
    // An empty directory is used as it is.
    std::fs::create_dir(dir.path().join("o")).unwrap();
    assert!(run(&[]).status.success());
    std::fs::write(dir.path().join("o/notes.txt"), "mine").unwrap();
    let before = std::fs::read(dir.path().join("o/summary.json")).unwrap();
    let o = run(&[]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--out o") && stderr(&o).contains("--overwrite"), "{}", stderr(&o));
    assert_eq!(std::fs::read(dir.path().join("o/summary.json")).unwrap(), before);
    assert!(dir.path().join("o/notes.txt").exists());
    let o = run(&["--overwrite"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!dir.path().join("o/notes.txt").exists(), "the old directory was replaced");
    assert!(dir.path().join("o/summary.json").exists());
    // A file in the way, and a directory holding the working directory, are refused.
    std::fs::write(dir.path().join("f"), "").unwrap();
    assert_eq!(wgsph(&["run", "--steps", "1", "--out", "f", "--overwrite"], dir.path()).status.code(), Some(2));
    let o = wgsph(&["run", "--steps", "1", "--out", ".", "--overwrite"], &dir.path().join("o"));
    assert_eq!(o.status.code(), Some(2));
    assert!(dir.path().join("o/summary.json").exists(), "{}", stderr(&o));
}

#[test]
fn quiet_prints_nothing_and_rust_log_sets_the_level() {
    let dir = tempfile::tempdir().unwrap();
    let o = wgsph(&["run", "hydrostatic", "--steps", "2", "--backend", "cpu", "--out", "q", "--quiet"], dir.path());
    assert!(o.status.success());
    assert!(o.stdout.is_empty() && o.stderr.is_empty(), "{:?} {:?}", String::from_utf8_lossy(&o.stdout), stderr(&o));
    let o = wgsph(&["run", "hydrostatic", "--steps", "2", "--backend", "cpu", "--out", "n"], dir.path());
    assert!(String::from_utf8_lossy(&o.stdout).contains("2 steps"));
    assert!(!stderr(&o).contains("INFO"), "{}", stderr(&o));
    let o = Command::new(env!("CARGO_BIN_EXE_wgsph"))
        .args(["run", "hydrostatic", "--steps", "2", "--backend", "cpu", "--out", "l"])
        .current_dir(dir.path())
        .env("RUST_LOG", "wgsph=info")
        .output()
        .unwrap();
    assert!(o.status.success());
    assert!(stderr(&o).contains("INFO") && stderr(&o).contains("step_000002.csv"), "{}", stderr(&o));
}

/// Output files are written through private temporary files; once in place they have the
/// permissions of any new file (0666 less the umask), not the temporary file's 0600.
#[cfg(unix)]
#[test]
fn outputs_get_the_permissions_of_new_files() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let bin = env!("CARGO_BIN_EXE_wgsph");
    for (umask, mode) in [("022", 0o644), ("027", 0o640)] {
        let out = format!("o{umask}");
        let status = std::process::Command::new("sh")
            .args(["-c", &format!("umask {umask}; exec '{bin}' run seed --steps 2 --backend cpu --quiet --out {out}")])
            .current_dir(dir.path())
            .status()
            .unwrap();
        assert!(status.success());
        for file in ["summary.json", "scene.toml", "snapshots/step_000000.csv"] {
            let got = std::fs::metadata(dir.path().join(&out).join(file)).unwrap().permissions().mode() & 0o777;
            assert_eq!(got, mode, "{file} with umask {umask}: {got:o}");
        }
    }
}
