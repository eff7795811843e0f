//! `mpirun -np N wgsph-mpi run ...` as a user launches it: 1, 2 and 4 ranks on the dam break and the
//! hydrostatic tank give the same snapshots byte for byte (on the CPU path and on a software GPU
//! adapter), particles migrate, a rank may hold no particle, a checkpoint of 2 ranks continues
//! on 4 or 1, a killed rank stops the run within
//! seconds with a resumable checkpoint, an error on one rank stops all of them naming it, and plain
//! `wgsph` (not `wgsph-mpi`) refuses a multi-rank launch.
//!
//! MPI starts once per process, so these run `mpirun` on `wgsph-mpi` (the mpi/ crate), found
//! through WGSPH_MPI_BIN (.ci/run builds it). Without mpirun or that binary the tests say
//! SKIPPED, unless WGSPH_REQUIRE_MPI is set (CI sets it): then they fail.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};
use wgsph::io::summary::{RunStatus, Summary};

/// mpirun and the MPI-enabled wgsph, or `None` (SKIPPED) where either is missing.
fn mpi() -> Option<(PathBuf, PathBuf)> {
    let required = std::env::var_os("WGSPH_REQUIRE_MPI").is_some();
    let missing = |what: String| {
        if required {
            panic!("WGSPH_REQUIRE_MPI is set but {what}");
        }
        eprintln!("SKIPPED: {what}");
        None
    };
    let mpirun = match std::env::var_os("PATH").and_then(|p| std::env::split_paths(&p).map(|d| d.join("mpirun")).find(|f| f.is_file())) {
        Some(m) => m,
        None => return missing("there is no mpirun (apt-get install openmpi-bin)".into()),
    };
    match std::env::var_os("WGSPH_MPI_BIN").map(PathBuf::from) {
        Some(bin) if bin.is_file() => Some((mpirun, bin)),
        Some(bin) => missing(format!("WGSPH_MPI_BIN names {}, which is not a file", bin.display())),
        None => missing("WGSPH_MPI_BIN does not name a wgsph-mpi (cargo build --release -p wgsph-mpi)".into()),
    }
}

/// `mpirun -np N BIN ARGS` (as root where CI runs as root; more ranks than cores allowed).
fn mpirun(mpi: &(PathBuf, PathBuf), ranks: usize, args: &[&str], dir: &Path) -> Command {
    let mut c = Command::new(&mpi.0);
    if is_root() {
        c.arg("--allow-run-as-root");
    }
    c.args(["--oversubscribe", "-np", &ranks.to_string()]).arg(&mpi.1).args(args).current_dir(dir).env_remove("RUST_LOG");
    c
}

fn is_root() -> bool {
    Command::new("id").arg("-u").output().is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
}

