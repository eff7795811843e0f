//! `wgsph run`: the run loop steps a backend, writes snapshots, checkpoints, frames and the
//! summary, and stops with a diagnosis when the state goes bad.

use super::args::{BackendArg, PrecisionArg, RunArgs, SnapshotInterval};
use super::errors::InputError;
use super::signals::{self, StopSignal};
use crate::io::checkpoint::{self, RunRecord, CHECKPOINT_FILE};
use crate::io::probes::ProbeWriter;
use crate::io::rundir::{numbered_run_dir, run_id, write_scene_copy, RunOutputs, RunWrites, StartGuard, PROBES_DIR, SNAPSHOTS_DIR};
use crate::io::snapshot::format::SnapshotFormat;
use crate::io::snapshot::SnapshotWriter;
use crate::io::summary::{write_summary, DfsphSummary, RanksSummary, RunStatus, Summary, SUMMARY_FILE};
use crate::io::surface::{write_snapshot_surface, MeshFormat, SurfaceParameters};
use crate::model::params::Params;
use crate::model::scene::Scene;
use crate::model::diagnosis::diagnose_non_positive_density;
use crate::model::state::{Snapshot, SnapshotExtremes};
use crate::model::diagnosis::regime_warnings;
use crate::solver::backend::diagnose_failure;
use crate::solver::{open, Backend, Ranks};
use crate::viz::probe_plots::plot_probes;
use crate::viz::render::frames::FrameRecorder;
use crate::viz::render::RenderOptions;
use anyhow::Context;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Pictures to write during a run.
#[derive(Clone, Debug)]
pub struct FramesSpec {
    pub dir: PathBuf,
    /// A picture every this many steps (the first of the run and the last too).
    pub every: u64,
    pub options: RenderOptions,
}

pub struct RunOptions {
    pub steps: u64,
    pub out: PathBuf,
    /// Write a snapshot every this many steps (0: only the first and the last).
    pub snapshot_every: u64,
    /// Write a snapshot at the first step reaching each multiple of this simulated time (with
    /// `snapshot_every` 0).
    pub snapshot_interval: Option<f64>,
    /// Read the health counters every this many steps.
    pub check_every: u64,
    pub progress: bool,
    pub frames: Option<FramesSpec>,
    /// Snapshot file formats (the first one is the summary's `last_snapshot`).
    pub formats: Vec<SnapshotFormat>,
    /// Write `DIR/checkpoint.wgsph` every this many steps (0: never).
    pub checkpoint_every: u64,
    /// Set when the run continues from a checkpoint: no first snapshot is written (the
    /// interrupted run wrote it), and the VTK series index keeps the earlier snapshots.
    pub resumed: Option<ResumedRun>,
    /// With adaptive dt: stop at the first step that reaches this simulated time (`steps` is
    /// then an upper bound).
    pub end_time: Option<f64>,
    /// Reconstruct the fluid surface every this many steps (0: never), into `DIR/surface/`.
    pub surface_mesh_every: u64,
    pub surface_mesh_format: MeshFormat,
    /// The start of a new run, committed once the run took its first step; an error before
    /// then returns with the start still uncommitted (dropping it undoes the start).
    pub start: Option<StartGuard>,
    /// Whether this process writes the files: alone it does; across ranks rank 0 does, and the
    /// other ranks take part in the same collective reads (snapshots, checkpoints) without
    /// writing.
    pub writes_files: bool,
}

/// What a resumed run takes over from the run that wrote its checkpoint.
#[derive(Clone, Debug, Default)]
pub struct ResumedRun {
    pub last_snapshot: Option<PathBuf>,
    pub max_speed: f64,
    /// The series files' lines the resumed run should find (`RunRecord::series_lines`).
    pub series_lines: Vec<(String, u64)>,
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions {
            steps: 0,
            out: PathBuf::from("out"),
            snapshot_every: 0,
            snapshot_interval: None,
            check_every: 50,
            progress: false,
            formats: vec![SnapshotFormat::Csv],
            checkpoint_every: 0,
            resumed: None,
            frames: None,
            end_time: None,
            surface_mesh_every: 0,
            surface_mesh_format: MeshFormat::Obj,
            start: None,
            writes_files: true,
        }
    }
}

/// Steps for a run of `time` seconds (or the scene's end time).
pub fn steps_for_time(params: &Params, time: Option<f64>) -> u64 {
    let t = time.unwrap_or(params.end_time);
    ((t / params.dt) - 1e-9).ceil().max(0.0) as u64
}

/// Default snapshot interval: about 50 snapshots per run.
pub fn default_snapshot_every(steps: u64) -> u64 {
    (steps / 50).max(1)
}

