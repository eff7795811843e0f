//! The run directory: the copy of the scene, --overwrite and what it may replace, output
//! locations checked before anything changes, a failed start undone, a full disk, --quiet and
//! RUST_LOG.

use crate::common;
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

fn read(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Every file under `dir` (relative paths, sorted) with its bytes.
fn tree(dir: &Path) -> Vec<(String, Vec<u8>)> {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<(String, Vec<u8>)>) {
        for e in std::fs::read_dir(dir).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                out.push((p.strip_prefix(root).unwrap().display().to_string() + "/", Vec::new()));
                walk(root, &p, out);
            } else {
                out.push((p.strip_prefix(root).unwrap().display().to_string(), read(&p)));
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort();
    out
}

#[test]
fn an_existing_output_directory_is_refused_without_overwrite_and_replaced_with_it() {
    let dir = tempfile::tempdir().unwrap();
    let run = |extra: &[&str]| wgsph(&[&["run", "hydrostatic", "--steps", "1", "--backend", "cpu", "--out", "o"], extra].concat(), dir.path());
    // An empty directory is used as it is.
    std::fs::create_dir(dir.path().join("o")).unwrap();
    assert!(run(&[]).status.success());
    let before = tree(&dir.path().join("o"));
    let o = run(&[]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--out o") && stderr(&o).contains("--overwrite"), "{}", stderr(&o));
    assert_eq!(tree(&dir.path().join("o")), before);
    let o = run(&["--overwrite"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(dir.path().join("o/summary.json").exists());
    // A file in the way is refused.
    std::fs::write(dir.path().join("f"), "").unwrap();
    let o = wgsph(&["run", "--steps", "1", "--out", "f", "--overwrite"], dir.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--out f: is a file"), "{}", stderr(&o));
}

/// `--out Documents --overwrite` once removed a folder of the user's own files.
#[test]
fn overwrite_refuses_a_directory_that_no_run_wrote() {
    let dir = tempfile::tempdir().unwrap();
    let docs = dir.path().join("Documents");
    std::fs::create_dir_all(docs.join("photos")).unwrap();
    std::fs::write(docs.join("notes.txt"), "mine").unwrap();
    std::fs::write(docs.join("photos/cat.png"), "meow").unwrap();
    let before = tree(&docs);
    for extra in [&[][..], &["--overwrite"][..]] {
        let o = wgsph(&[&["run", "hydrostatic", "--steps", "1", "--backend", "cpu", "--out", "Documents"], extra].concat(), dir.path());
        assert_eq!(o.status.code(), Some(2), "{extra:?}: {}", stderr(&o));
        let err = stderr(&o);
        assert!(err.contains("--out Documents") && err.contains("notes.txt") && err.contains(".wgsph-run"), "{err}");
        assert_eq!(tree(&docs), before, "{extra:?}: the directory was changed");
    }
    // Also from inside it.
    let o = wgsph(&["run", "hydrostatic", "--steps", "1", "--backend", "cpu", "--out", ".", "--overwrite"], &docs);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert_eq!(tree(&docs), before);
}

/// A run directory whose snapshots/ (or surface/, probes/) is a link to a folder of the user's
/// is refused, with or without --overwrite: replacing the earlier run's snapshots there once
/// deleted and replaced the user's files.
#[test]
fn overwrite_refuses_a_run_directory_whose_subdirectory_is_a_link() {
    let dir = tempfile::tempdir().unwrap();
    let o = wgsph(&["run", "hydrostatic", "--steps", "1", "--backend", "cpu", "--out", "r1"], dir.path());
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let mine = dir.path().join("mine");
    std::fs::create_dir(&mine).unwrap();
    std::fs::write(mine.join("step_000000.csv"), "my data").unwrap();
    std::fs::write(mine.join("step_000009.csv"), "more of mine").unwrap();
    let before = tree(&mine);
    for sub in ["snapshots", "surface", "probes"] {
        let link = dir.path().join("r1").join(sub);
        let _ = std::fs::remove_dir_all(&link);
        std::os::unix::fs::symlink("../mine", &link).unwrap();
        for extra in [&[][..], &["--overwrite"][..]] {
            let o = wgsph(&[&["run", "hydrostatic", "--steps", "1", "--backend", "cpu", "--out", "r1"], extra].concat(), dir.path());
            let err = stderr(&o);
            assert_eq!(o.status.code(), Some(2), "{sub} {extra:?}: {err}");
            assert!(err.contains(&format!("r1/{sub} is a link to ../mine")) && err.contains("remove the link"), "{err}");
            assert_eq!(tree(&mine), before, "{sub} {extra:?}: the linked folder was changed");
        }
        std::fs::remove_file(&link).unwrap();
    }
    // A file where the run writes a directory is named too.
    std::fs::write(dir.path().join("r1/surface"), "not a directory").unwrap();
    let o = wgsph(&["run", "hydrostatic", "--steps", "1", "--backend", "cpu", "--out", "r1", "--overwrite"], dir.path());
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("r1/surface is a file, where a run writes its surface/ directory"), "{}", stderr(&o));
}

/// `--overwrite` replaces the files an earlier run wrote, and nothing else: not a file the user
/// put beside them, and not the scene being run.
#[test]
fn overwrite_replaces_only_what_a_run_wrote_and_never_the_scene_being_run() {
    let dir = tempfile::tempdir().unwrap();
    let o = dir.path().join("o");
    let run = |args: &[&str]| wgsph(&[&["run"], args, &["--backend", "cpu", "--snapshot-every", "1"]].concat(), dir.path());
    assert!(run(&["hydrostatic", "--particles", "300", "--steps", "3", "--out", "o"]).status.success());
    std::fs::write(o.join("notes.txt"), "mine").unwrap();
    std::fs::write(o.join("snapshots/my_plot.csv"), "x,y").unwrap();
    // The scene copy of the earlier run, run into its own directory: refused, nothing changed.
    let before = tree(&o);
    let r = run(&["o/scene.toml", "--steps", "1", "--out", "o", "--overwrite"]);
    assert_eq!(r.status.code(), Some(2), "{}", stderr(&r));
    assert!(stderr(&r).contains("scene.toml") && stderr(&r).contains("reads"), "{}", stderr(&r));
    assert_eq!(tree(&o), before);
    // A scene file the user keeps in the run directory stays.
    std::fs::copy(o.join("scene.toml"), o.join("mine.toml")).unwrap();
    let r = run(&["o/mine.toml", "--steps", "1", "--out", "o", "--overwrite"]);
    assert!(r.status.success(), "{}", stderr(&r));
    assert!(stderr(&r).contains("keeps") && stderr(&r).contains("notes.txt"), "{}", stderr(&r));
    let names: Vec<String> = tree(&o).into_iter().map(|f| f.0).collect();
    for kept in ["notes.txt", "mine.toml", "snapshots/my_plot.csv"] {
        assert!(names.contains(&kept.to_string()), "{kept} was removed: {names:?}");
    }
    assert!(!names.iter().any(|n| n.contains("step_000003") || n.contains("step_000002")), "the earlier run's snapshots stayed: {names:?}");
    assert!(!names.iter().any(|n| n.contains(".wgsph-replaced") || n.contains(".wgsph-tmp")), "{names:?}");
    let summary: serde_json::Value = serde_json::from_slice(&read(&o.join("summary.json"))).unwrap();
    assert_eq!(summary["steps"], 1);
}

/// `--overwrite` replaces in snapshots/, surface/ and probes/ only files of the kinds the
/// earlier run wrote (its marker records its formats, surface meshes and probes): a user's file
/// there named like another run's output stays, and one this run would write over is in the
/// way (exit 2, nothing changed).
#[test]
fn overwrite_replaces_only_the_kinds_of_file_the_earlier_run_wrote() {
    let dir = tempfile::tempdir().unwrap();
    let o = dir.path().join("o");
    let run = |extra: &[&str]| wgsph(&[&["run", "hydrostatic", "--particles", "300", "--steps", "3", "--backend", "cpu", "--out", "o"][..], extra].concat(), dir.path());
    assert!(run(&[]).status.success());
    // The earlier run wrote CSV snapshots, no surface meshes and no probes.
    let mine = ["probes/data.csv", "probes/data.png", "snapshots/step_000050.vtk", "surface/step_000000.obj"];
    for f in mine {
        std::fs::create_dir_all(o.join(f).parent().unwrap()).unwrap();
        std::fs::write(o.join(f), "mine").unwrap();
    }
    let r = run(&["--overwrite"]);
    assert!(r.status.success(), "{}", stderr(&r));
    for f in mine {
        assert_eq!(std::fs::read_to_string(o.join(f)).unwrap(), "mine", "{f}");
    }
    assert!(stderr(&r).contains("keeps") && stderr(&r).contains("snapshots/step_000050.vtk"), "{}", stderr(&r));
    // A run writing VTK would replace the user's step_000050.vtk's kind: refused, nothing changed.
    let before = tree(&o);
    let r = run(&["--overwrite", "--format", "vtk"]);
    assert_eq!(r.status.code(), Some(2), "{}", stderr(&r));
    assert!(stderr(&r).contains("step_000050.vtk is in the way"), "{}", stderr(&r));
    assert_eq!(tree(&o), before);
    // Once moved, the VTK run replaces the CSV run, and a later CSV run replaces its VTK files.
    std::fs::remove_file(o.join("snapshots/step_000050.vtk")).unwrap();
    assert!(run(&["--overwrite", "--format", "vtk"]).status.success());
    assert!(o.join("snapshots/step_000003.vtk").is_file() && !o.join("snapshots/step_000003.csv").exists());
    assert!(run(&["--overwrite"]).status.success());
    assert!(o.join("snapshots/step_000003.csv").is_file() && !o.join("snapshots/step_000003.vtk").exists());
    assert!(!o.join("snapshots/particles.vtk.series").exists());
    for f in ["probes/data.csv", "probes/data.png", "surface/step_000000.obj"] {
        assert_eq!(std::fs::read_to_string(o.join(f)).unwrap(), "mine", "{f}");
    }
}

/// Runs wgsph with `dir` made read-only: in a user namespace where `dir` is a read-only bind
/// mount (root ignores file permissions), else by its permissions. `None` where neither works.
#[cfg(unix)]
fn with_read_only(dir: &Path, args: &[&str], cwd: &Path) -> Option<Output> {
    use std::os::unix::fs::PermissionsExt;
    let bin = env!("CARGO_BIN_EXE_wgsph");
    let d = dir.display().to_string();
    let script = format!("mount --bind '{d}' '{d}' && mount -o remount,bind,ro '{d}' && exec \"$@\"");
    let namespaced = Command::new("unshare").args(["-rm", "sh", "-c", &script, "sh", bin]).args(args).current_dir(cwd).env_remove("RUST_LOG").output();
    if let Ok(o) = namespaced {
        if !String::from_utf8_lossy(&o.stderr).contains("unshare:") && !String::from_utf8_lossy(&o.stderr).contains("mount:") {
            return Some(o);
        }
    }
    let is_root = Command::new("id").arg("-u").output().is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0");
    if is_root {
        eprintln!("SKIPPED: no user namespace to make {d} read-only, and root ignores permissions");
        return None;
    }
    std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o555)).unwrap();
    let o = wgsph(args, cwd);
    std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o755)).unwrap();
    Some(o)
}