fn run_ok(mut c: Command) -> Output {
    let out = c.output().unwrap();
    assert!(out.status.success(), "{c:?} failed: {}\n{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    out
}

fn summary(dir: &Path) -> Summary {
    serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap()
}

/// The bytes of the run's last snapshot (its path in the summary is relative to where the run
/// was started: the run directory's parent here).
fn last_snapshot(dir: &Path) -> Vec<u8> {
    let path = PathBuf::from(summary(dir).last_snapshot.expect("a last snapshot"));
    std::fs::read(dir.parent().expect("a parent").join(path)).unwrap()
}

/// The same run on 1, 2 and 4 ranks: the last snapshots are byte for byte the same, on the CPU
/// path and on the GPU (a software adapter shared by the ranks), whose ranks compute one GPU's
/// bits. The summaries are the CPU path's.
fn same_on_every_rank_count(scene: &str, extra: &[&str]) -> Vec<Summary> {
    let summaries = same_on_every_rank_count_on("cpu", scene, extra);
    same_on_every_rank_count_on("gpu", scene, extra);
    summaries
}

fn same_on_every_rank_count_on(backend: &str, scene: &str, extra: &[&str]) -> Vec<Summary> {
    let Some(m) = mpi() else { return Vec::new() };
    let tmp = tempfile::tempdir().unwrap();
    let mut summaries = Vec::new();
    let mut first: Option<Vec<u8>> = None;
    for ranks in [1, 2, 4] {
        let out = format!("r{ranks}");
        let mut args = vec!["run", scene, "--backend", backend, "--quiet", "--out", &out];
        args.extend_from_slice(extra);
        run_ok(mpirun(&m, ranks, &args, tmp.path()));
        let dir = tmp.path().join(&out);
        let s = summary(&dir);
        assert_eq!(s.status, RunStatus::Completed);
        let snapshot = last_snapshot(&dir);
        match &first {
            None => first = Some(snapshot),
            Some(f) => assert!(f == &snapshot, "{scene}, {backend}: the last snapshot on {ranks} ranks differs from one rank's"),
        }
        assert_eq!(s.ranks.as_ref().map_or(1, |r| r.count), ranks);
        summaries.push(s);
    }
    summaries
}

#[test]
fn the_dam_break_on_one_two_and_four_ranks_writes_the_same_snapshots() {
    let s = same_on_every_rank_count("dam_break", &["--particles", "1000", "--steps", "200", "--snapshot-every", "100"]);
    if let Some(four) = s.get(2).and_then(|s| s.ranks.clone()) {
        assert_eq!(four.slab_axis, "x");
        assert_eq!(four.per_rank.iter().map(|r| r.particles).sum::<usize>(), s[2].fluid_particles);
        assert!(four.per_rank.iter().map(|r| r.migrated).sum::<u64>() > 0, "the collapsing column crosses slab faces: {four:?}");
        assert!(four.per_rank.iter().all(|r| (0.0..=1.0).contains(&r.exchange_share)));
        // The CPU path has no device to wait for.
        assert!(four.per_rank.iter().all(|r| r.device_seconds == 0.0 && r.device_share == 0.0), "{four:?}");
        // Each rank holds the walls near its slab; the summary counts the scene's.
        assert_eq!(s[2].wall_particles, s[0].wall_particles);
        assert!(four.per_rank.iter().all(|r| r.walls > 0 && r.walls < s[2].wall_particles), "{four:?}");
        // One machine: its 4 ranks, each in its own place.
        let mut places: Vec<usize> = four.per_rank.iter().map(|r| r.node_rank).collect();
        places.sort();
        assert!(places == [0, 1, 2, 3] && four.per_rank.iter().all(|r| r.node_ranks == 4 && r.threads >= 1), "{four:?}");
    }
}

/// Two GPU ranks against one GPU, in batches of 10 steps (the health checks), with a snapshot
/// after 20: the particles stay on each rank's device across batches (resident steps but for
/// the first, the step after the snapshot and one whose band or merge outgrows its room), and
/// `--full-exchange`, every step on the full path, writes the same snapshot byte for byte.
#[test]
fn the_dam_break_on_two_gpu_ranks_agrees_with_one_gpu() {
    let Some(m) = mpi() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let args = |out: &'static str| ["run", "dam_break", "--particles", "800", "--backend", "gpu", "--quiet", "--steps", "40", "--check-every", "10", "--snapshot-every", "20", "--format", "csv", "--out", out];
    run_ok(mpirun(&m, 1, &args("one"), tmp.path()));
    run_ok(mpirun(&m, 2, &args("two"), tmp.path()));
    let mut full = args("full").to_vec();
    full.push("--full-exchange");
    run_ok(mpirun(&m, 2, &full, tmp.path()));
    assert!(last_snapshot(&tmp.path().join("full")) == last_snapshot(&tmp.path().join("two")), "--full-exchange writes the resident steps' last snapshot");
    // Where the automatic choice falls on the CPU path (no hardware adapter), whose ranks
    // exchange every particle at every step, the flag is said to be unused, once.
    let o = run_ok(mpirun(&m, 2, &["run", "hydrostatic", "--particles", "300", "--steps", "2", "--quiet", "--full-exchange", "--out", "auto"], tmp.path()));
    let notes = String::from_utf8_lossy(&o.stderr).matches("note: --full-exchange not used: the automatic choice is the CPU path").count();
    assert_eq!(notes, (summary(&tmp.path().join("auto")).backend == "cpu") as usize, "{}", String::from_utf8_lossy(&o.stderr));
    let resident = |s: &Summary| s.ranks.as_ref().expect("a ranks block").per_rank.iter().map(|r| r.resident_steps).collect::<Vec<u64>>();
    let (one, two) = (summary(&tmp.path().join("one")), summary(&tmp.path().join("two")));
    assert_eq!(resident(&summary(&tmp.path().join("full"))), [0, 0]);
    assert!(resident(&two).iter().all(|&r| r >= 40 - 3), "{:?}", resident(&two));
    assert_eq!(two.status, RunStatus::Completed);
    let ranks = two.ranks.expect("a ranks block");
    assert!(ranks.per_rank.len() == 2 && ranks.per_rank.iter().all(|r| r.adapter.contains("hardware adapter") || r.adapter.contains("no hardware adapter")), "each rank says which adapter and why: {ranks:?}");
    // The time in the device's calls (the steps run there) is counted apart from the exchange's,
    // and on rank 0, whose run the shares are of, the two fit in it (another rank may wait for
    // rank 0 to start, and counts that wait in its exchange).
    let first = &ranks.per_rank[0];
    assert!(ranks.per_rank.iter().all(|r| r.device_seconds > 0.0) && first.device_share + first.exchange_share <= 1.0, "{ranks:?}");
    let rows = |dir: &str| -> Vec<Vec<f64>> {
        let text = String::from_utf8(last_snapshot(&tmp.path().join(dir))).unwrap();
        text.lines().skip(1).map(|l| l.split(',').map(|v| v.trim().parse().unwrap()).collect()).collect()
    };
    let (a, b) = (rows("one"), rows("two"));
    assert!(a.len() == b.len() && a.len() == one.fluid_particles);
    // Rows in particle order, x,y,z first and the density seventh: within the GPU-versus-CPU
    // bounds over many steps.
    let bounds = wgsph::solver::compare::MANY_STEPS;
    let relative = |col: usize, floor: f64| a.iter().zip(&b).map(|(r, s)| (r[col] - s[col]).abs() / r[col].abs().max(floor)).fold(0.0, f64::max);
    let position = (0..3).map(|k| relative(k, 1e-3)).fold(0.0, f64::max);
    let density = relative(6, 1.0);
    assert!(position <= bounds.position && density <= bounds.density, "1 and 2 GPU ranks after 40 steps: position {position:e}, density {density:e}");
}

/// DFSPH across MPI ranks (the CPU path): the dam break's last snapshot is byte for byte one
/// rank's, and the summary reports the same iterations.
#[test]
fn the_dam_break_with_dfsph_on_one_two_and_four_ranks_writes_the_same_snapshots() {
    let scenes = tempfile::tempdir().unwrap();
    let base = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/dam_break.toml")).unwrap();
    let dfsph = base.replace("speed_of_sound = 40.0", "solver = \"dfsph\"").replace("dt = 0.00025", "dt = 0.001");
    assert!(dfsph.contains("solver = \"dfsph\"") && dfsph.contains("dt = 0.001"), "the scene file changed: {dfsph}");
    let path = scenes.path().join("dam_break_dfsph.toml");
    std::fs::write(&path, dfsph).unwrap();
    let s = same_on_every_rank_count(path.to_str().unwrap(), &["--particles", "1000", "--steps", "60", "--snapshot-every", "60"]);
    for later in s.iter().skip(1) {
        assert_eq!(later.dfsph, s[0].dfsph, "the ranks iterate as one");
    }
}

/// DFSPH across two GPU ranks under mpirun (the host runs the solves' loops and exchanges the
/// ghosts' velocities after every iteration): the last snapshot is byte for byte one GPU's and
/// the ranks iterate as one GPU does.
#[test]
fn the_dam_break_with_dfsph_on_two_gpu_ranks_writes_one_gpus_snapshot() {
    let Some(m) = mpi() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let base = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/dam_break.toml")).unwrap();
    let dfsph = base.replace("speed_of_sound = 40.0", "solver = \"dfsph\"").replace("dt = 0.00025", "dt = 0.001");
    let path = tmp.path().join("dam_break_dfsph.toml");
    std::fs::write(&path, dfsph).unwrap();
    let scene = path.to_str().unwrap();
    let args = |out: &'static str| ["run", scene, "--particles", "800", "--backend", "gpu", "--quiet", "--steps", "30", "--snapshot-every", "30", "--format", "csv", "--out", out];
    run_ok(mpirun(&m, 1, &args("one"), tmp.path()));
    run_ok(mpirun(&m, 2, &args("two"), tmp.path()));
    let (one, two) = (summary(&tmp.path().join("one")), summary(&tmp.path().join("two")));
    assert_eq!(two.status, RunStatus::Completed);
    assert_eq!(two.ranks.as_ref().map(|r| r.count), Some(2));
    let counts = |s: &Summary| s.dfsph.as_ref().map(|d| (d.pressure_iterations_mean, d.pressure_iterations_max, d.divergence_iterations_mean, d.divergence_iterations_max));
    assert!(counts(&one).is_some() && counts(&one) == counts(&two), "the ranks iterate as one GPU: {:?} against {:?}", counts(&two), counts(&one));
    assert!(last_snapshot(&tmp.path().join("one")) == last_snapshot(&tmp.path().join("two")), "2 GPU ranks with DFSPH write one GPU's last snapshot");
}

#[test]
fn the_hydrostatic_tank_on_one_two_and_four_ranks_writes_the_same_snapshots() {
    same_on_every_rank_count("hydrostatic", &["--particles", "800", "--steps", "100", "--snapshot-every", "50"]);
}

/// Surface tension across ranks (a third ghost layer): the weightless cube pulling itself
/// into a ball, on 1, 2 and 4 ranks.
#[test]
fn the_weightless_cube_with_surface_tension_on_one_two_and_four_ranks_writes_the_same_snapshots() {
    let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/weightless_cube.toml");
    let s = same_on_every_rank_count(scene, &["--steps", "200", "--snapshot-every", "100"]);
    if let Some(four) = s.get(2).and_then(|s| s.ranks.clone()) {
        assert!(four.per_rank.iter().map(|r| r.migrated).sum::<u64>() > 0, "the cube's corners cross slab faces: {four:?}");
    }
}

#[test]
fn a_rank_without_particles_takes_part() {
    let Some(m) = mpi() else { return };
    let tmp = tempfile::tempdir().unwrap();
    // A puddle at one end of a long tank: of 4 slabs along the tank, the far ones hold nothing.
    let scene = r#"
        name = "puddle"
        domain = { min = [-0.1, -0.1, -0.1], max = [1.3, 0.3, 0.3] }
        physics = { smoothing_length = 0.04, particle_spacing = 0.02, speed_of_sound = 20, clamp_negative_pressure = true, viscosity = 0.01 }
        time = { dt = 0.0004, end_time = 0.1 }
        [[fluid]]
        min = [0.0, 0.0, 0.0]
        max = [0.12, 0.1, 0.2]
        [[boundary]]
        type = "container"
        min = [0.0, 0.0, 0.0]
        max = [1.2, 0.2, 0.2]
    "#;
    std::fs::write(tmp.path().join("puddle.toml"), scene).unwrap();
    for backend in ["cpu", "gpu"] {
        let args = ["run", "puddle.toml", "--backend", backend, "--quiet", "--steps", "40"];
        let (one, four) = (format!("one-{backend}"), format!("four-{backend}"));
        run_ok(mpirun(&m, 1, &[&args[..], &["--out", &one]].concat(), tmp.path()));
        run_ok(mpirun(&m, 4, &[&args[..], &["--out", &four]].concat(), tmp.path()));
        let ranks = summary(&tmp.path().join(&four)).ranks.expect("across ranks");
        assert!(ranks.per_rank.iter().any(|r| r.particles == 0), "{backend}: an empty rank: {ranks:?}");
        assert!(last_snapshot(&tmp.path().join(&one)) == last_snapshot(&tmp.path().join(&four)), "{backend}: 4 ranks, some empty, against one");
    }
}

#[test]
fn a_checkpoint_of_two_ranks_continues_on_four_and_on_one_and_one_of_one_rank_on_two() {
    let Some(m) = mpi() else { return };
    let tmp = tempfile::tempdir().unwrap();
    // WCSPH, and DFSPH (whose warm starts travel with the particles and are read per rank).
    let base = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/dam_break.toml")).unwrap();
    let dfsph = tmp.path().join("dam_break_dfsph.toml");
    std::fs::write(&dfsph, base.replace("speed_of_sound = 40.0", "solver = \"dfsph\"").replace("dt = 0.00025", "dt = 0.001")).unwrap();
    // Every change of rank count on the CPU path's WCSPH; one each for the others, so that
    // every method and path saves on one count and continues on another (each launch of
    // mpirun costs its ranks' start: docs/testing.md, the suite's time budget).
    let every = [("four", 2, 4), ("one", 2, 1), ("two", 1, 2)];
    let dfsph = dfsph.to_str().unwrap();
    let runs: [(&str, &str, &[(&str, usize, usize)]); 4] =
        [("dam_break", "cpu", &every), (dfsph, "cpu", &every[..1]), ("dam_break", "gpu", &every[1..2]), (dfsph, "gpu", &every[2..])];
    for (scene, backend, changes) in runs {
        let common = ["run", scene, "--particles", "800", "--backend", backend, "--quiet"];
        let out = |name: &str| format!("{name}-{}-{backend}", scene.len());
        run_ok(mpirun(&m, 1, &[&common[..], &["--steps", "60", "--out", &out("straight")]].concat(), tmp.path()));
        let straight = last_snapshot(&tmp.path().join(out("straight")));
        for &(name, saved_on, ranks) in changes {
            let name = out(name);
            run_ok(mpirun(&m, saved_on, &[&common[..], &["--steps", "30", "--checkpoint-every", "30", "--out", &name]].concat(), tmp.path()));
            run_ok(mpirun(&m, ranks, &["run", "--resume", &name, "--steps", "30", "--quiet"], tmp.path()));
            let s = summary(&tmp.path().join(&name));
            assert_eq!(s.status, RunStatus::Completed);
            assert!(last_snapshot(&tmp.path().join(&name)) == straight, "{scene}, {backend}: saved on {saved_on} ranks, continued on {ranks}: not the uninterrupted run");
        }
    }
}

#[test]
fn a_killed_rank_stops_every_rank_and_the_checkpoint_resumes() {
    let Some(m) = mpi() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let mut run = mpirun(&m, 2, &["run", "dam_break", "--particles", "2000", "--backend", "cpu", "--quiet", "--steps", "100000", "--checkpoint-every", "20", "--out", "killed"], tmp.path());
    let mut child = run.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
    let checkpoint = tmp.path().join("killed/checkpoint.wgsph");
    let start = Instant::now();
    while !checkpoint.exists() {
        assert!(start.elapsed() < Duration::from_secs(120), "no checkpoint after two minutes");
        assert!(child.try_wait().unwrap().is_none(), "the run ended before its first checkpoint");
        std::thread::sleep(Duration::from_millis(100));
    }
    // The ranks are mpirun's children; rank 1 is killed as a crash would end it.
    let ranks = Command::new("pgrep").args(["-P", &child.id().to_string()]).output().unwrap();
    let pids: Vec<String> = String::from_utf8_lossy(&ranks.stdout).split_whitespace().map(String::from).collect();
    assert_eq!(pids.len(), 2, "two rank processes under mpirun: {pids:?}");
    let killed_at = Instant::now();
    Command::new("kill").args(["-9", &pids[1]]).status().unwrap();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        assert!(killed_at.elapsed() < Duration::from_secs(30), "the other rank still runs 30 s after one was killed");
        std::thread::sleep(Duration::from_millis(100));
    };
    let out = child.wait_with_output().unwrap();
    let said = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(!status.success(), "a run with a killed rank failed");
    assert!(said.contains("signal 9") || said.contains("Killed"), "mpirun names the killed rank's end: {said}");
    // The last checkpoint continues the run on one rank.
    run_ok(mpirun(&m, 1, &["run", "--resume", "killed", "--steps", "10", "--quiet"], tmp.path()));
    assert_eq!(summary(&tmp.path().join("killed")).status, RunStatus::Completed);
}