/// Runs `opts.steps` steps, writing `out/snapshots/step_*.{csv,vtk,ply}`, their index,
/// `out/summary.json` and checkpoints. Returns the summary, whose `status` and `failure` say
/// how the run ended: the state went bad, an output could not be written (the summary names
/// the step and the file), or SIGINT/SIGTERM stopped it (after the batch of steps under way,
/// with a checkpoint when checkpoints are on). An error before the first step is returned as
/// an error, without a summary (the caller undoes the start).
pub fn run(backend: &mut dyn Backend, scene: &Scene, opts: &RunOptions) -> anyhow::Result<Summary> {
    let snapshots_dir = opts.out.join(SNAPSHOTS_DIR);
    if opts.writes_files {
        std::fs::create_dir_all(&snapshots_dir).with_context(|| format!("cannot create {}", snapshots_dir.display()))?;
    }
    let params = backend.params().clone();
    let start = backend.steps_done();
    let end = start + opts.steps;
    let bar = if opts.progress && std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        // With adaptive dt the bar counts thousandths of the simulated time.
        let b = indicatif::ProgressBar::new(if opts.end_time.is_some() { 1000 } else { opts.steps });
        b.set_style(
            indicatif::ProgressStyle::with_template("{spinner} {bar:40} {pos}/{len} steps  {per_sec}  eta {eta}  {msg}")
                .expect("valid template"),
        );
        Some(b)
    } else {
        None
    };
    let t0 = Instant::now();
    let resumed = opts.resumed.clone().unwrap_or_default();
    let mut last_snapshot: Option<PathBuf> = resumed.last_snapshot;
    let mut max_speed = resumed.max_speed;
    let mut failure = None;
    let mut snapshots_written = 0u64;
    // Why the last snapshot written is not a good state, where it is not (named with a failure).
    let mut unsound_snapshot: Option<String> = None;
    let checkpoint_path = opts.out.join(CHECKPOINT_FILE);
    let mut last_checkpoint = (opts.resumed.is_some() && checkpoint_path.exists()).then(|| checkpoint_path.clone());
    let mut writer = snapshot_writer(opts, start)?;
    // The probes' time series: a resumed run keeps the lines before its first step.
    // Across ranks every rank holds the same samples and the first alone writes them.
    let mut missing_series = Vec::new();
    let mut probe_writer = match (params.probes.is_empty() || !opts.writes_files, opts.resumed.is_some()) {
        (true, _) => None,
        (false, false) => Some(ProbeWriter::new(&opts.out, &params.probes)),
        (false, true) => {
            let (w, missing) = ProbeWriter::resume(&opts.out, &params.probes, start)?;
            for path in &missing {
                let what = if path.exists() { "is empty" } else { "is missing" };
                eprintln!("warning: {} {what}: its series restarts at step {start}, without the samples before", path.display());
            }
            missing_series = missing;
            Some(w)
        }
    };
    if let (Some(r), true) = (&opts.resumed, opts.writes_files) {
        warn_cut_series(&opts.out, &r.series_lines, &series_lines(&writer, probe_writer.as_ref(), start), &missing_series, start);
    }
    let has_probes = !params.probes.is_empty();
    // The samples the backend took since the last call, added to the series and written; none
    // of a step at or after `bad_step` (the first that went bad: its state is not the flow's).
    let write_probes = |backend: &mut dyn Backend, w: &mut Option<ProbeWriter>, bad_step: Option<u64>| -> anyhow::Result<()> {
        let step = backend.steps_done();
        let Some(w) = w else {
            // A rank that writes nothing still lets go of its copy.
            if has_probes {
                backend.take_probe_samples().with_context(|| format!("step {step}: reading the probes"))?;
            }
            return Ok(());
        };
        let mut samples = backend.take_probe_samples().with_context(|| format!("step {step}: reading the probes"))?;
        samples.retain(|s| bad_step.is_none_or(|bad| s.step < bad));
        w.add(&samples);
        w.write().with_context(|| format!("step {step}: writing the probes' time series"))
    };
    // A snapshot is named the last good state only where it is one: a step's density check
    // reads the state it starts from, so the snapshot before a step stopped for its density
    // already shows that density (and a continuity density driven below zero passes no check).
    let stop = params.stop_levels();
    let mut write_snap = |writer: &mut SnapshotWriter, backend: &mut dyn Backend, last: &mut Option<PathBuf>, max_speed: &mut f64| -> anyhow::Result<WrittenSnapshot> {
        let step = backend.steps_done();
        let (snapshot, path, extremes) = (|| -> anyhow::Result<(Option<Snapshot>, Option<PathBuf>, SnapshotExtremes)> {
            // Across ranks in pieces, every rank writing its own; streamed where the backend
            // can (the GPU): no host copy of every array either way.
            if let Some(written) = writer.write_pieces(backend) {
                let (path, extremes) = written?;
                return Ok((None, Some(path), extremes));
            }
            if let Some(written) = writer.write_streamed(backend) {
                let (path, extremes) = written?;
                return Ok((None, Some(path), extremes));
            }
            let s = backend.snapshot()?;
            let extremes = s.extremes();
            let path = if opts.writes_files { Some(writer.write(&s)?) } else { None };
            Ok((Some(s), path, extremes))
        })()
        .with_context(|| format!("step {step}: writing the snapshot"))?;
        snapshots_written += 1;
        *max_speed = extremes.max_speed;
        let why_bad = extremes.why_bad(stop, params.rest_density).map(|why| format!("the snapshot of step {step} is not a good state: {why}"));
        if why_bad.is_none() && path.is_some() {
            *last = path;
        }
        Ok(WrittenSnapshot { snapshot, extremes, why_bad })
    };
    let surface = SurfaceParameters::for_scene(&params, scene.physics.particle_spacing);
    let mut surface_meshes_written = 0u64;
    let mut write_surface = |backend: &mut dyn Backend, snapshot: Option<Snapshot>| -> anyhow::Result<()> {
        let step = backend.steps_done();
        let s = match snapshot {
            Some(s) => s,
            None => backend.snapshot()?,
        };
        if opts.writes_files {
            write_snapshot_surface(&opts.out, &s, &surface, opts.surface_mesh_format).with_context(|| format!("step {step}: writing the surface mesh"))?;
            surface_meshes_written += 1;
        }
        Ok(())
    };
    if opts.resumed.is_none() {
        let s = write_snap(&mut writer, backend, &mut last_snapshot, &mut max_speed)?;
        unsound_snapshot = s.why_bad;
        if opts.surface_mesh_every > 0 {
            write_surface(backend, s.snapshot)?;
        }
    }
    let mut frames = match &opts.frames {
        Some(f) => Some(FrameRecorder::new(backend, scene, f.options.clone(), f.dir.clone(), f.every.max(1))?),
        None => None,
    };
    if let Some(f) = &mut frames {
        f.capture(backend).with_context(|| format!("step {start}: drawing the first picture"))?;
    }
    // With a snapshot interval in simulated time: the next time a snapshot is due.
    let next_multiple = |interval: f64, time: f64| ((time / interval + 1e-9).floor() + 1.0) * interval;
    let mut next_snapshot_time = opts.snapshot_interval.map(|i| next_multiple(i, backend.time()));
    let mut step = start;
    let mut end = end;
    let mut warned_unconverged = false;
    let mut started = false;
    let mut stopped_by: Option<StopSignal> = None;
    // The health at the last check that found nothing wrong: a failed run reports its maxima up
    // to its first bad step, not those of the steps its batch ran on past it.
    let mut last_good_health = backend.health()?;
    let outcome = (|| -> anyhow::Result<()> {
    while step < end {
        if started {
            // Across ranks every rank stops at the same batch, whichever saw the signal first.
            let signal = signals::requested();
            if backend.any_rank(signal.is_some())? {
                stopped_by = Some(signal.unwrap_or(StopSignal::Interrupt));
                break;
            }
        }
        // The next step at which anything is due (an interval of 0 is never due).
        // (Saturating: a time beyond any step count must not wrap the batch around.)
        let next = |every: u64| if every > 0 { (step / every + 1).saturating_mul(every) } else { end };
        let mut target = [opts.snapshot_every, opts.check_every.max(1), opts.checkpoint_every, opts.surface_mesh_every, frames.as_ref().map_or(0, |f| f.every)]
            .into_iter()
            .map(next)
            .fold(end, u64::min);
        // With adaptive dt, or a snapshot due at a simulated time: the step at which a time is
        // reached is known only as the run gets there.
        let dt = match (opts.end_time.is_some() || next_snapshot_time.is_some(), params.adaptive.is_some()) {
            (false, _) => 0.0,
            (true, true) => backend.dt_stats()?.last,
            (true, false) => params.dt,
        };
        let steps_to = |t: f64, halve: bool| -> u64 {
            let left = t - backend.time();
            match (dt > 0.0, halve) {
                // Before the first adaptive step there is no dt yet: take one.
                (false, _) => 1,
                // Adaptive dt: about half the time left at the current dt, so that the run
                // ends at the first step reaching the time.
                (true, true) => ((0.5 * left / dt).floor() as u64).max(1),
                (true, false) => ((left / dt - 1e-6).ceil() as u64).max(1),
            }
        };
        if let Some(t_end) = opts.end_time {
            target = target.min(step.saturating_add(steps_to(t_end, true)));
        }
        if let Some(t) = next_snapshot_time {
            target = target.min(step.saturating_add(steps_to(t, params.adaptive.is_some())));
        }
        backend.step(target - step)?;
        step = backend.steps_done();
        if !started {
            started = true;
            if let Some(guard) = &opts.start {
                if let Err(e) = guard.commit() {
                    eprintln!("warning: {e:#}");
                }
            }
        }
        // With adaptive dt the time is read from the GPU: once per batch.
        let time = backend.time();
        if opts.end_time.is_some_and(|t_end| time >= t_end) {
            end = step;
        }
        let health = backend.health()?;
        write_probes(backend, &mut probe_writer, health.first_bad_step)?;
        warn_unconverged(&health, &params, &mut warned_unconverged);
        if let Some(b) = &bar {
            match opts.end_time {
                Some(t_end) => b.set_position((1000.0 * time / t_end).min(1000.0) as u64),
                None => b.set_position(step - start),
            }
            b.set_message(format!("t = {time:.3}"));
        }
        if !health.is_ok() {
            let diagnosis = diagnose_failure(backend, scene)?;
            failure = Some(match &unsound_snapshot {
                Some(why) => format!("{diagnosis} ({why})"),
                None => diagnosis,
            });
            break;
        }
        last_good_health = health;
        let time_due = match (next_snapshot_time, opts.snapshot_interval) {
            (Some(t), Some(interval)) => time >= t - 1e-9 * interval,
            _ => false,
        };
        let mut snapshot = None;
        if step == end || time_due || (opts.snapshot_every > 0 && step % opts.snapshot_every == 0) {
            let written = write_snap(&mut writer, backend, &mut last_snapshot, &mut max_speed)?;
            unsound_snapshot = written.why_bad;
            if let Some(interval) = opts.snapshot_interval {
                next_snapshot_time = Some(next_multiple(interval, time));
            }
            // No step's check sees a density below zero: the snapshot that shows one ends the run.
            if written.extremes.non_positive_density > 0 {
                failure = Some(diagnose_non_positive_density(scene, step, time, &written.extremes));
                break;
            }
            snapshot = written.snapshot;
        }
        if opts.surface_mesh_every > 0 && step % opts.surface_mesh_every == 0 {
            write_surface(backend, snapshot)?;
        }
        if let Some(f) = &mut frames {
            if step == end || step % f.every == 0 {
                f.capture(backend).with_context(|| format!("step {step}: drawing a picture"))?;
            }
        }
        if opts.checkpoint_every > 0 && step % opts.checkpoint_every == 0 {
            write_checkpoint(backend, scene, opts, end, last_snapshot.as_deref(), max_speed, series_lines(&writer, probe_writer.as_ref(), step))?;
            last_checkpoint = Some(checkpoint_path.clone());
        }
    }
    if let Some(w) = &probe_writer {
        plot_probes(w).context("plotting the probes' time series")?;
    }
    if stopped_by.is_some() && opts.checkpoint_every > 0 && step % opts.checkpoint_every != 0 {
        // Stopped between checkpoints: one more, so that nothing computed is lost.
        write_checkpoint(backend, scene, opts, end, last_snapshot.as_deref(), max_speed, series_lines(&writer, probe_writer.as_ref(), step))?;
        last_checkpoint = Some(checkpoint_path.clone());
    }
    Ok(())
    })();
    let frames_written = match frames {
        // The pictures under way are finished either way.
        Some(f) => f.finish(),
        None => Ok(0),
    };
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    let error = match (outcome, frames_written.as_ref()) {
        (Err(e), _) if !started => return Err(e),
        (Err(e), _) => Some(e),
        (Ok(()), Err(e)) => Some(anyhow::anyhow!("writing the pictures: {e:#}")),
        (Ok(()), Ok(_)) => None,
    };
    let frames_written = frames_written.unwrap_or(0);
    let wall_seconds = t0.elapsed().as_secs_f64();
    let health = backend.health()?.until_first_bad_step(&last_good_health);
    // The steps computed, for the speed; the steps and time reached, for the record: a failed
    // run ends at its first bad step, not where the GPU's batch ran on to past it.
    let steps_computed = backend.steps_done() - start;
    let (steps, sim_time) = match health.bad_step {
        Some(bad) => (bad.step.saturating_sub(start), bad.measured.time),
        None => (steps_computed, backend.time()),
    };
    let dt_stats = backend.dt_stats()?;
    let (status, failure) = match (stopped_by, &error, failure) {
        (_, Some(e), _) => (RunStatus::Error, Some(format!("{e:#}"))),
        (_, None, Some(f)) => (RunStatus::Failed, Some(f)),
        (Some(signal), None, None) => {
            (RunStatus::Interrupted, Some(format!("interrupted by {} at step {} (t = {})", signal.name(), backend.steps_done(), crate::model::numbers::short_time(backend.time()))))
        }
        (None, None, None) => (RunStatus::Completed, None),
    };
    let summary = Summary {
        scene: scene.name.clone(),
        backend: backend.kind().into(),
        adapter: backend.adapter(),
        driver: backend.driver(),
        fluid_particles: backend.fluid_count(),
        wall_particles: backend.wall_count(),
        steps,
        sim_time,
        dt: params.dt,
        dt_min: dt_stats.min,
        dt_max: dt_stats.max,
        dt_mean: dt_stats.mean,
        wall_seconds,
        particle_steps_per_second: if wall_seconds > 0.0 { (steps_computed as f64 * backend.fluid_count() as f64) / wall_seconds } else { 0.0 },
        max_density_ratio: health.max_density / params.rest_density,
        nan_count: health.bad_counts().0,
        escaped: health.bad_counts().1,
        failure: failure.clone(),
        last_snapshot: last_snapshot.as_ref().map(|p| p.display().to_string()),
        frames: frames_written,
        status,
        last_checkpoint: last_checkpoint.as_ref().map(|p| p.display().to_string()),
        snapshots: snapshots_written,
        surface_meshes: surface_meshes_written,
        // Over the whole run (a resumed run's counts continue from its checkpoint).
        dfsph: health.iterations.map(|it| DfsphSummary::of(&it, backend.steps_done())),
        max_mach: (params.speed_of_sound() > 0.0).then(|| health.max_speed / params.speed_of_sound()),
        warnings: regime_warnings(scene, &health),
        probes: params.probes.probes.iter().map(|p| p.name.clone()).collect(),
        ranks: backend.rank_reports()?.map(|reports| RanksSummary::of(&reports, wall_seconds)),
    };
    if !opts.writes_files {
        return Ok(summary);
    }
    // The run stands (a run of no steps too): its start is no longer undone.
    if let Some(guard) = &opts.start {
        if let Err(e) = guard.commit() {
            eprintln!("warning: {e:#}");
        }
    }
    let summary_path = opts.out.join(SUMMARY_FILE);
    write_summary(&summary_path, &summary).with_context(|| match &failure {
        Some(f) => format!("the run stopped ({f}), and its summary could not be written either"),
        None => "writing the summary".to_string(),
    })?;
    Ok(summary)
}

