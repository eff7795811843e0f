//! Runs as a user meets them: the first run (the command without arguments), run twice; Ctrl-C
//! and SIGTERM; `--resume` after a kill; `--backend auto` and what it says; the seed scene's
//! note.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};
use wgsph::io::summary::{RunStatus, Summary};

fn wgsph(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_wgsph")).args(args).current_dir(dir).env_remove("RUST_LOG").output().unwrap()
}

fn spawn(args: &[&str], dir: &Path) -> Child {
    Command::new(env!("CARGO_BIN_EXE_wgsph"))
        .args(args)
        .current_dir(dir)
        .env_remove("RUST_LOG")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn summary(dir: &Path) -> Summary {
    serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap()
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// Waits (at most two minutes) until `path` exists.
fn wait_for(path: &Path, child: &mut Child) {
    let start = Instant::now();
    while !path.exists() {
        if let Some(status) = child.try_wait().unwrap() {
            panic!("the run ended ({status}) before {} appeared", path.display());
        }
        assert!(start.elapsed() < Duration::from_secs(120), "{} did not appear", path.display());
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[cfg(unix)]
fn signal(child: &Child, name: &str) {
    assert!(Command::new("kill").args([&format!("-{name}"), &child.id().to_string()]).status().unwrap().success());
}

/// Every file name under `dir`, recursively.
fn all_names(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        out.push(p.file_name().unwrap().to_string_lossy().into_owned());
        if p.is_dir() {
            out.extend(all_names(&p));
        }
    }
    out
}

/// The README's first command, `cargo run --release`, is `wgsph` without arguments: it runs the
/// dam break and shows water, and it can be run again (it once ran the seed scene, whose
/// picture is a clump of strands at 29 times the rest density, and failed the second time).
#[cfg(unix)]
#[test]
fn the_first_run_shows_water_and_can_be_run_twice() {
    let dir = tempfile::tempdir().unwrap();
    // As on a server or in a container: no desktop session, so no runtime directory.
    let o = Command::new(env!("CARGO_BIN_EXE_wgsph"))
        .current_dir(dir.path())
        .env_remove("RUST_LOG")
        .env_remove("XDG_RUNTIME_DIR")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .unwrap();
    let (stdout, stderr) = (text(&o.stdout), text(&o.stderr));
    assert!(o.status.success(), "{stdout}\n{stderr}");
    // A first run that prints errors or warnings looks broken: libwayland's complaint about
    // the runtime directory and a fill warning once did.
    assert!(stderr.trim().is_empty(), "nothing on stderr: {stderr}");
    let run = dir.path().join("out/dam_break-001");
    let s = summary(&run);
    assert_eq!((s.scene.as_str(), s.status, s.failure.as_deref()), ("dam_break", RunStatus::Completed, None));
    assert!((s.sim_time - 1.5).abs() < 1e-3, "ran to t = {}", s.sim_time);
    assert!(s.max_density_ratio < 1.5, "water stays near its rest density, not {}", s.max_density_ratio);
    assert_eq!((s.nan_count, s.escaped), (0, 0));
    // What was written where is reported.
    assert!(stdout.contains("wrote out/dam_break-001") && stdout.contains("snapshots/") && stdout.contains("index.csv"), "{stdout}");
    assert!(stdout.contains("backend: "), "{stdout}");
    if common::contexts().is_empty() {
        assert!(stdout.contains("no GPU adapter"), "{stdout}");
    } else {
        assert!(stdout.contains("frames/") && stdout.contains("7 pictures"), "{stdout}");
        assert_eq!(s.frames, 7);
        // The water: at the start a column at the left of the tank; at the end spread over the
        // whole floor, with little of it high up.
        let water = |frame: &str| {
            let img = image::open(run.join("frames").join(frame)).unwrap().to_rgb8();
            let (w, h) = img.dimensions();
            let mut thirds = [0usize; 3];
            let (mut low, mut high) = (0usize, 0usize);
            for (x, y, p) in img.enumerate_pixels() {
                // The surface style draws water blue.
                if p[2] as i32 > p[0] as i32 + 60 && p[2] as i32 > p[1] as i32 + 20 {
                    thirds[(3 * x / w) as usize] += 1;
                    if y >= h / 2 {
                        low += 1;
                    } else {
                        high += 1;
                    }
                }
            }
            (thirds, low, high)
        };
        let (start, _, _) = water("frame_00000.png");
        assert!(start[0] > 20 * start[2].max(1) && start[0] > 5000, "the column at the left: {start:?}");
        let (end, low, high) = water("frame_00006.png");
        assert!(end.iter().all(|&n| n > 3000), "water over the whole floor: {end:?}");
        assert!(low > 5 * high, "the water lies low: {low} pixels low, {high} high");
    }
    // Run again: a new directory; the first is left as it is. Stopped once it started (SIGTERM).
    let before = std::fs::read(run.join("summary.json")).unwrap();
    let mut second = spawn(&[], dir.path());
    let again = dir.path().join("out/dam_break-002");
    wait_for(&again.join("snapshots/step_000000.csv"), &mut second);
    signal(&second, "TERM");
    let o = second.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(143), "{}", text(&o.stderr));
    assert_eq!(summary(&again).status, RunStatus::Interrupted);
    assert_eq!(std::fs::read(run.join("summary.json")).unwrap(), before);
}

/// Ctrl-C (SIGINT) and SIGTERM once ended a run without a word and without a summary. Now the
/// run stops after the batch under way: the summary says "interrupted", a checkpoint holds the
/// last step (with checkpoints on) and the message says how to resume; exit 130 and 143.
#[cfg(unix)]
#[test]
fn ctrl_c_and_sigterm_stop_a_run_with_its_summary_and_say_where_to_resume() {
    let dir = tempfile::tempdir().unwrap();
    let args = ["run", "dam_break", "--backend", "cpu", "--check-every", "10", "--snapshot-every", "20"];
    let mut child = spawn(&[&args[..], &["--out", "a", "--checkpoint-every", "30"]].concat(), dir.path());
    wait_for(&dir.path().join("a/snapshots/step_000020.csv"), &mut child);
    signal(&child, "INT");
    let o = child.wait_with_output().unwrap();
    let stderr = text(&o.stderr);
    assert_eq!(o.status.code(), Some(130), "{stderr}");
    let a = dir.path().join("a");
    let s = summary(&a);
    assert_eq!(s.status, RunStatus::Interrupted);
    assert!(s.failure.as_deref().unwrap().contains("SIGINT"), "{:?}", s.failure);
    assert!(s.steps >= 20 && s.steps < 6000, "{} steps", s.steps);
    // The checkpoint holds the step the run stopped at, not only the last multiple of 30.
    let checkpoint = wgsph::io::checkpoint::read(&a.join("checkpoint.wgsph")).unwrap();
    assert_eq!(checkpoint.state.step, s.steps);
    assert_eq!(s.last_checkpoint.as_deref(), Some("a/checkpoint.wgsph"));
    assert!(stderr.contains("interrupted by SIGINT") && stderr.contains("wgsph run --resume a"), "{stderr}");
    assert!(!all_names(&a).iter().any(|n| n.starts_with(".wgsph-tmp")), "partial files left: {:?}", all_names(&a));
    // It continues from there.
    let o = wgsph(&["run", "--resume", "a", "--steps", "10"], dir.path());
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert_eq!(summary(&a).status, RunStatus::Completed);

    // SIGTERM, without checkpoints: the summary, and the message says the run cannot go on.
    let mut child = spawn(&[&args[..], &["--out", "b"]].concat(), dir.path());
    wait_for(&dir.path().join("b/snapshots/step_000020.csv"), &mut child);
    signal(&child, "TERM");
    let o = child.wait_with_output().unwrap();
    let stderr = text(&o.stderr);
    assert_eq!(o.status.code(), Some(143), "{stderr}");
    let s = summary(&dir.path().join("b"));
    assert_eq!((s.status, s.last_checkpoint), (RunStatus::Interrupted, None));
    assert!(stderr.contains("SIGTERM") && stderr.contains("no checkpoint"), "{stderr}");
    // Every snapshot listed in the index is whole: its header and a line per particle.
    let index = std::fs::read_to_string(dir.path().join("b/snapshots/index.csv")).unwrap();
    for row in index.lines().skip(1) {
        let file = row.split(',').nth(2).unwrap();
        let csv = std::fs::read_to_string(dir.path().join("b/snapshots").join(file)).unwrap();
        assert_eq!(csv.lines().count(), s.fluid_particles + 1, "{file}");
    }
}

/// A series file cut (or replaced) after the checkpoint was written: the resume goes on, and
/// says which file holds fewer lines than the checkpoint recorded (the series then has a gap).
#[test]
fn resume_names_a_series_file_cut_since_the_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let scene = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/hydrostatic.toml")).unwrap()
        + "\n[[probe]]\nname = \"mid\"\ntype = \"point\"\nposition = [0.2, 0.05, 0.05]\nevery_steps = 2\n\n[[probe]]\nname = \"low\"\ntype = \"point\"\nposition = [0.2, 0.02, 0.05]\nevery_steps = 5\n";
    std::fs::write(dir.path().join("probed.toml"), scene).unwrap();
    let o = wgsph(&["run", "probed.toml", "--particles", "300", "--steps", "10", "--backend", "cpu", "--snapshot-every", "2", "--checkpoint-every", "10", "--format", "csv,vtk", "--out", "o"], dir.path());
    assert!(o.status.success(), "{}", text(&o.stderr));
    // Untouched: no warning.
    let o = wgsph(&["run", "--resume", "o", "--steps", "10"], dir.path());
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(!text(&o.stderr).contains("warning"), "{}", text(&o.stderr));
    // The checkpoint is now at step 20. Cut the index to its header and first line, and the
    // probe's series to its header and its first two samples.
    let o_dir = dir.path().join("o");
    let cut = |name: &str, keep: usize| {
        let path = o_dir.join(name);
        let text = std::fs::read_to_string(&path).unwrap();
        std::fs::write(&path, text.lines().take(keep).map(|l| format!("{l}\n")).collect::<String>()).unwrap();
    };
    cut("snapshots/index.csv", 2);
    cut("probes/mid.csv", 3);
    let series = o_dir.join("snapshots/particles.vtk.series");
    let mut json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&series).unwrap()).unwrap();
    json["files"].as_array_mut().unwrap().truncate(3);
    std::fs::write(&series, json.to_string()).unwrap();
    let o = wgsph(&["run", "--resume", "o", "--steps", "2"], dir.path());
    assert!(o.status.success(), "{}", text(&o.stderr));
    let stderr = text(&o.stderr);
    assert!(stderr.contains("warning: o/snapshots/index.csv holds 1 snapshots up to step 20, where the run had written 11"), "{stderr}");
    assert!(stderr.contains("warning: o/probes/mid.csv holds 2 samples before step 20, where the run had written 10"), "{stderr}");
    assert!(stderr.contains("warning: o/snapshots/particles.vtk.series holds 3 snapshots up to step 20, where the run had written 11"), "{stderr}");
    assert!(!stderr.contains("probes/low.csv"), "{stderr}");
}

