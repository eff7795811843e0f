//! `wgsph run --resume DIR`: continues the run in DIR from its checkpoint, bit for bit.

use super::args::RunArgs;
use super::errors::InputError;
use super::run::{exit_code_of, report_run, run, steps_for_time, ResumedRun, RunOptions};
use super::signals;
use crate::io::checkpoint::{read, read_where, Checkpoint, CheckpointFile, CHECKPOINT_FILE};
use crate::io::rundir::{check_resumable, remove_partial_files, remove_steps_after, restore_marker, run_id, RunWrites, MARKER, SCENE_COPY, SNAPSHOTS_DIR};
use crate::io::summary::Summary;
use crate::model::scene::{Scene, SceneOrigin};
use crate::solver::{open, Backend, BackendChoice, Precision, Ranks};
use anyhow::Context;
use std::path::{Path, PathBuf};

/// Continues the run in `dir` from its checkpoint, to the end it was heading to, or for
/// `--steps N` / `--time T` more.
pub fn resume_run(dir: &Path, args: &RunArgs, ranks: Option<&Ranks>) -> anyhow::Result<i32> {
    // The checkpoint records the run, not how its GPU step was tuned: a flag given here would
    // be silently unused (and a neighbour skin changes the sums' order).
    let tuning = args.gpu.given();
    if !tuning.is_empty() {
        return Err(InputError(format!(
            "--resume continues a run with the checkpoint's settings and the GPU step's defaults; {} cannot be given with it{}",
            tuning.join(", "),
            if tuning.contains(&"--neighbour-skin") { " (a run with a neighbour skin resumes without one)" } else { "" }
        ))
        .into());
    }
    // A checkpoint does not record pictures: a resumed run draws none, so how they would look
    // would change nothing.
    let mut pictures = args.picture.given();
    if args.frame_every.is_some() {
        pictures.insert(0, "--frame-every");
    }
    if !pictures.is_empty() {
        return Err(InputError(format!(
            "--resume continues a run without pictures (a checkpoint does not record them); {} cannot be given with it: draw a run's pictures with wgsph run DIR/scene.toml --frames FRAMES_DIR",
            pictures.join(", ")
        ))
        .into());
    }
    if let Some(t) = args.time {
        if !(t.is_finite() && t >= 0.0) {
            return Err(InputError(format!("--time is {t}; must be a finite number >= 0")).into());
        }
    }
    if !dir.is_dir() {
        let what = if dir.exists() { "is a file, not a run directory" } else { "does not exist" };
        return Err(InputError(format!("--resume {}: {what}; give the --out directory of a run written with --checkpoint-every K", dir.display())).into());
    }
    let writes_files = super::ranks::writes_files(ranks);
    // Its subdirectories and files must be the run's own, before the checkpoint is read.
    if writes_files {
        check_resumable(dir)?;
    }
    let path = dir.join(CHECKPOINT_FILE);
    if !path.exists() {
        return Err(InputError(format!(
            "--resume {}: there is no checkpoint {} (write one with --checkpoint-every K)",
            dir.display(),
            path.display()
        ))
        .into());
    }
    // Across ranks each rank reads only its part of the particles, once its backend is open;
    // here the rest (a read that keeps no particle).
    let c = match ranks {
        None => read(&path),
        Some(_) => read_where(&path, &mut |_, _| false).map(|(c, _)| c),
    }
    .map_err(|e| InputError(format!("--resume: {e}")))?;
    // A checkpoint copied in from another run would mix that run's steps into this one's files.
    if let (true, Some(theirs), Some(ours)) = (writes_files, c.run.run_id.as_deref(), run_id(dir)) {
        if theirs != ours {
            return Err(InputError(format!(
                "--resume {}: {} was written by another run (run {theirs}) than the one this directory holds (run {ours}, in its {MARKER}): \
                 resuming it here would mix the two runs' snapshots and series; resume the directory the checkpoint came from",
                dir.display(),
                path.display()
            ))
            .into());
        }
    }
    let scene = Scene::from_toml_str(&c.scene_toml, &SceneOrigin::File(path.clone()))?;
    if writes_files {
        if let Some(why) = scene_copy_differs(dir, &scene) {
            eprintln!("warning: {why}; the resumed run continues the checkpoint's scene, as it was when the run started");
        }
    }
    let params = scene.params();
    let step = c.state.step;
    let end = match (args.steps, args.time) {
        (Some(n), _) => step.saturating_add(n),
        (None, Some(t)) => step.saturating_add(steps_for_time(&params, Some(t))),
        (None, None) => c.run.end_step,
    };
    if end <= step {
        let why = match (args.steps, args.time) {
            (Some(_), _) => "--steps 0 adds no step beyond the checkpoint's: give at least 1".to_string(),
            (None, Some(t)) => format!("--time {} adds no step of dt = {}: give a longer time", crate::model::numbers::short(t), crate::model::numbers::short(params.dt)),
            (None, None) => "the run already reached its end there; give --steps N or --time T to continue further".to_string(),
        };
        return Err(InputError(format!("--resume {}: the checkpoint is at step {step}; {why}", dir.display())).into());
    }
    // A run killed while writing left partial files of the atomic writer: they go first.
    let removed = if writes_files { remove_partial_files(dir)? } else { Vec::new() };
    if !removed.is_empty() && !args.quiet {
        let names: Vec<String> = removed.iter().map(|p| p.display().to_string()).collect();
        println!("removed {} partial file(s) the interrupted run left: {}", removed.len(), names.join(", "));
    }
    // What the run writes, as its checkpoint records it.
    let writes = RunWrites::of_run(&c.run.formats, (c.run.surface_mesh_every > 0).then_some(c.run.surface_mesh_format), &params.probes);
    if writes_files {
        if restore_marker(dir, &writes, c.run.run_id.as_deref())? {
            eprintln!("note: {} had no {MARKER} (it was deleted): written again, so that --overwrite knows the run's files", dir.display());
        }
    }
    // A state whose arrays disagree with each other was not written so by a run: corrupt, bad
    // input (the backend checks it against the scene's particles when it is restored).
    let corrupt = |e: anyhow::Error| InputError(format!("--resume {}: {}: {e:#}; the checkpoint is corrupt and cannot be resumed", dir.display(), path.display()));
    let mut choice = choice_of_kind(&c.state.kind).map_err(corrupt)?;
    if ranks.is_none() {
        c.state.check_fits(&c.state.kind, c.state.positions.len()).map_err(corrupt)?;
    }
    signals::install();
    choice.ranks = ranks.cloned();
    let mut sim = open(&scene, &choice)?;
    let backend = sim.backend();
    // The steps after the checkpoint are computed again (the backend is open, the checkpoint
    // sound): what the run wrote for them goes.
    if writes_files {
        let later = remove_steps_after(dir, step, &writes)?;
        if !later.is_empty() && !args.quiet {
            println!("removed {} snapshot and surface file(s) of steps after the checkpoint's step {step}, which the resumed run computes again", later.len());
        }
    }
    // The CPU path gives the same bits with any number of threads; a GPU may not on another adapter.
    if c.state.kind == "gpu" && backend.adapter() != c.run.adapter {
        eprintln!(
            "warning: the checkpoint was computed on {}; this run uses {}: it continues the run, but not bit for bit as the original adapter would",
            c.run.adapter,
            backend.adapter()
        );
    }
    let summary = match ranks {
        None => resume_with(backend, dir, &c, end, !args.quiet && writes_files, writes_files)?,
        Some(_) => {
            let restored = backend.restore_state_part(&mut CheckpointFile(&path)).unwrap_or_else(|| Err(anyhow::anyhow!("the backend does not run across ranks")));
            restored.with_context(|| format!("cannot restore the checkpoint in {}", dir.display()))?;
            continue_run(backend, dir, &c, end, !args.quiet && writes_files, writes_files)?
        }
    };
    if !writes_files {
        return Ok(exit_code_of(&summary));
    }
    report_run(&summary, dir, args.quiet)
}