/// Writes the run's checkpoint (`DIR/checkpoint.wgsph`) at the backend's step.
fn write_checkpoint(backend: &mut dyn Backend, scene: &Scene, opts: &RunOptions, end: u64, last_snapshot: Option<&Path>, max_speed: f64, series_lines: Vec<(String, u64)>) -> anyhow::Result<()> {
    if !opts.writes_files {
        // Across ranks the state streams to the rank that writes it, piece by piece: the
        // other ranks make the same requests and write nothing.
        checkpoint::take_part_in_save(backend)?;
        return Ok(());
    }
    let path = opts.out.join(CHECKPOINT_FILE);
    let step = backend.steps_done();
    let record = run_record(backend, opts, end, last_snapshot, max_speed, series_lines);
    checkpoint::save(backend, &scene.to_toml(), &record, &path).with_context(|| format!("step {step}: writing the checkpoint"))?;
    log::info!("wrote {} at step {step}", path.display());
    Ok(())
}

/// Warns once when a DFSPH solve stopped at its iteration limit above its tolerance: the run
/// goes on, but that step's density (or divergence) error is larger than the scene asks.
fn warn_unconverged(health: &crate::model::state::Health, params: &Params, warned: &mut bool) {
    let (Some(it), Some(d)) = (health.iterations, &params.dfsph) else { return };
    if *warned || it.pressure.unconverged + it.divergence.unconverged == 0 {
        return;
    }
    *warned = true;
    eprintln!(
        "warning: {} step(s) ended their DFSPH solve at the iteration limit above the tolerance (constant density: {} at max_iterations = {}, divergence: {} at max_divergence_iterations = {}); raise the limits or lower dt",
        it.pressure.unconverged + it.divergence.unconverged,
        it.pressure.unconverged,
        d.max_iterations,
        it.divergence.unconverged,
        d.max_divergence_iterations
    );
}