/// A run killed while writing leaves the atomic writer's partial files; `--resume` removes
/// them, and only them.
#[test]
fn resume_removes_the_partial_files_a_killed_run_left() {
    let dir = tempfile::tempdir().unwrap();
    let o = wgsph(&["run", "hydrostatic", "--particles", "300", "--steps", "10", "--backend", "cpu", "--checkpoint-every", "10", "--out", "o"], dir.path());
    assert!(o.status.success(), "{}", text(&o.stderr));
    let o_dir = dir.path().join("o");
    let partial: Vec<PathBuf> = [
        "snapshots/.wgsph-tmp-0123456789abcdef-step_000015.csv",
        ".wgsph-tmp-fedcba9876543210-checkpoint.wgsph",
        "snapshots/.wgsph-tmp-00000000000000aa-index.csv",
    ]
    .iter()
    .map(|p| o_dir.join(p))
    .collect();
    for p in &partial {
        std::fs::write(p, "partial").unwrap();
    }
    let mine = o_dir.join("snapshots/.tmp-my-notes");
    std::fs::write(&mine, "mine").unwrap();
    let o = wgsph(&["run", "--resume", "o", "--steps", "5"], dir.path());
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(text(&o.stdout).contains("removed 3 partial file"), "{}", text(&o.stdout));
    for p in &partial {
        assert!(!p.exists(), "{} is still there", p.display());
    }
    assert!(mine.exists(), "a file the writer did not name was removed");
}