/// An unwritable `--out` or `--frames` is refused (exit 2, naming the path) before anything is
/// written or removed: `--overwrite --frames /read-only/dir` once removed the earlier run first.
#[cfg(unix)]
#[test]
fn unusable_output_locations_are_refused_before_anything_changes() {
    let dir = tempfile::tempdir().unwrap();
    let ro = dir.path().join("ro");
    std::fs::create_dir(&ro).unwrap();
    let args = ["run", "hydrostatic", "--particles", "300", "--steps", "2", "--backend", "cpu"];
    assert!(wgsph(&[&args[..], &["--out", "o"]].concat(), dir.path()).status.success());
    let before = tree(&dir.path().join("o"));
    // Frames below a file, and frames in a read-only directory.
    std::fs::write(dir.path().join("file"), "").unwrap();
    let o = wgsph(&[&args[..], &["--out", "o", "--overwrite", "--frames", "file/frames"]].concat(), dir.path());
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--frames file/frames"), "{}", stderr(&o));
    assert_eq!(tree(&dir.path().join("o")), before, "the earlier run was changed");
    // A name no file system holds: bad input too, before any work.
    let long = "n".repeat(300);
    for flag in ["--out", "--frames"] {
        let o = wgsph(&[&args[..], &[flag, &format!("x/{long}")]].concat(), dir.path());
        assert_eq!(o.status.code(), Some(2), "{flag}: {}", stderr(&o));
        assert!(stderr(&o).contains(&format!("{flag} x/{long}: cannot be created: the name nnnnnnnnnnnnnnnnnnnn... is 300 bytes long")), "{}", stderr(&o));
        assert!(!dir.path().join("x").exists());
    }
    let Some(o) = with_read_only(&ro, &[&args[..], &["--out", "o", "--overwrite", "--frames", "ro/frames"]].concat(), dir.path()) else {
        return;
    };
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--frames ro/frames") && stderr(&o).contains("cannot write in ro"), "{}", stderr(&o));
    assert_eq!(tree(&dir.path().join("o")), before, "the earlier run was changed");
    // --out in a read-only directory, and a read-only --out itself.
    for out in ["ro/run", "ro"] {
        let o = with_read_only(&ro, &[&args[..], &["--out", out]].concat(), dir.path()).unwrap();
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        assert!(stderr(&o).contains(&format!("--out {out}:")) && stderr(&o).contains("ro"), "{}", stderr(&o));
    }
    assert!(tree(&ro).is_empty());
}