/// The one-line summary printed at the end of a run.
pub fn summary_line(s: &Summary, out: &Path) -> String {
    let dfsph = match &s.dfsph {
        Some(d) => format!(
            ", DFSPH iterations per step {:.2} (max {}) + divergence {:.2} (max {}), unconverged steps {}",
            d.pressure_iterations_mean,
            d.pressure_iterations_max,
            d.divergence_iterations_mean,
            d.divergence_iterations_max,
            d.unconverged_pressure_steps + d.unconverged_divergence_steps
        ),
        None => String::new(),
    };
    format!(
        "{}: {} fluid + {} wall particles, {} steps to t = {:.4} (dt min/max/mean {:.3e}/{:.3e}/{:.3e}) on {} in {:.2} s ({:.3e} particle-steps/s), max rho/rho0 = {:.4}{dfsph}, nan = {}, escaped = {} -> {}",
        s.scene, s.fluid_particles, s.wall_particles, s.steps, s.sim_time, s.dt_min, s.dt_max, s.dt_mean, s.adapter, s.wall_seconds,
        s.particle_steps_per_second, s.max_density_ratio, s.nan_count, s.escaped, out.display()
    )
}

/// The scene of `wgsph run`: the file or built-in scene, with `--set` and `--particles`, and
/// its warnings (an import's notes, the lattice's), which are the run's to print.
pub fn run_scene(args: &RunArgs) -> anyhow::Result<(Scene, Vec<String>)> {
    super::args::load_scene_warning(&args.scene, &args.overrides, args.particles)
}