/// `--resume` takes no GPU tuning flag (the checkpoint does not record them; a neighbour skin
/// given there was silently unused), and a VTK series index that is not the run's is bad
/// input, left as it is.
#[test]
fn resume_refuses_tuning_flags_and_a_foreign_series_index() {
    let dir = tempfile::tempdir().unwrap();
    let o = wgsph(&["run", "hydrostatic", "--particles", "300", "--steps", "4", "--backend", "cpu", "--format", "csv,vtk", "--checkpoint-every", "4", "--out", "o"], dir.path());
    assert!(o.status.success(), "{}", text(&o.stderr));
    for flag in [&["--neighbour-skin", "0.1"][..], &["--fused"][..]] {
        let o = wgsph(&[&["run", "--resume", "o", "--steps", "2"][..], flag].concat(), dir.path());
        assert_eq!(o.status.code(), Some(2), "{flag:?}: {}", text(&o.stderr));
        assert!(text(&o.stderr).contains(&format!("{} cannot be given with it", flag[0])), "{}", text(&o.stderr));
    }
    let series = dir.path().join("o/snapshots/particles.vtk.series");
    std::fs::write(&series, "garbage\n").unwrap();
    let o = wgsph(&["run", "--resume", "o", "--steps", "2"], dir.path());
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    assert!(text(&o.stderr).contains("is not the run's file series"), "{}", text(&o.stderr));
    assert_eq!(std::fs::read_to_string(&series).unwrap(), "garbage\n");
    std::fs::remove_file(&series).unwrap();
    // A time that is not a number is not a line the run wrote.
    let index = dir.path().join("o/snapshots/index.csv");
    let nan = std::fs::read_to_string(&index).unwrap().replacen("\n0,0,", "\n0,NaN,", 1);
    std::fs::write(&index, &nan).unwrap();
    let o = wgsph(&["run", "--resume", "o", "--steps", "2"], dir.path());
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    assert!(text(&o.stderr).contains("line 2 is not step,time,files: '0,NaN,"), "{}", text(&o.stderr));
    assert_eq!(std::fs::read_to_string(&index).unwrap(), nan);
    std::fs::remove_file(&index).unwrap();
    let o = wgsph(&["run", "--resume", "o", "--steps", "2", "--quiet"], dir.path());
    assert!(o.status.success() && text(&o.stderr).contains("index.csv is missing, where the run had written 5 snapshots up to step 4"), "{}", text(&o.stderr));
}

