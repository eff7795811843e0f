//! Checkpoint and restart: a run interrupted and resumed writes bitwise the same snapshots as
//! an uninterrupted run (CPU f64 and f32, and every GPU adapter); bad checkpoints are refused.

use crate::common;

use std::path::Path;
use std::process::{Command, Output};
use wgsph::io::checkpoint::read;
use wgsph::app::resume::resume_with;
use wgsph::io::checkpoint::CHECKPOINT_FILE;
use wgsph::io::snapshot::format::SnapshotFormat;
use wgsph::app::run::run;
use wgsph::app::run::RunOptions;
use wgsph::model::params::Params;
use wgsph::model::state::BackendState;
use wgsph::model::state::StepFields;
use wgsph::solver::Backend;
use wgsph::solver::gpu::GpuContext;
use wgsph::model::state::Health;
use wgsph::model::scene::Scene;
use wgsph::model::state::Snapshot;
use wgsph::io::summary::RunStatus;

fn wgsph(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_wgsph")).args(args).current_dir(dir).output().unwrap()
}

/// A backend that fails once it reaches `fail_at` steps, as a lost device or a killed process
/// would stop a run.
struct FailingAt<'a> {
    inner: &'a mut dyn Backend,
    fail_at: u64,
}

impl Backend for FailingAt<'_> {
    fn kind(&self) -> &'static str {
        self.inner.kind()
    }
    fn adapter(&self) -> String {
        self.inner.adapter()
    }
    fn params(&self) -> &Params {
        self.inner.params()
    }
    fn fluid_count(&self) -> usize {
        self.inner.fluid_count()
    }
    fn wall_count(&self) -> usize {
        self.inner.wall_count()
    }
    fn step(&mut self, n: u64) -> anyhow::Result<()> {
        let room = self.fail_at.saturating_sub(self.inner.steps_done());
        self.inner.step(n.min(room))?;
        anyhow::ensure!(n <= room, "interrupted at step {}", self.inner.steps_done());
        Ok(())
    }
    fn steps_done(&self) -> u64 {
        self.inner.steps_done()
    }
    fn time(&self) -> f64 {
        self.inner.time()
    }
    fn dt_stats(&mut self) -> anyhow::Result<wgsph::model::state::DtStats> {
        self.inner.dt_stats()
    }
    fn health(&mut self) -> anyhow::Result<Health> {
        self.inner.health()
    }
    fn snapshot(&mut self) -> anyhow::Result<Snapshot> {
        self.inner.snapshot()
    }
    fn step_fields(&mut self) -> anyhow::Result<StepFields> {
        self.inner.step_fields()
    }
    fn save_state(&mut self) -> anyhow::Result<BackendState> {
        self.inner.save_state()
    }
    fn streams_snapshots(&self) -> bool {
        self.inner.streams_snapshots()
    }
    fn visit_snapshot_rows(&mut self, visit: &mut dyn FnMut(u64, &[wgsph::solver::SnapshotRow]) -> anyhow::Result<()>) -> anyhow::Result<()> {
        self.inner.visit_snapshot_rows(visit)
    }
    fn save_state_header(&mut self) -> anyhow::Result<BackendState> {
        self.inner.save_state_header()
    }
    fn visit_state_array(
        &mut self,
        array: wgsph::solver::StateArray,
        chunk: u64,
        visit: &mut dyn FnMut(wgsph::solver::StatePiece) -> anyhow::Result<()>,
    ) -> anyhow::Result<()> {
        self.inner.visit_state_array(array, chunk, visit)
    }
    fn restore_state(&mut self, state: &BackendState) -> anyhow::Result<()> {
        self.inner.restore_state(state)
    }
    fn take_probe_samples(&mut self) -> anyhow::Result<Vec<wgsph::model::probes::ProbeSample>> {
        self.inner.take_probe_samples()
    }
}

fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir.join("snapshots"))
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            (e.file_name().to_string_lossy().into_owned(), std::fs::read(e.path()).unwrap())
        })
        .collect();
    v.sort();
    v
}