/// What is odd about a built-in scene, said in one line when it runs.
fn scene_note(name: &str) -> Option<&'static str> {
    (name == "seed").then_some(
        "note: `seed` is the seed report's scene as published: its fluid is so soft (k = 2 Pa, sound at 4.5 cm/s) that it collapses into dense strands on the floor (max rho/rho0 near 30); `wgsph run dam_break` shows water",
    )
}

/// `wgsph run` (without `--resume`): a new run.
pub fn cmd_run(args: &RunArgs, ranks: Option<&Ranks>) -> anyhow::Result<i32> {
    if let Some(t) = args.time {
        if !(t.is_finite() && t >= 0.0) {
            return Err(InputError(format!("--time is {t}; must be a finite number >= 0")).into());
        }
    }
    // The GPU step's tuning flags change nothing on the CPU path: refused where the CPU was
    // asked for, a note where the automatic choice fell on it.
    let gpu_flags = args.gpu.given();
    if args.backend == BackendArg::Cpu && !gpu_flags.is_empty() {
        let (tune, they, them) = if gpu_flags.len() == 1 { ("tunes", "it", "it") } else { ("tune", "they", "them") };
        return Err(InputError(format!(
            "{} {tune} the GPU step, and --backend cpu runs the CPU path, where {they} would change nothing: leave {them} out, or run with --backend gpu",
            gpu_flags.join(", ")
        ))
        .into());
    }
    // Pictures are drawn only into --frames: their look without it would change nothing.
    let picture_flags = args.picture.given();
    if args.frames.is_none() && !picture_flags.is_empty() {
        return Err(InputError(format!("{} set how the pictures look, and this run draws none: add --frames DIR, or leave {} out", picture_flags.join(", "), if picture_flags.len() == 1 { "it" } else { "them" })).into());
    }
    if let Some(f) = args.formats.iter().enumerate().find(|(i, f)| args.formats[..*i].contains(f)).map(|(_, f)| f) {
        return Err(InputError(format!("--format {} is given twice; give each snapshot format once", f.extension())).into());
    }
    if let (Some(f), 0) = (args.surface_mesh_format, args.surface_mesh_every) {
        return Err(InputError(format!("--surface-mesh-format {} sets the surface meshes' format, and this run writes none: add --surface-mesh-every K, or leave it out", f.extension())).into());
    }
    // The GPU computes in f32 whatever the CPU path's float type.
    if let (BackendArg::Gpu, Some(PrecisionArg::F64)) = (args.backend, args.precision) {
        return Err(InputError("--precision f64 sets the CPU path's float type, and --backend gpu computes in f32: leave it out, or run with --backend cpu".into()).into());
    }
    let writes_files = super::ranks::writes_files(ranks);
    let quiet = args.quiet || !writes_files;
    let across = ranks.map_or(1, |r| r.comm.size());
    if args.full_exchange && (across < 2 || args.backend == BackendArg::Cpu) {
        let why = if across < 2 { "one process has nothing to exchange (run it under mpirun with wgsph-mpi and -np 2 or more)".to_string() } else { format!("--backend cpu exchanges every particle at every step already ({across} ranks)") };
        return Err(InputError(format!("--full-exchange chooses how GPU ranks exchange their particles, and {why}: leave it out")).into());
    }
    if let Some(r) = ranks.filter(|r| r.comm.size() > 1) {
        if args.frames.is_some() || args.surface_mesh_every > 0 {
            return Err(InputError(format!(
                "--frames and --surface-mesh-every are not supported across ranks yet ({} ranks): run them on one rank (from a checkpoint: `wgsph run --resume DIR` without mpirun)",
                r.comm.size()
            ))
            .into());
        }
    }
    let (scene, warnings) = run_scene(args)?;
    if !quiet {
        super::args::print_warnings(&warnings);
    }
    let params = scene.params();
    args.gpu.check_scene(&params)?;
    let steps = args.steps.unwrap_or_else(|| steps_for_time(&params, args.time));
    if args.checkpoint_every > 0 && params.rebuild_every > 1 {
        return Err(InputError(format!(
            "--checkpoint-every {} needs time.neighbour_rebuild_every = 1 (the scene has {}): between rebuilds the state depends on the grid of the last rebuild, which a checkpoint does not hold",
            args.checkpoint_every, params.rebuild_every
        ))
        .into());
    }
    // Every output location is checked before anything is written or removed.
    let out = args.out.clone().unwrap_or_else(|| numbered_run_dir(Path::new("out"), &scene.name));
    let scene_file = Scene::builtin(&args.scene).is_none().then(|| PathBuf::from(&args.scene));
    let inputs: Vec<&Path> = scene_file.iter().map(PathBuf::as_path).collect();
    // Across ranks rank 0 alone checks and prepares the outputs.
    let writes = RunWrites::of_run(&args.formats, (args.surface_mesh_every > 0).then_some(args.surface_mesh_format.unwrap_or_default()), &params.probes);
    let outputs = if writes_files { Some(RunOutputs::check(&out, args.frames.as_deref(), args.overwrite, args.out.is_none(), &inputs, writes)?) } else { None };
    for (dir, names) in outputs.iter().flat_map(|o| o.kept()) {
        eprintln!("note: --overwrite keeps {} in {}: no wgsph run wrote it", names.join(", "), dir.display());
    }
    if let (Some(note), false) = (scene_note(&args.scene), quiet) {
        println!("{note}");
    }
    signals::install();
    let mut choice = args.backend_choice();
    choice.ranks = ranks.cloned();
    let mut sim = open(&scene, &choice)?;
    if !quiet {
        println!("backend: {}", sim.backend_reason());
    }
    // What the automatic choice leaves unused, said once (by the first rank across ranks).
    if sim.kind() == "gpu" && args.precision == Some(PrecisionArg::F64) && writes_files {
        eprintln!("note: --precision f64 not used: the automatic choice is the GPU, which computes in f32 (--backend cpu runs the CPU path in f64)");
    }
    // CPU ranks exchange every particle at every step: --full-exchange steers GPU ranks only.
    let unused: Vec<&str> = gpu_flags.iter().copied().chain(args.full_exchange.then_some("--full-exchange")).collect();
    if sim.kind() == "cpu" && !unused.is_empty() && writes_files {
        eprintln!("note: {} not used: the automatic choice is the CPU path (--backend gpu runs the GPU step)", unused.join(", "));
    }
    // From here on the directories are changed; a failure before the first step undoes it.
    let start = match outputs {
        Some(outputs) => {
            let start = outputs.prepare()?;
            write_scene_copy(&out, &scene)?;
            Some(start)
        }
        None => None,
    };
    // With adaptive dt a run to a time has no step count known in advance.
    let end_time = (params.adaptive.is_some() && args.steps.is_none()).then(|| args.time.unwrap_or(params.end_time));
    let (snapshot_every, snapshot_interval) = match args.snapshot_every {
        None => (default_snapshot_every(steps), None),
        Some(SnapshotInterval::Steps(k)) => (k, None),
        Some(SnapshotInterval::Seconds(t)) => (0, Some(t)),
    };
    let opts = RunOptions {
        steps: if end_time.is_some() { u64::MAX / 4 } else { steps },
        out: out.clone(),
        snapshot_every,
        snapshot_interval,
        check_every: args.check_every,
        progress: !quiet,
        formats: args.formats.clone(),
        checkpoint_every: args.checkpoint_every,
        resumed: None,
        frames: args.frames.as_ref().map(|dir| FramesSpec {
            dir: dir.clone(),
            every: args.frame_every.unwrap_or((steps / 100).max(1)),
            options: args.picture.options(),
        }),
        end_time,
        surface_mesh_every: args.surface_mesh_every,
        surface_mesh_format: args.surface_mesh_format.unwrap_or_default(),
        start,
        writes_files,
    };
    let summary = run(sim.backend(), &scene, &opts)?;
    if !writes_files {
        return Ok(exit_code_of(&summary));
    }
    let code = report_run(&summary, &out, args.quiet)?;
    if !args.quiet {
        print_outputs(&summary, &out, args.frames.as_deref(), &args.formats, args.surface_mesh_format.unwrap_or_default());
    }
    Ok(code)
}