/// Output into a closed pipe (`wgsph run | head -1`) ends the process by SIGPIPE, as any Unix
/// tool, not with a panic (exit 101) in its next print.
#[cfg(unix)]
#[test]
fn a_closed_output_pipe_ends_the_process_without_a_panic() {
    use std::os::unix::process::ExitStatusExt;
    let dir = tempfile::tempdir().unwrap();
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_wgsph"))
        .args(["run", "hydrostatic", "--particles", "300", "--steps", "3", "--backend", "cpu", "--out", "o"])
        .current_dir(dir.path())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.signal(), Some(libc::SIGPIPE), "{:?}: {}", out.status, text(&out.stderr));
    assert!(!text(&out.stderr).contains("panicked"), "{}", text(&out.stderr));
}

/// What `--resume` finds changed in the run's directory: an edited `scene.toml` is said to be
/// unused (the checkpoint's scene runs on), a probe's missing series is said to restart, and a
/// file where a probe's series was that is not one is refused (exit 2) and left as it was.
#[test]
fn resume_says_what_it_does_not_use_and_refuses_to_replace_a_foreign_probe_file() {
    let dir = tempfile::tempdir().unwrap();
    let probe = "probe=[{name=\"p\",type=\"point\",position=[0.2,0.1,0.05]}]";
    let o = wgsph(&["run", "hydrostatic", "--particles", "300", "--steps", "10", "--backend", "cpu", "--checkpoint-every", "10", "--set", probe, "--out", "o"], dir.path());
    assert!(o.status.success(), "{}", text(&o.stderr));
    let (scene, series) = (dir.path().join("o/scene.toml"), dir.path().join("o/probes/p.csv"));
    let resume = || wgsph(&["run", "--resume", "o", "--steps", "2", "--quiet"], dir.path());

    let o = resume();
    assert!(o.status.success() && !text(&o.stderr).contains("warning"), "{}", text(&o.stderr));

    let edited = std::fs::read_to_string(&scene).unwrap().replace("viscosity = ", "viscosity = 0.5 # ");
    std::fs::write(&scene, &edited).unwrap();
    std::fs::remove_file(&series).unwrap();
    let o = resume();
    let stderr = text(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(stderr.contains("scene.toml was edited") && stderr.contains("continues the checkpoint's scene"), "{stderr}");
    assert!(stderr.contains("p.csv is missing: its series restarts at step 10"), "{stderr}");
    assert_eq!(std::fs::read_to_string(&scene).unwrap(), edited, "the edited copy was changed");
    assert_eq!(std::fs::read_to_string(&series).unwrap().lines().nth(1).unwrap().split(',').nth(1), Some("10"));

    std::fs::write(&series, "").unwrap();
    std::fs::remove_file(dir.path().join("o/.wgsph-run")).unwrap();
    let o = resume();
    assert!(text(&o.stderr).contains(".wgsph-run (it was deleted): written again"), "{}", text(&o.stderr));
    assert!(std::fs::read_to_string(dir.path().join("o/.wgsph-run")).unwrap().contains("probes p\n"));
    assert!(o.status.success() && text(&o.stderr).contains("p.csv is empty: its series restarts at step 10"), "{}", text(&o.stderr));

    std::fs::write(&series, "my own notes\n").unwrap();
    let o = resume();
    let stderr = text(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("p.csv: its first line is 'my own notes'") && stderr.contains("move it away"), "{stderr}");
    assert_eq!(std::fs::read_to_string(&series).unwrap(), "my own notes\n");
}

/// `--backend auto` (the default) once took a software GPU adapter (llvmpipe, lavapipe) over
/// the CPU path, which is faster on the same cores. It takes a hardware GPU, else the CPU path,
/// and says which and why in one line; `--backend gpu` still runs on a software adapter.
#[test]
fn auto_takes_a_hardware_gpu_else_the_cpu_path_and_says_why() {
    let dir = tempfile::tempdir().unwrap();
    let adapters = wgsph::solver::gpu::device::compute_adapters();
    let hardware = adapters.iter().any(|a| a.get_info().device_type != wgpu::DeviceType::Cpu);
    let o = wgsph(&["run", "hydrostatic", "--particles", "300", "--steps", "2", "--out", "auto"], dir.path());
    assert!(o.status.success(), "{}", text(&o.stderr));
    let stdout = text(&o.stdout);
    let line = stdout.lines().find(|l| l.starts_with("backend: ")).unwrap_or_else(|| panic!("no backend line: {stdout}"));
    let s = summary(&dir.path().join("auto"));
    if hardware {
        assert_eq!(s.backend, "gpu", "{line}");
        assert!(line.contains("hardware"), "{line}");
    } else {
        assert_eq!(s.backend, "cpu", "{line}");
        assert!(line.contains(if adapters.is_empty() { "no GPU adapter" } else { "software" }), "{line}");
    }
    if let Some(software) = adapters.iter().find(|a| a.get_info().device_type == wgpu::DeviceType::Cpu) {
        let o = wgsph(&["run", "hydrostatic", "--particles", "300", "--steps", "2", "--out", "gpu", "--backend", "gpu"], dir.path());
        assert!(o.status.success(), "{}", text(&o.stderr));
        assert_eq!(summary(&dir.path().join("gpu")).backend, "gpu");
        // An adapter named with WGPU_ADAPTER_NAME is taken, software or not.
        let o = Command::new(env!("CARGO_BIN_EXE_wgsph"))
            .args(["run", "hydrostatic", "--particles", "300", "--steps", "2", "--out", "named"])
            .env("WGPU_ADAPTER_NAME", software.get_info().name)
            .current_dir(dir.path())
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", text(&o.stderr));
        assert_eq!(summary(&dir.path().join("named")).backend, "gpu");
        assert!(text(&o.stdout).contains("WGPU_ADAPTER_NAME"), "{}", text(&o.stdout));
    }
}

/// The GPU step's tuning flags change nothing on the CPU path: asked for with `--backend cpu`
/// they are refused by name with exit code 2 before anything is written; where the automatic
/// choice falls on the CPU path, a note says they were not used; `--precision f64` with
/// `--backend gpu` is refused the same way, and `--full-exchange` on one process. `profile --single-cells` (each particle's own walk)
/// cannot go with `--subgroup-tiles`.
#[test]
fn gpu_tuning_flags_on_the_cpu_path_are_refused_or_noted() {
    let dir = tempfile::tempdir().unwrap();
    for (flags, named) in [
        (&["--workgroup-size", "64"][..], "--workgroup-size tunes the GPU step"),
        (&["--fused", "--no-neighbour-lists"][..], "--fused, --no-neighbour-lists tune the GPU step"),
        (&["--steps-per-submit", "4"][..], "--steps-per-submit tunes"),
        (&["--neighbour-skin", "0.1"][..], "--neighbour-skin tunes the GPU step"),
    ] {
        let mut args = vec!["run", "hydrostatic", "--particles", "300", "--steps", "2", "--backend", "cpu", "--out", "refused"];
        args.extend_from_slice(flags);
        let o = wgsph(&args, dir.path());
        assert_eq!(o.status.code(), Some(2), "{flags:?}: {}", text(&o.stderr));
        assert!(text(&o.stderr).contains(named) && text(&o.stderr).contains("--backend cpu"), "{flags:?}: {}", text(&o.stderr));
        assert!(!dir.path().join("refused").exists(), "{flags:?}");
    }
    let o = wgsph(&["run", "hydrostatic", "--particles", "300", "--steps", "2", "--workgroup-size", "64", "--out", "auto"], dir.path());
    assert!(o.status.success(), "{}", text(&o.stderr));
    let noted = text(&o.stderr).contains("note: --workgroup-size not used: the automatic choice is the CPU path");
    assert_eq!(noted, summary(&dir.path().join("auto")).backend == "cpu", "{}", text(&o.stderr));
    // Nor does the CPU path's float type on the GPU, which computes in f32.
    let o = wgsph(&["run", "hydrostatic", "--particles", "300", "--steps", "2", "--backend", "gpu", "--precision", "f64", "--out", "refused"], dir.path());
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    assert!(text(&o.stderr).contains("--precision f64 sets the CPU path's float type"), "{}", text(&o.stderr));
    assert!(!dir.path().join("refused").exists());
    // How GPU ranks exchange their particles means nothing to one process.
    let o = wgsph(&["run", "hydrostatic", "--particles", "300", "--steps", "2", "--full-exchange", "--out", "refused"], dir.path());
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    assert!(text(&o.stderr).contains("--full-exchange") && text(&o.stderr).contains("one process has nothing to exchange"), "{}", text(&o.stderr));
    assert!(!dir.path().join("refused").exists());
    // DFSPH's solve loop means nothing to a weakly compressible scene.
    let o = wgsph(&["run", "hydrostatic", "--particles", "300", "--steps", "2", "--solver-loop", "indirect", "--out", "refused"], dir.path());
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    assert!(text(&o.stderr).contains("--solver-loop indirect steers the GPU's DFSPH solves"), "{}", text(&o.stderr));
    assert!(!dir.path().join("refused").exists());
    // A neighbour skin outside its range, or with a grid rebuilt every 2nd step (the skin
    // chooses when): refused by name before anything is written.
    let o = wgsph(&["run", "hydrostatic", "--particles", "300", "--steps", "2", "--neighbour-skin", "1.5", "--out", "refused"], dir.path());
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    assert!(text(&o.stderr).contains("--neighbour-skin") && text(&o.stderr).contains("at most 1"), "{}", text(&o.stderr));
    if wgsph::solver::gpu::GpuContext::new().is_ok() {
        let o = wgsph(&["run", "hydrostatic", "--particles", "300", "--steps", "2", "--backend", "gpu", "--neighbour-skin", "0.1", "--set", "time.neighbour_rebuild_every=2", "--out", "refused"], dir.path());
        assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
        assert!(text(&o.stderr).contains("--neighbour-skin 0.1 cannot be used") && text(&o.stderr).contains("time.neighbour_rebuild_every = 2"), "{}", text(&o.stderr));
        // Nor are the forces and the integration fused where dt is chosen between them, or
        // where DFSPH has no forces pass: refused, not quietly run as two passes.
        for (set, why) in [(&["--set", "time.adaptive=true"][..], "time.adaptive = true"), (&["--set", "physics.solver=dfsph", "--unset", "physics.speed_of_sound"], "physics.solver = \"dfsph\"")] {
            let o = wgsph(&[&["run", "hydrostatic", "--particles", "300", "--steps", "2", "--backend", "gpu", "--fused", "--out", "refused"][..], set].concat(), dir.path());
            assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
            assert!(text(&o.stderr).contains("--fused cannot be used") && text(&o.stderr).contains(why), "{}", text(&o.stderr));
        }
    }
    assert!(!dir.path().join("refused").exists());
    // With a skin each step is submitted alone: --steps-per-submit would change nothing.
    let o = wgsph(&["run", "hydrostatic", "--particles", "300", "--steps", "2", "--neighbour-skin", "0.1", "--steps-per-submit", "4", "--out", "refused"], dir.path());
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    assert!(text(&o.stderr).contains("--neighbour-skin") && text(&o.stderr).contains("--steps-per-submit"), "{}", text(&o.stderr));
    assert!(!dir.path().join("refused").exists());
    let o = wgsph(&["profile", "dam_break", "--steps", "1", "--single-cells", "--subgroup-tiles"], dir.path());
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    assert!(text(&o.stderr).contains("--single-cells"), "{}", text(&o.stderr));
}

/// The seed scene is run as published, oddities and all; it says so in one line.
#[test]
fn the_seed_scene_states_its_oddities() {
    let dir = tempfile::tempdir().unwrap();
    let o = wgsph(&["run", "seed", "--steps", "1", "--backend", "cpu", "--out", "s"], dir.path());
    assert!(o.status.success(), "{}", text(&o.stderr));
    let notes: Vec<String> = text(&o.stdout).lines().filter(|l| l.starts_with("note: ")).map(String::from).collect();
    assert_eq!(notes.len(), 1, "{notes:?}");
    assert!(notes[0].contains("seed") && notes[0].contains("dam_break"), "{}", notes[0]);
    let o = wgsph(&["run", "seed", "--steps", "1", "--backend", "cpu", "--out", "q", "--quiet"], dir.path());
    assert!(o.stdout.is_empty());
}

/// Without --out every run gets a new numbered directory; --overwrite needs --out.
#[test]
fn runs_without_out_get_numbered_directories() {
    let dir = tempfile::tempdir().unwrap();
    for n in 1..=2 {
        let o = wgsph(&["run", "hydrostatic", "--particles", "300", "--steps", "1", "--backend", "cpu", "-q"], dir.path());
        assert!(o.status.success(), "{}", text(&o.stderr));
        assert!(dir.path().join(format!("out/hydrostatic-{n:03}/summary.json")).exists());
    }
    // A run of no steps stands too.
    let o = wgsph(&["run", "hydrostatic", "--particles", "300", "--steps", "0", "--backend", "cpu", "-q"], dir.path());
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert_eq!(summary(&dir.path().join("out/hydrostatic-003")).status, RunStatus::Completed);
    let o = wgsph(&["run", "hydrostatic", "--steps", "1", "--overwrite"], dir.path());
    assert_eq!(o.status.code(), Some(2), "{}", text(&o.stderr));
    assert!(text(&o.stderr).contains("--out"), "{}", text(&o.stderr));
}

/// The number after `label` in a failure message ("|v|max = 54.9337, ...").
fn figure_after(text: &str, label: &str) -> f64 {
    let rest = &text[text.find(label).unwrap_or_else(|| panic!("no '{label}' in: {text}")) + label.len()..];
    let end = rest.find(|c: char| !(c.is_ascii_digit() || matches!(c, '.' | 'e' | '-' | '+'))).unwrap_or(rest.len());
    rest[..end].parse().unwrap_or_else(|e| panic!("'{}' after '{label}': {e}", &rest[..end]))
}

/// The GPU runs a batch of steps on past a blow-up before the host reads its health, so the
/// run's largest density and speed grew to those of the wreck (21 rho0, Mach 4e8) while the
/// failure named what its first bad step measured (1.15 rho0, Mach 1.4): the summary and its
/// warnings contradicted the message. They now report the maxima up to the first bad step.
#[test]
fn a_failed_run_reports_its_maxima_up_to_its_first_bad_step() {
    let dir = tempfile::tempdir().unwrap();
    let mut runs: Vec<(String, Vec<(&str, String)>)> = vec![("cpu".into(), vec![])];
    for adapter in wgsph::solver::gpu::device::compute_adapters() {
        runs.push((format!("gpu-{:?}", adapter.get_info().backend), vec![("WGPU_ADAPTER_NAME", adapter.get_info().name)]));
    }
    for (i, (label, env)) in runs.iter().enumerate() {
        let out = format!("blow-{i}");
        let backend = if label == "cpu" { "cpu" } else { "gpu" };
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_wgsph"));
        cmd.args(["run", "dam_break", "--particles", "1000", "--set", "time.dt=0.0025", "--steps", "400", "--backend", backend, "--out", &out]);
        cmd.current_dir(dir.path()).env_remove("RUST_LOG");
        for (k, v) in env {
            cmd.env(k, v);
        }
        let o = cmd.output().unwrap();
        assert_eq!(o.status.code(), Some(1), "{label}: {}", text(&o.stderr));
        let s = summary(&dir.path().join(&out));
        assert_eq!(s.status, RunStatus::Failed, "{label}");
        let failure = s.failure.clone().unwrap();
        // The run fails within its first steps: before them the fluid was at rest near rho0.
        // Where it failed: the summary's steps and time are those of the step the failure names.
        let failed_step: u64 = failure.strip_prefix("step ").and_then(|r| r.split(' ').next()).and_then(|n| n.parse().ok()).expect(&failure);
        assert_eq!(s.steps, failed_step, "{label}: {failure}");
        assert!((s.sim_time - figure_after(&failure, "(t = ")).abs() < 1e-6, "{label}: t = {} against {failure}", s.sim_time);
        let bad_speed = figure_after(&failure, "|v|max = ");
        let bad_ratio = figure_after(&failure, "max rho/rho0 = ");
        let speed = s.max_mach.unwrap() * 40.0;
        assert!((speed - bad_speed).abs() <= 1e-3 * bad_speed, "{label}: summary speed {speed}, first bad step's {bad_speed}");
        assert!(s.max_density_ratio <= bad_ratio.max(1.1) * (1.0 + 1e-5), "{label}: summary density {} rho0, first bad step's {bad_ratio}", s.max_density_ratio);
        for w in s.warnings.iter().filter(|w| w.contains("the speed reached ")) {
            assert!(figure_after(w, "the speed reached ") <= bad_speed * (1.0 + 1e-3), "{label}: a warning from past the failure: {w}");
        }
        for w in s.warnings.iter().filter(|w| w.contains("the density reached ")) {
            assert!(figure_after(w, "the density reached ") <= bad_ratio.max(1.1) * (1.0 + 1e-3), "{label}: a warning from past the failure: {w}");
        }
    }
}

/// A block falling in a tank with the continuity density and delta = 1 at dt = 3e-4: delta c0
/// dt / h = 0.225, past where the diffusive term damps noise. The density it drives below zero
/// passes no step's check; the snapshot that shows it ends the run, and the diffusion is named.
/// Without a snapshot every step the run stops later, for its density, and the snapshot written
/// just before (already over the stop level) is not named the last good one.
#[test]
fn a_density_driven_below_zero_or_over_its_limit_is_never_named_the_last_good_snapshot() {
    let dir = tempfile::tempdir().unwrap();
    let scene = "name = \"fall\"\n[domain]\nmin = [-0.1, -0.1, -0.1]\nmax = [0.3, 0.4, 0.2]\n\
        [physics]\nsmoothing_length = 0.04\nparticle_spacing = 0.02\nequation_of_state = \"tait\"\nspeed_of_sound = 30.0\n\
        clamp_negative_pressure = true\nviscosity = 0.01\ndensity = \"continuity\"\ndensity_diffusion = 1.0\n\
        [time]\ndt = 0.0003\nend_time = 0.1\n[[fluid]]\nmin = [0.0, 0.0, 0.0]\nmax = [0.1, 0.1, 0.1]\njitter = 0.0\n\
        [[boundary]]\ntype = \"container\"\nmin = [0.0, 0.0, 0.0]\nmax = [0.2, 0.3, 0.1]\n";
    std::fs::write(dir.path().join("fall.toml"), scene).unwrap();
    let summary = |o: &str| -> Summary { serde_json::from_str(&std::fs::read_to_string(dir.path().join(o).join("summary.json")).unwrap()).unwrap() };
    let densities = |o: &str, file: &str| -> Vec<f64> {
        let text = std::fs::read_to_string(dir.path().join(o).join("snapshots").join(file)).unwrap();
        text.lines().skip(1).map(|l| l.split(',').nth(6).unwrap().parse().unwrap()).collect()
    };

    let o = wgsph(&["run", "fall.toml", "--backend", "cpu", "--snapshot-every", "1", "--out", "every", "--quiet"], dir.path());
    let stderr = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("particles fell to zero or below") && stderr.contains("Cause: the density diffusion: delta c0 dt / h = 0.225 is over 0.16"), "{stderr}");
    let s = summary("every");
    let last = s.last_snapshot.expect("a last good snapshot");
    let name = Path::new(&last).file_name().unwrap().to_string_lossy().into_owned();
    assert!(densities("every", &name).iter().all(|&d| d > 0.0 && d <= 1500.0), "{name}");
    let bad = format!("step_{:06}.csv", s.steps);
    assert!(densities("every", &bad).iter().any(|&d| d <= 0.0), "{bad} shows no density at or below zero");

    let o = wgsph(&["run", "fall.toml", "--backend", "cpu", "--snapshot-every", "10", "--out", "tens", "--quiet"], dir.path());
    let stderr = text(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("Cause: the density diffusion"), "{stderr}");
    let s = summary("tens");
    let last = s.last_snapshot.expect("a last good snapshot");
    let name = Path::new(&last).file_name().unwrap().to_string_lossy().into_owned();
    assert!(densities("tens", &name).iter().all(|&d| d > 0.0 && d <= 1500.0), "{name}");
}