#[test]
fn a_build_without_mpi_refuses_a_multi_rank_launch() {
    // As mpirun would start it: the launcher's variables set, plain wgsph (not wgsph-mpi).
    let tmp = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_wgsph"))
        .args(["run", "dam_break", "--steps", "1", "--out", "o"])
        .current_dir(tmp.path())
        .env("OMPI_COMM_WORLD_SIZE", "2")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("built without MPI") && err.contains("cargo build --release -p wgsph-mpi"), "{err}");
    assert!(!tmp.path().join("o").exists(), "nothing written");
}

#[test]
fn an_error_on_one_rank_stops_every_rank_naming_it() {
    let Some(m) = mpi() else { return };
    let tmp = tempfile::tempdir().unwrap();
    // Rank 0 alone checks the output directory, and refuses one a run did not write; the
    // other rank is already waiting for it.
    std::fs::create_dir(tmp.path().join("taken")).unwrap();
    std::fs::write(tmp.path().join("taken/notes.txt"), "mine").unwrap();
    let start = Instant::now();
    let out = mpirun(&m, 2, &["run", "dam_break", "--particles", "500", "--backend", "cpu", "--steps", "10", "--out", "taken"], tmp.path()).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(start.elapsed() < Duration::from_secs(60), "every rank ended");
    assert!(err.contains("rank 0 of 2 stops every rank") && err.contains("taken"), "{err}");
    assert_eq!(std::fs::read_to_string(tmp.path().join("taken/notes.txt")).unwrap(), "mine");
}