/// A short account of what a run wrote where.
pub fn print_outputs(s: &Summary, out: &Path, frames: Option<&Path>, formats: &[SnapshotFormat], mesh_format: MeshFormat) {
    let names: Vec<&str> = formats.iter().map(|f| f.extension()).collect();
    println!("wrote {}:", out.display());
    let plural = if s.snapshots == 1 { "" } else { "s" };
    println!("  snapshots/     {} snapshot{plural} ({}); the step and time of each in snapshots/index.csv", s.snapshots, names.join(", "));
    if let Some(dir) = frames {
        let shown = match s.frames {
            0 => String::new(),
            1 => format!(": {}", crate::io::rundir::frame_file_name(0)),
            n => format!(": {} to {}", crate::io::rundir::frame_file_name(0), crate::io::rundir::frame_file_name(n - 1)),
        };
        let dir = match dir.strip_prefix(out) {
            Ok(inside) => format!("{}/", inside.display()),
            Err(_) => dir.display().to_string(),
        };
        println!("  {dir:<13}  {} picture{}{shown}", s.frames, if s.frames == 1 { "" } else { "s" });
    }
    if s.surface_meshes > 0 {
        let plural = if s.surface_meshes == 1 { "" } else { "es" };
        println!("  surface/       {} surface mesh{plural} (step_NNNNNN.{})", s.surface_meshes, mesh_format.extension());
    }
    if s.last_checkpoint.is_some() {
        println!("  checkpoint.wgsph  the state to continue from with `wgsph run --resume {}`", out.display());
    }
    if !s.probes.is_empty() {
        // What is there: a series needs a sample, a plot two.
        let count = |ext: &str| s.probes.iter().filter(|p| out.join(PROBES_DIR).join(format!("{p}.{ext}")).is_file()).count();
        let (series, plots) = (count("csv"), count("png"));
        let plots = match plots {
            0 => "no plots (a plot needs two samples)".to_string(),
            n if n == series => "their plots (NAME.png)".to_string(),
            n => format!("{n} plots (NAME.png; a plot needs two samples)"),
        };
        println!("  probes/        {series} probe time series (NAME.csv) and {plots}: {}", s.probes.join(", "));
    }
    println!("  summary.json   what the run did and how it ended");
    println!("  scene.toml     the scene as run (`wgsph run {}` runs it again)", out.join("scene.toml").display());
}