/// A run that fails before its first step (no adapter for --backend gpu, no adapter to draw
/// with, a state that is not finite at step 0) leaves its directories as it found them, so
/// that the retry is not refused.
#[test]
fn a_start_that_fails_leaves_the_directories_as_it_found_them() {
    let dir = tempfile::tempdir().unwrap();
    let no_adapter = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_wgsph")).args(args).current_dir(dir.path()).env("WGPU_ADAPTER_NAME", "no such adapter").output().unwrap()
    };
    let args = ["run", "hydrostatic", "--particles", "300", "--steps", "2"];
    std::fs::create_dir(dir.path().join("empty")).unwrap();
    assert!(wgsph(&[&args[..], &["--backend", "cpu", "--out", "earlier"]].concat(), dir.path()).status.success());
    let earlier = tree(&dir.path().join("earlier"));
    for (what, extra) in [
        ("--backend gpu into a new directory", &["--backend", "gpu", "--out", "a/new"][..]),
        ("--backend gpu into an empty directory", &["--backend", "gpu", "--out", "empty"][..]),
        ("--backend gpu over an earlier run", &["--backend", "gpu", "--out", "earlier", "--overwrite"][..]),
        ("pictures without an adapter", &["--backend", "cpu", "--out", "b", "--frames", "b/frames"][..]),
        ("pictures without an adapter, over an earlier run", &["--backend", "cpu", "--out", "earlier", "--overwrite", "--frames", "pictures"][..]),
    ] {
        let o = no_adapter(&[&args[..], extra].concat());
        assert_ne!(o.status.code(), Some(0), "{what}");
        assert!(!stderr(&o).contains("panicked"), "{what}: {}", stderr(&o));
        assert!(!dir.path().join("a").exists() && !dir.path().join("b").exists() && !dir.path().join("pictures").exists(), "{what}");
        assert!(tree(&dir.path().join("empty")).is_empty(), "{what}");
        assert_eq!(tree(&dir.path().join("earlier")), earlier, "{what}");
    }
    assert_eq!(no_adapter(&[&args[..], &["--backend", "gpu", "--out", "x"]].concat()).status.code(), Some(2), "no adapter for --backend gpu is bad input");
    // A state that is not finite at step 0 (a pressure beyond f64: rho/rho0 = 1e64, to the 7th).
    let o = wgsph(
        &[&args[..], &["--backend", "cpu", "--out", "c", "--set", "physics.rest_density=1e-60", "--set", "physics.particle_mass=1"]].concat(),
        dir.path(),
    );
    assert_ne!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(!dir.path().join("c").exists(), "{}", stderr(&o));
    // The retry works.
    let o = wgsph(&[&args[..], &["--backend", "cpu", "--out", "a/new"]].concat(), dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
}