/// Probes across MPI ranks: the first rank alone writes the series, and those of a point, a gauge
/// and a front are byte for byte those of one rank (each point and gauge level is evaluated by
/// the rank whose slab holds it; the tank's slabs cut the vertical, so the gauge crosses them).
/// The tank with a point probe, a gauge (where `gauge`) and a front every 10 steps, run for 100
/// steps on 1 and 2 ranks of `backend`: each probe's CSV file of both runs (the gauge's empty
/// without it).
fn probe_series_on_one_and_two_ranks(m: &(PathBuf, PathBuf), backend: &str, gauge: bool) -> Vec<[String; 3]> {
    let tmp = tempfile::tempdir().unwrap();
    let base = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/hydrostatic.toml")).unwrap();
    let probes = r#"
[[probe]]
name = "sensor"
type = "point"
position = [0.2, 0.05, 0.05]
every_steps = 10

[[probe]]
name = "front"
type = "front"
every_steps = 10
"#;
    let level = r#"
[[probe]]
name = "level"
type = "gauge"
position = [0.2, 0.0, 0.05]
every_steps = 10
"#;
    std::fs::write(tmp.path().join("tank.toml"), base + probes + if gauge { level } else { "" }).unwrap();
    let mut series = Vec::new();
    for ranks in [1, 2] {
        let out = format!("r{ranks}");
        run_ok(mpirun(m, ranks, &["run", "tank.toml", "--backend", backend, "--quiet", "--particles", "800", "--steps", "100", "--out", &out], tmp.path()));
        let read = |name: &str| std::fs::read_to_string(tmp.path().join(&out).join("probes").join(format!("{name}.csv"))).unwrap_or_default();
        let files = ["sensor", "level", "front"].map(read);
        assert_eq!(files[0].lines().count(), 11, "a header and the steps 0, 10, ..., 90: {}", files[0]);
        assert_eq!(files[1].is_empty(), !gauge);
        assert!(tmp.path().join(&out).join("probes").join("sensor.png").exists(), "the plot");
        series.push(files);
    }
    series
}