/// The exit code of a run that ended as `summary` says (see [`report_run`]).
pub fn exit_code_of(summary: &Summary) -> i32 {
    match summary.status {
        RunStatus::Completed => 0,
        RunStatus::Interrupted => signals::requested().unwrap_or(StopSignal::Interrupt).exit_code(),
        RunStatus::Failed | RunStatus::Error => 1,
    }
}

/// Prints the end of a run (the summary line unless quiet; how it stopped, if it did) and
/// returns its exit code: 0 completed, 1 the state went bad or an output could not be written,
/// 130 / 143 interrupted by SIGINT / SIGTERM.
pub fn report_run(summary: &Summary, out: &std::path::Path, quiet: bool) -> anyhow::Result<i32> {
    if !quiet {
        println!("{}", summary_line(summary, out));
        for w in &summary.warnings {
            eprintln!("warning: {w}");
        }
    }
    let summary_path = out.join(SUMMARY_FILE);
    match summary.status {
        RunStatus::Completed => Ok(0),
        RunStatus::Interrupted => {
            eprintln!("{}; the summary is {}", summary.failure.as_deref().unwrap_or("interrupted"), summary_path.display());
            match &summary.last_checkpoint {
                Some(c) => eprintln!("to continue from the checkpoint {c}: wgsph run --resume {}", out.display()),
                None => eprintln!("no checkpoint was written, so the run cannot be continued (--checkpoint-every K writes them)"),
            }
            Ok(signals::requested().unwrap_or(StopSignal::Interrupt).exit_code())
        }
        RunStatus::Failed | RunStatus::Error => {
            let f = summary.failure.as_deref().unwrap_or("an unknown failure");
            if summary.status == RunStatus::Failed {
                eprintln!("error: the run stopped at {f}");
            } else {
                eprintln!("error: the run stopped: {f}");
            }
            if let Some(s) = &summary.last_snapshot {
                eprintln!("the last good snapshot is {s}; the summary is {}", summary_path.display());
            }
            Ok(1)
        }
    }
}