/// Runs 40 steps uninterrupted, and 40 steps interrupted at step 25 with checkpoints every 20
/// and resumed on a fresh backend from `make`; every snapshot file must be the same bytes.
fn resumed_run_is_bitwise_the_uninterrupted_one(make: &mut dyn FnMut() -> Box<dyn Backend>, scene: &Scene, what: &str) {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    let opts = |out: &Path, checkpoint_every| RunOptions {
        steps: 40,
        out: out.to_path_buf(),
        snapshot_every: 10,
        check_every: 7,
        formats: vec![SnapshotFormat::Csv, SnapshotFormat::Vtk],
        checkpoint_every,
        ..Default::default()
    };
    let whole = run(make().as_mut(), scene, &opts(&a, 0)).unwrap();
    assert!(whole.failure.is_none());
    let mut first = make();
    // A run that stops on an error after its start still writes its summary, naming the step.
    let stopped = run(&mut FailingAt { inner: first.as_mut(), fail_at: 25 }, scene, &opts(&b, 20)).unwrap();
    assert_eq!(stopped.status, RunStatus::Error, "{what}");
    let why = stopped.failure.expect("the failure is recorded");
    assert!(why.contains("interrupted at step 25"), "{why}");
    assert_eq!(stopped.last_checkpoint.map(|p| Path::new(&p).file_name().unwrap().to_owned()), Some(CHECKPOINT_FILE.into()));
    let c = read(&b.join(CHECKPOINT_FILE)).unwrap();
    assert_eq!((c.state.step, c.run.end_step), (20, 40), "{what}");
    let names = |d: &Path| files(d).into_iter().map(|f| f.0).collect::<Vec<_>>();
    assert_eq!(names(&b).len(), 3 * 2 + 2, "{what}: snapshots 0, 10, 20, the series and the index before the resume");
    let resumed = resume_with(make().as_mut(), &b, &c, c.run.end_step, false, true).unwrap();
    assert_eq!((resumed.steps, resumed.failure.clone()), (20, None));
    assert_eq!(names(&a), names(&b), "{what}");
    for ((name, x), (_, y)) in files(&a).iter().zip(files(&b).iter()) {
        assert!(x == y, "{what}: {name} differs after the resume");
    }
    assert_eq!(resumed.max_density_ratio, whole.max_density_ratio, "{what}");
    assert_eq!(resumed.sim_time, whole.sim_time, "{what}");
    assert_eq!(resumed.last_snapshot.map(|p| Path::new(&p).file_name().unwrap().to_owned()), Some("step_000040.csv".into()));
    // The checkpoint of the finished run is at its end.
    assert_eq!(read(&b.join(CHECKPOINT_FILE)).unwrap().state.step, 40);
}

/// The dam break with a fixed step, with adaptive dt (whose time, dt and compensation live in
/// the state too), and with continuity density (whose carried densities do).
fn scenes() -> Vec<(Scene, &'static str)> {
    let fixed = Scene::builtin("dam_break").unwrap();
    let mut adaptive = fixed.clone();
    adaptive.time.adaptive = true;
    let continuity = common::TestScene::from(fixed.clone()).continuity().density_diffusion(0.1).hydrostatic_start().build();
    vec![(fixed, "fixed dt"), (adaptive, "adaptive dt"), (continuity, "continuity density")]
}

/// The dam break with DFSPH (whose warm start and iteration counts live in the state too), with
/// a fixed step and with adaptive dt.
fn dfsph_scenes() -> Vec<(Scene, &'static str)> {
    let fixed = common::TestScene::from(Scene::builtin("dam_break").unwrap()).dfsph().dt(0.001).build();
    let mut adaptive = fixed.clone();
    adaptive.time.adaptive = true;
    vec![(fixed, "DFSPH, fixed dt"), (adaptive, "DFSPH, adaptive dt")]
}

#[test]
fn cpu_restart_is_bitwise_exact() {
    for (scene, how) in scenes().into_iter().chain(dfsph_scenes()) {
        resumed_run_is_bitwise_the_uninterrupted_one(&mut || Box::new(common::cpu::<f64>(&scene)), &scene, &format!("cpu f64, {how}"));
        resumed_run_is_bitwise_the_uninterrupted_one(&mut || Box::new(common::cpu::<f32>(&scene)), &scene, &format!("cpu f32, {how}"));
    }
}

/// Each scene resumes on one adapter, taking the adapters found in turn, so that every adapter
/// resumes some of them (each scene on every adapter took the io tests' whole time budget:
/// docs/testing.md); every run, the resumed one too, opens a device of its own.
#[test]
fn gpu_restart_is_bitwise_exact_on_every_adapter() {
    let contexts = common::contexts();
    for (i, (scene, how)) in scenes().into_iter().chain(dfsph_scenes()).enumerate() {
        let Some(ctx) = contexts.get(i % contexts.len().max(1)) else { continue };
        let name = format!("{}, {how}", ctx.describe());
        let mut make = || -> Box<dyn Backend> { Box::new(common::gpu(GpuContext::from_adapter(ctx.adapter.clone()).unwrap(), &scene)) };
        resumed_run_is_bitwise_the_uninterrupted_one(&mut make, &scene, &name);
    }
}