/// Why the run's copy of its scene (`DIR/scene.toml`) no longer describes the checkpoint's
/// scene, or None when it does: an edited copy is not what a resumed run uses.
fn scene_copy_differs(dir: &Path, scene: &Scene) -> Option<String> {
    let copy = dir.join(SCENE_COPY);
    let text = match std::fs::read_to_string(&copy) {
        Ok(t) => t,
        Err(e) => return Some(format!("{} cannot be read ({e})", copy.display())),
    };
    let edited = format!("{} was edited since the run started (a changed scene is a new run: wgsph run {} --out NEW_DIR)", copy.display(), copy.display());
    match Scene::from_toml_str(&text, &SceneOrigin::File(copy.clone())) {
        Ok(s) if s == *scene => None,
        _ => Some(edited),
    }
}

/// Restores `c` into `backend` (a fresh one of the kind that saved it) and runs on to step
/// `end`, writing into `dir` with the settings of the interrupted run.
pub fn resume_with(backend: &mut dyn Backend, dir: &Path, c: &Checkpoint, end: u64, progress: bool, writes_files: bool) -> anyhow::Result<Summary> {
    backend.restore_state(&c.state).with_context(|| format!("cannot restore the checkpoint in {}", dir.display()))?;
    continue_run(backend, dir, c, end, progress, writes_files)
}