/// A snapshot the run wrote: the state (where the backend read it whole), what it shows of
/// the state's health, and why it is not a good state to name as the last one (None: it is).
struct WrittenSnapshot {
    snapshot: Option<Snapshot>,
    extremes: SnapshotExtremes,
    why_bad: Option<String>,
}

/// The snapshot writer of a run; a resumed run keeps the series index up to its first step.
fn snapshot_writer(opts: &RunOptions, start_step: u64) -> anyhow::Result<SnapshotWriter> {
    if opts.resumed.is_some() {
        SnapshotWriter::resume(&opts.out, &opts.formats, start_step)
    } else {
        Ok(SnapshotWriter::new(&opts.out, &opts.formats))
    }
}

/// The settings of the run, as a checkpoint records them.
pub fn run_record(backend: &dyn Backend, opts: &RunOptions, end_step: u64, last_snapshot: Option<&Path>, max_speed: f64, series_lines: Vec<(String, u64)>) -> RunRecord {
    RunRecord {
        end_step,
        snapshot_every: opts.snapshot_every,
        snapshot_interval: opts.snapshot_interval,
        check_every: opts.check_every,
        checkpoint_every: opts.checkpoint_every,
        formats: opts.formats.clone(),
        adapter: backend.adapter(),
        last_snapshot: last_snapshot.map(|p| p.display().to_string()),
        max_speed,
        end_time: opts.end_time,
        surface_mesh_every: opts.surface_mesh_every,
        surface_mesh_format: opts.surface_mesh_format,
        series_lines,
        run_id: opts.writes_files.then(|| run_id(&opts.out)).flatten(),
    }
}

/// The lines of the snapshot index and of the probes' series that a run resumed at `step`
/// keeps (a checkpoint's record of them).
fn series_lines(snapshots: &SnapshotWriter, probes: Option<&ProbeWriter>, step: u64) -> Vec<(String, u64)> {
    let mut lines = snapshots.lines_up_to(step);
    lines.extend(probes.map(|p| p.lines_before(step)).unwrap_or_default());
    lines
}

/// Warns of each series file that holds fewer lines than the checkpoint recorded (cut or
/// replaced since): the resumed run goes on from what is there, so the series has a gap.
/// `missing` files were named already.
fn warn_cut_series(out: &Path, recorded: &[(String, u64)], found: &[(String, u64)], missing: &[PathBuf], start: u64) {
    for (name, had) in recorded {
        let Some((_, has)) = found.iter().find(|(n, _)| n == name) else { continue };
        if has >= had || missing.iter().any(|m| m.ends_with(name)) {
            continue;
        }
        let what = if name.starts_with(SNAPSHOTS_DIR) { "snapshots up to" } else { "samples before" };
        if !out.join(name).exists() {
            eprintln!(
                "warning: {} is missing, where the run had written {had} {what} step {start} when it saved its checkpoint: the resumed run starts it anew, without them",
                out.join(name).display()
            );
            continue;
        }
        eprintln!(
            "warning: {} holds {has} {what} step {start}, where the run had written {had} when it saved its checkpoint: the file was cut or replaced since, and the resumed run does not write the missing lines again",
            out.join(name).display()
        );
    }
}