#[test]
fn resume_from_the_command_line_continues_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let common = ["--snapshot-every", "5", "--backend", "cpu", "--format", "csv,vtk"];
    let o = wgsph(&[&["run", "hydrostatic", "--steps", "30", "--out", "a"], &common[..]].concat(), dir.path());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = wgsph(&[&["run", "hydrostatic", "--steps", "20", "--out", "b", "--checkpoint-every", "10"], &common[..]].concat(), dir.path());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // The run reached its end: resuming needs more steps.
    let o = wgsph(&["run", "--resume", "b"], dir.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("the checkpoint is at step 20; the run already reached its end there"), "{}", String::from_utf8_lossy(&o.stderr));
    for (extra, says) in [
        (&["--steps", "0"][..], "--steps 0 adds no step beyond the checkpoint's"),
        (&["--time", "0"][..], "--time 0 adds no step"),
        (&["--steps", "1", "--resolution", "32x32"][..], "--resolution cannot be given with it"),
        (&["--steps", "1", "--fused"][..], "--fused cannot be given with it"),
    ] {
        let o = wgsph(&[&["run", "--resume", "b"][..], extra].concat(), dir.path());
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{extra:?}: {err}");
        assert!(err.contains(says) && !err.contains("neighbour skin"), "{extra:?}: {err}");
    }
    std::fs::write(dir.path().join("afile"), "x").unwrap();
    let o = wgsph(&["run", "--resume", "afile"], dir.path());
    assert!(o.status.code() == Some(2) && String::from_utf8_lossy(&o.stderr).contains("afile: is a file, not a run directory"), "{}", String::from_utf8_lossy(&o.stderr));
    let o = wgsph(&["run", "--resume", "b", "--steps", "10"], dir.path());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("10 steps"));
    assert_eq!(files(&dir.path().join("a")), files(&dir.path().join("b")));
    // Settings come from the checkpoint: changing them is refused.
    for changed in [&["--out", "c"][..], &["--set", "time.dt=1e-4"], &["--unset", "physics.viscosity"]] {
        let o = wgsph(&[&["run", "--resume", "b", "--steps", "1"][..], changed].concat(), dir.path());
        assert_eq!(o.status.code(), Some(2), "{changed:?}");
        assert!(String::from_utf8_lossy(&o.stderr).contains("cannot be used with"), "{}", String::from_utf8_lossy(&o.stderr));
    }
}

#[test]
fn bad_checkpoints_are_refused_with_a_clear_message() {
    let dir = tempfile::tempdir().unwrap();
    let o = wgsph(&["run", "hydrostatic", "--steps", "4", "--backend", "cpu", "--out", "b", "--checkpoint-every", "2"], dir.path());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let path = dir.path().join("b").join(CHECKPOINT_FILE);
    let good = std::fs::read(&path).unwrap();
    assert_eq!(read(&path).unwrap().state.step, 4);
    let version = wgsph::io::checkpoint::WGSPH_VERSION.as_bytes();
    let at = good.windows(version.len()).position(|w| w == version).unwrap();
    let mut other_version = good.clone();
    other_version[at..at + version.len()].copy_from_slice(&b"9.9.99999999"[..version.len()]);
    let mut flipped = good.clone();
    let last = flipped.len() - 9;
    flipped[last] ^= 0x40;
    // Written with a good checksum by something else than a run: a NaN, arrays that disagree,
    // a backend no wgsph has.
    let altered = |change: &dyn Fn(&mut wgsph::io::checkpoint::Checkpoint)| -> Vec<u8> {
        std::fs::write(&path, &good).unwrap();
        let mut c = read(&path).unwrap();
        change(&mut c);
        wgsph::io::checkpoint::write(&path, &c).unwrap();
        std::fs::read(&path).unwrap()
    };
    let not_finite = altered(&|c| c.state.positions[3][1] = f64::NAN);
    let id_short = altered(&|c| {
        c.state.ids.pop();
    });
    let other_kind = altered(&|c| c.state.kind = "cpu f16".into());
    let cases: [(&str, Vec<u8>, &[&str]); 9] = [
        ("other version", other_version, &["written by wgsph 9.9", "only resumes its own"]),
        ("flipped bit", flipped, &["corrupt", "checksum"]),
        ("truncated", good[..good.len() - 100].to_vec(), &["corrupt", "payload has"]),
        ("not a checkpoint", b"hello".to_vec(), &["not a wgsph checkpoint"]),
        ("cut in its magic", good[..5].to_vec(), &["corrupt", "truncated"]),
        ("empty", Vec::new(), &["corrupt", "empty"]),
        ("not finite", not_finite, &["corrupt", "particle 3's position or velocity is not finite"]),
        ("an id short", id_short, &["corrupt", "ids and 0 carried densities", "checkpoint.wgsph"]),
        ("unknown backend", other_kind, &["corrupt", "unknown backend 'cpu f16'", "checkpoint.wgsph"]),
    ];
    for (what, bytes, words) in cases {
        std::fs::write(&path, bytes).unwrap();
        let o = wgsph(&["run", "--resume", "b", "--steps", "2"], dir.path());
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{what}: {err}");
        for w in words {
            assert!(err.contains(w), "{what}: {err}");
        }
    }
    std::fs::remove_file(&path).unwrap();
    let o = wgsph(&["run", "--resume", "b"], dir.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("no checkpoint"));
}