/// Probes across ranks on the CPU path: the CSV series of a point probe, a gauge
/// and a front are byte for byte those of one rank (each point and gauge level is evaluated by
/// the rank whose slab holds it; the tank's slabs cut the vertical, so the gauge crosses them).
#[test]
fn probes_on_two_ranks_write_the_series_of_one_rank() {
    let Some(m) = mpi() else { return };
    let series = probe_series_on_one_and_two_ranks(&m, "cpu", true);
    assert!(series[0] == series[1], "one rank:\n{:?}\ntwo ranks:\n{:?}", series[0], series[1]);
}

/// Probes on GPU ranks. Without the gauge each rank's device samples them within its steps and
/// the ranks add their rows: the series are one GPU's byte for byte. With a gauge whose line
/// crosses the slabs (the tank's cut the vertical) the host samples them from each device's
/// density stage: one GPU's series to the rounding of the probe stage's f32 sums.
#[test]
fn probes_on_two_gpu_ranks_write_the_series_of_one_gpu() {
    let Some(m) = mpi() else { return };
    let series = probe_series_on_one_and_two_ranks(&m, "gpu", false);
    assert!(series[0] == series[1], "one GPU:\n{:?}\ntwo GPU ranks:\n{:?}", series[0], series[1]);
    let series = probe_series_on_one_and_two_ranks(&m, "gpu", true);
    let numbers = |text: &str| -> Vec<Vec<f64>> { text.lines().skip(1).map(|l| l.split(',').map(|v| v.trim().parse().unwrap()).collect()).collect() };
    for (one, two) in series[0].iter().zip(&series[1]) {
        assert_eq!(one.lines().next(), two.lines().next(), "the same columns");
        let (a, b) = (numbers(one), numbers(two));
        assert_eq!(a.len(), b.len());
        for (r, s) in a.iter().zip(&b) {
            for (x, y) in r.iter().zip(s) {
                // Pressures in Pa and densities in kg/m^3 at the scale of rho0; lengths in m.
                assert!((x - y).abs() <= 1e-5 * x.abs().max(1.0), "one GPU:\n{one}\ntwo GPU ranks:\n{two}");
            }
        }
    }
}