/// The checkpoint's last snapshot `recorded` as a file of the run directory `dir`: a run's
/// snapshots live in its snapshots/, and a directory copied or moved since the checkpoint was
/// written names its own, not the one it came from.
fn own_snapshot(dir: &Path, recorded: &str) -> PathBuf {
    match Path::new(recorded).file_name() {
        Some(name) => dir.join(SNAPSHOTS_DIR).join(name),
        None => PathBuf::from(recorded),
    }
}

/// Runs a backend that holds the state of `c` on to step `end` (see [`resume_with`]).
fn continue_run(backend: &mut dyn Backend, dir: &Path, c: &Checkpoint, end: u64, progress: bool, writes_files: bool) -> anyhow::Result<Summary> {
    let step = c.state.step;
    log::info!("resuming {} at step {step} towards step {end}", dir.display());
    let opts = RunOptions {
        steps: end.saturating_sub(step),
        out: dir.to_path_buf(),
        snapshot_every: c.run.snapshot_every,
        snapshot_interval: c.run.snapshot_interval,
        check_every: c.run.check_every,
        progress,
        formats: c.run.formats.clone(),
        checkpoint_every: c.run.checkpoint_every,
        resumed: Some(ResumedRun {
            last_snapshot: c.run.last_snapshot.as_deref().map(|p| own_snapshot(dir, p)),
            max_speed: c.run.max_speed,
            series_lines: c.run.series_lines.clone(),
        }),
        frames: None,
        end_time: c.run.end_time,
        surface_mesh_every: c.run.surface_mesh_every,
        surface_mesh_format: c.run.surface_mesh_format,
        start: None,
        writes_files,
    };
    let scene = Scene::from_toml_str(&c.scene_toml, &SceneOrigin::Text)?;
    run(backend, &scene, &opts)
}

/// The backend of the kind that saved a state (`gpu`, `cpu f32`, `cpu f64`).
pub fn choice_of_kind(kind: &str) -> anyhow::Result<BackendChoice> {
    Ok(match kind {
        "gpu" => BackendChoice::gpu(),
        "cpu f64" => BackendChoice::cpu(Precision::F64),
        "cpu f32" => BackendChoice::cpu(Precision::F32),
        other => anyhow::bail!("the checkpoint names an unknown backend '{other}'"),
    })
}

#[cfg(test)]
mod tests {
    use super::own_snapshot;
    use std::path::Path;

    #[test]
    fn a_copied_run_directory_names_its_own_last_snapshot() {
        assert_eq!(own_snapshot(Path::new("copy"), "runs/original/snapshots/step_000010.csv"), Path::new("copy/snapshots/step_000010.csv"));
        assert_eq!(own_snapshot(Path::new("/data/run"), "/data/run/snapshots/step_000002.vtk"), Path::new("/data/run/snapshots/step_000002.vtk"));
    }
}