/// A full disk names the step and the file being written (not a temporary file), and the
/// summary records the failure. Needs a small filesystem: a tmpfs in a user namespace.
#[cfg(target_os = "linux")]
#[test]
fn a_full_disk_names_the_step_and_the_file_and_the_summary_says_so() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("small")).unwrap();
    let bin = env!("CARGO_BIN_EXE_wgsph");
    // A CSV snapshot of the hydrostatic tank is about 200 KiB: the third does not fit. The
    // filesystem is gone with the namespace, so the summary and the listing come out on stdout.
    let script = "mount -t tmpfs -o size=512k tmpfs small || exit 99; \"$@\"; rc=$?; echo '=== summary'; cat small/run/summary.json; echo '=== files'; ls -A small/run/snapshots; exit $rc";
    let o = Command::new("unshare")
        .args(["-rm", "sh", "-c", script, "sh", bin])
        .args(["run", "hydrostatic", "--steps", "30", "--snapshot-every", "5", "--backend", "cpu", "--out", "small/run"])
        .current_dir(dir.path())
        .env_remove("RUST_LOG")
        .output();
    let o = match o {
        Ok(o) if o.status.code() != Some(99) && !stderr(&o).contains("unshare:") => o,
        _ => {
            eprintln!("SKIPPED: no user namespace to mount a small filesystem in");
            return;
        }
    };
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(err.contains("step 10: writing the snapshot: cannot write small/run/snapshots/step_000010.csv") && err.contains("No space left"), "{err}");
    assert!(!err.contains(".wgsph-tmp") && !err.contains(".tmp"), "{err}");
    assert!(err.contains("the last good snapshot is small/run/snapshots/step_000005.csv"), "{err}");
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    let (_, rest) = stdout.split_once("=== summary\n").expect("the summary was printed");
    let (json, files) = rest.split_once("=== files\n").expect("the files were listed");
    let summary: serde_json::Value = serde_json::from_str(json).unwrap_or_else(|e| panic!("{e}: {json}"));
    assert_eq!(summary["status"], "error");
    assert!(summary["failure"].as_str().unwrap().contains("step_000010.csv"), "{summary}");
    assert_eq!(summary["steps"], 10);
    // No partial file is left.
    assert_eq!(files.split_whitespace().collect::<Vec<_>>(), ["index.csv", "step_000000.csv", "step_000005.csv"]);
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