/// A blow-up names the setting that caused it: an adaptive step held at `time.dt_min` (not
/// time.dt or the CFL number, which cannot lower it), a viscosity from the schedule (not
/// `physics.viscosity`), a start off rest density (not the speed of sound).
#[test]
fn a_blow_up_names_the_setting_in_force() {
    let dir = tempfile::tempdir().unwrap();
    let scene = "name = \"fall\"\n[domain]\nmin = [-0.1, -0.1, -0.1]\nmax = [0.3, 0.4, 0.2]\n\
        [physics]\nsmoothing_length = 0.04\nparticle_spacing = 0.02\nequation_of_state = \"tait\"\nspeed_of_sound = 30.0\n\
        clamp_negative_pressure = true\nviscosity = 0.01\n\
        [time]\ndt = 0.0003\nend_time = 0.05\n[[fluid]]\nmin = [0.0, 0.0, 0.0]\nmax = [0.1, 0.1, 0.1]\njitter = 0.0\n\
        [[boundary]]\ntype = \"container\"\nmin = [0.0, 0.0, 0.0]\nmax = [0.2, 0.3, 0.1]\n";
    std::fs::write(dir.path().join("fall.toml"), scene).unwrap();
    for (sets, says, not) in [
        (&["time.adaptive=true", "time.dt=0.01", "time.dt_min=0.01"][..], "time.dt_min = 0.01 held the adaptive step there", "lower time.dt to"),
        (&["physics.viscosity_schedule=[{time=0.01,viscosity=1e9}]"][..], "lower time.dt or physics.viscosity_schedule[0].viscosity", "or physics.viscosity,"),
        // h = one spacing: the kernel's sum starts the fluid at 1.57 rho0, which no c0 mends.
        (&["physics.smoothing_length=0.02", "time.dt=0.0001"][..], "Cause: the fluid started at", "raise physics.speed_of_sound"),
    ] {
        let mut args = vec!["run", "fall.toml", "--backend", "cpu", "--out", "o", "--overwrite", "--quiet"];
        for s in sets {
            args.extend(["--set", s]);
        }
        let o = wgsph(&args, dir.path());
        let stderr = text(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{sets:?}: {stderr}");
        assert!(stderr.contains(says) && !stderr.contains(not), "{sets:?}: {stderr}");
    }
}