/// Without --out the run directory is named after the scene: a name too long for a file system
/// is named as the scene's, not as a flag the user never gave.
#[test]
fn a_scene_name_too_long_for_its_run_directory_is_named_as_the_cause() {
    let dir = tempfile::tempdir().unwrap();
    let name = format!("name={}", "n".repeat(300));
    let o = wgsph(&["run", "hydrostatic", "--particles", "300", "--steps", "1", "--backend", "cpu", "--set", &name], dir.path());
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("the run directory named after the scene's name (no --out given)") && stderr(&o).contains("at most 255"), "{}", stderr(&o));
    assert!(!dir.path().join("out").exists());
}

/// `--frames` at an earlier run's directory is refused even with `--overwrite`: the run's
/// snapshots, summary and checkpoint are not replaced by pictures. A directory that held only
/// pictures is replaced as before.
#[test]
fn overwrite_does_not_replace_a_run_with_the_pictures_of_another() {
    let dir = tempfile::tempdir().unwrap();
    let args = ["run", "hydrostatic", "--particles", "300", "--steps", "2", "--backend", "cpu"];
    assert!(wgsph(&[&args[..], &["--out", "a", "--checkpoint-every", "1"]].concat(), dir.path()).status.success());
    let before = tree(&dir.path().join("a"));
    let o = wgsph(&[&args[..], &["--out", "b", "--frames", "a", "--overwrite", "--resolution", "32x32"]].concat(), dir.path());
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--frames") && stderr(&o).contains("is an earlier run's directory"), "{}", stderr(&o));
    assert_eq!(tree(&dir.path().join("a")), before);
    assert!(!dir.path().join("b").exists());
    if common::contexts().is_empty() {
        return;
    }
    let pictures = |out: &str| wgsph(&[&args[..], &["--out", out, "--frames", "f", "--overwrite", "--resolution", "32x32"]].concat(), dir.path());
    let o = pictures("c");
    assert!(o.status.success(), "{}", stderr(&o));
    let o = pictures("d");
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(std::fs::read_to_string(dir.path().join("f/.wgsph-run")).unwrap().contains("holds frames\n"));
}

/// A checkpoint copied from another run into a run directory is refused by `--resume`, which
/// would mix that run's steps into this one's files; a copy of a whole run directory resumes.
#[test]
fn resume_refuses_a_checkpoint_of_another_run() {
    let dir = tempfile::tempdir().unwrap();
    for (scene, out) in [("hydrostatic", "h"), ("dam_break", "d")] {
        let o = wgsph(&["run", scene, "--particles", "300", "--steps", "10", "--checkpoint-every", "5", "--backend", "cpu", "--out", out], dir.path());
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let copy = |from: &Path, to: &Path| assert!(Command::new("cp").arg("-r").arg(from).arg(to).status().unwrap().success());
    copy(&dir.path().join("d"), &dir.path().join("d2"));
    std::fs::copy(dir.path().join("h/checkpoint.wgsph"), dir.path().join("d/checkpoint.wgsph")).unwrap();
    let before = tree(&dir.path().join("d"));
    let o = wgsph(&["run", "--resume", "d", "--steps", "3"], dir.path());
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("was written by another run") && stderr(&o).contains("resume the directory the checkpoint came from"), "{}", stderr(&o));
    assert_eq!(tree(&dir.path().join("d")), before);
    let o = wgsph(&["run", "--resume", "d2", "--steps", "3", "--quiet"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
}

/// A directory where the run writes one of its files (a snapshot, the summary) would stop the
/// run part way, after its steps: `--overwrite` and `--resume` refuse it before any work.
#[test]
fn a_directory_where_the_run_writes_a_file_is_refused_before_any_work() {
    let dir = tempfile::tempdir().unwrap();
    let args = ["run", "hydrostatic", "--particles", "300", "--steps", "20", "--backend", "cpu", "--snapshot-every", "10"];
    assert!(wgsph(&[&args[..], &["--out", "o", "--checkpoint-every", "10"]].concat(), dir.path()).status.success());
    let snapshot = dir.path().join("o/snapshots/step_000010.csv");
    std::fs::remove_file(&snapshot).unwrap();
    std::fs::create_dir(&snapshot).unwrap();
    let before = tree(&dir.path().join("o"));
    for extra in [&["--out", "o", "--overwrite"][..]] {
        let o = wgsph(&[&args[..], extra].concat(), dir.path());
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        assert!(stderr(&o).contains("step_000010.csv is a directory, where the run writes a file"), "{}", stderr(&o));
    }
    let o = wgsph(&["run", "--resume", "o", "--steps", "5"], dir.path());
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("step_000010.csv is a directory"), "{}", stderr(&o));
    assert_eq!(tree(&dir.path().join("o")), before);
    // In the numbered directories, one past the largest number there is, never a wrap.
    std::fs::create_dir_all(dir.path().join(format!("out/hydrostatic-{}", u64::MAX))).unwrap();
    let o = wgsph(&["run", "hydrostatic", "--particles", "300", "--steps", "1", "--backend", "cpu", "--quiet"], dir.path());
    assert!(o.status.success() && dir.path().join("out/hydrostatic-001/summary.json").exists(), "{}", stderr(&o));
}

/// A run resumed from its checkpoint to an earlier end than it had reached removes its
/// snapshots of the steps after the checkpoint (computed again, or not at all): none is left
/// that its index does not list. A user's file there stays.
#[test]
fn a_resume_to_an_earlier_end_leaves_no_snapshot_its_index_does_not_list() {
    let dir = tempfile::tempdir().unwrap();
    let o = wgsph(&["run", "hydrostatic", "--particles", "300", "--steps", "30", "--snapshot-every", "5", "--checkpoint-every", "20", "--backend", "cpu", "--out", "o"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    std::fs::write(dir.path().join("o/snapshots/step_000030.txt"), "mine").unwrap();
    let o = wgsph(&["run", "--resume", "o", "--steps", "3"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let mut files: Vec<String> = std::fs::read_dir(dir.path().join("o/snapshots")).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    files.sort();
    let listed: Vec<String> = std::fs::read_to_string(dir.path().join("o/snapshots/index.csv")).unwrap().lines().skip(1).map(|l| l.split(',').nth(2).unwrap().to_string()).collect();
    assert_eq!(listed, ["step_000000.csv", "step_000005.csv", "step_000010.csv", "step_000015.csv", "step_000020.csv", "step_000023.csv"]);
    let expected: Vec<String> = listed.iter().cloned().chain(["index.csv".to_string(), "step_000030.txt".to_string()]).collect::<std::collections::BTreeSet<_>>().into_iter().collect();
    assert_eq!(files, expected);
}
