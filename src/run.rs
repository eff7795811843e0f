//! The `wgsph run` loop: steps a backend, writes snapshots and the summary, and stops with a
//! diagnosis when the state goes bad.

use crate::export::SnapshotFormat;
use crate::output::{write_summary, Summary};
use crate::render::frames::FrameRecorder;
use crate::scene::{Params, Scene};
use crate::sim::{Backend, Health, Snapshot};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Pictures to write during a run.
#[derive(Clone, Debug)]
pub struct FramesSpec {
    pub dir: PathBuf,
    /// A picture every this many steps (the first of the run and the last too).
    pub every: u64,
    pub options: crate::render::RenderOptions,
}

pub struct RunOptions {
    pub steps: u64,
    pub out: PathBuf,
    /// Write a snapshot every this many steps (0: only the first and the last).
    pub snapshot_every: u64,
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
    pub surface_mesh_format: crate::surface::MeshFormat,
}

/// What a resumed run takes over from the run that wrote its checkpoint.
#[derive(Clone, Debug, Default)]
pub struct ResumedRun {
    pub last_snapshot: Option<PathBuf>,
    pub max_speed: f64,
}

impl Default for RunOptions {
    fn default() -> Self {
        RunOptions {
            steps: 0,
            out: PathBuf::from("out"),
            snapshot_every: 0,
            check_every: 50,
            progress: false,
            formats: vec![SnapshotFormat::Csv],
            checkpoint_every: 0,
            resumed: None,
            frames: None,
            end_time: None,
            surface_mesh_every: 0,
            surface_mesh_format: crate::surface::MeshFormat::Obj,
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

/// Why a run went bad, with the likely cause in terms of the CFL condition.
pub fn diagnose(params: &Params, health: &Health, max_speed: f64) -> String {
    diagnose_at(params, health, max_speed, health.first_bad_step.unwrap_or(0) as f64 * params.dt)
}

/// `diagnose` for a run at simulated time `time` whose last step was `params.dt` (adaptive dt).
pub fn diagnose_at(params: &Params, health: &Health, max_speed: f64, time: f64) -> String {
    let step = health.first_bad_step.unwrap_or(0);
    let c0 = params.speed_of_sound();
    let cfl = params.dt * (c0 + max_speed) / params.h;
    let g = params.gravity.iter().map(|v| v * v).sum::<f64>().sqrt();
    let mut what = Vec::new();
    if health.non_finite > 0 {
        what.push(format!("{} particles became NaN or infinite", health.non_finite));
    }
    if health.escaped > 0 {
        what.push(format!("{} particles left the domain", health.escaped));
    }
    let mut msg = format!("step {step} (t = {time:.6}): {}.", what.join(" and "));
    msg += &format!(
        " Likely cause: the time step is too large for the stiffness: the CFL number dt (c0 + |v|max) / h = {:.3} \
         (dt = {}, c0 = {:.4}, |v|max = {:.4}, h = {}); explicit WCSPH is stable below about 0.4",
        cfl, params.dt, c0, max_speed, params.h
    );
    if g > 0.0 {
        msg += &format!(", and the force condition dt sqrt(|g|/h) = {:.3} should stay below about 0.25", params.dt * (g / params.h).sqrt());
    }
    if let Some(a) = params.adaptive {
        msg += &format!(". With adaptive dt (dt_min = {}, dt_max = {}): lower time.cfl_number or time.force_number, or dt_min", a.dt_min, a.dt_max);
    }
    msg += ". Lower dt or the stiffness, or check the scene's boundaries.";
    msg
}

/// Runs `opts.steps` steps, writing `out/snapshots/step_*.{csv,vtk,ply}`, `out/summary.json` and
/// checkpoints.
/// Returns the summary; `summary.failure` is set when the state went bad.
pub fn run(backend: &mut dyn Backend, scene: &Scene, opts: &RunOptions) -> anyhow::Result<Summary> {
    std::fs::create_dir_all(opts.out.join("snapshots"))?;
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
    let mut writer = crate::checkpoint::snapshot_writer(opts, start)?;
    let mut write_snap = |backend: &mut dyn Backend, last: &mut Option<PathBuf>, max_speed: &mut f64| -> anyhow::Result<Option<Snapshot>> {
        // Streamed where the backend can (the GPU): no host copy of every array.
        if let Some(written) = writer.write_streamed(backend) {
            (*last, *max_speed) = written.map(|(path, speed)| (Some(path), speed))?;
            return Ok(None);
        }
        let s = backend.snapshot()?;
        *max_speed = s.max_speed();
        *last = Some(writer.write(&s)?);
        Ok(Some(s))
    };
    let surface = crate::surface::SurfaceParameters::for_scene(&params, scene.physics.particle_spacing);
    let write_surface = |backend: &mut dyn Backend, snapshot: Option<Snapshot>| -> anyhow::Result<()> {
        let s = match snapshot {
            Some(s) => s,
            None => backend.snapshot()?,
        };
        crate::surface::write_snapshot_surface(&opts.out, &s, &surface, opts.surface_mesh_format)?;
        Ok(())
    };
    if opts.resumed.is_none() {
        let s = write_snap(backend, &mut last_snapshot, &mut max_speed)?;
        if opts.surface_mesh_every > 0 {
            write_surface(backend, s)?;
        }
    }
    let mut frames = match &opts.frames {
        Some(f) => Some(FrameRecorder::new(backend, scene, f.options.clone(), f.dir.clone(), f.every.max(1))?),
        None => None,
    };
    if let Some(f) = &mut frames {
        f.capture(backend)?;
    }
    let mut step = start;
    let mut end = end;
    while step < end {
        // The next step at which anything is due (an interval of 0 is never due).
        let next = |every: u64| if every > 0 { (step / every + 1) * every } else { end };
        let mut target = [opts.snapshot_every, opts.check_every.max(1), opts.checkpoint_every, opts.surface_mesh_every, frames.as_ref().map_or(0, |f| f.every)]
            .into_iter()
            .map(next)
            .fold(end, u64::min);
        if let Some(t_end) = opts.end_time {
            // Adaptive dt: steps of about half the time left, at the current dt, so that the
            // run ends at the first step reaching t_end.
            let dt = backend.dt_stats()?.last;
            let left = t_end - backend.time();
            // Before the first step there is no dt yet: take one.
            let chunk = if dt > 0.0 { ((0.5 * left / dt).floor() as u64).max(1) } else { 1 };
            target = target.min(step + chunk);
        }
        backend.step(target - step)?;
        step = backend.steps_done();
        // With adaptive dt the time is read from the GPU: once per batch.
        let time = backend.time();
        if opts.end_time.is_some_and(|t_end| time >= t_end) {
            end = step;
        }
        let health = backend.health()?;
        if let Some(b) = &bar {
            match opts.end_time {
                Some(t_end) => b.set_position((1000.0 * time / t_end).min(1000.0) as u64),
                None => b.set_position(step - start),
            }
            b.set_message(format!("t = {time:.3}"));
        }
        if !health.is_ok() {
            failure = Some(if params.adaptive.is_some() {
                let last = Params { dt: backend.dt_stats()?.last, ..params.clone() };
                diagnose_at(&last, &health, max_speed, time)
            } else {
                diagnose(&params, &health, max_speed)
            });
            break;
        }
        let mut snapshot = None;
        if step == end || (opts.snapshot_every > 0 && step % opts.snapshot_every == 0) {
            snapshot = write_snap(backend, &mut last_snapshot, &mut max_speed)?;
        }
        if opts.surface_mesh_every > 0 && step % opts.surface_mesh_every == 0 {
            write_surface(backend, snapshot)?;
        }
        if let Some(f) = &mut frames {
            if step == end || step % f.every == 0 {
                f.capture(backend)?;
            }
        }
        if opts.checkpoint_every > 0 && step % opts.checkpoint_every == 0 {
            let path = opts.out.join(crate::checkpoint::CHECKPOINT_FILE);
            crate::checkpoint::save(backend, scene, opts, end, last_snapshot.as_deref(), max_speed, &path)?;
            log::info!("wrote {} at step {step}", path.display());
        }
    }
    let frames_written = match frames {
        Some(f) => f.finish()?,
        None => 0,
    };
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    let wall_seconds = t0.elapsed().as_secs_f64();
    let health = backend.health()?;
    let steps = backend.steps_done() - start;
    let dt_stats = backend.dt_stats()?;
    let summary = Summary {
        scene: scene.name.clone(),
        backend: backend.kind().into(),
        adapter: backend.adapter(),
        fluid_particles: backend.fluid_count(),
        wall_particles: backend.wall_count(),
        steps,
        sim_time: backend.time(),
        dt: params.dt,
        dt_min: dt_stats.min,
        dt_max: dt_stats.max,
        dt_mean: dt_stats.mean,
        wall_seconds,
        particle_steps_per_second: if wall_seconds > 0.0 { (steps as f64 * backend.fluid_count() as f64) / wall_seconds } else { 0.0 },
        max_density_ratio: health.max_density / params.rest_density,
        nan_count: health.non_finite,
        escaped: health.escaped,
        failure: failure.clone(),
        last_snapshot: last_snapshot.as_ref().map(|p| p.display().to_string()),
        frames: frames_written,
    };
    write_summary(&opts.out.join("summary.json"), &summary)?;
    Ok(summary)
}

/// The one-line summary printed at the end of a run.
pub fn summary_line(s: &Summary, out: &Path) -> String {
    format!(
        "{}: {} fluid + {} wall particles, {} steps to t = {:.4} (dt min/max/mean {:.3e}/{:.3e}/{:.3e}) on {} in {:.2} s ({:.3e} particle-steps/s), max rho/rho0 = {:.4}, nan = {}, escaped = {} -> {}",
        s.scene, s.fluid_particles, s.wall_particles, s.steps, s.sim_time, s.dt_min, s.dt_max, s.dt_mean, s.adapter, s.wall_seconds,
        s.particle_steps_per_second, s.max_density_ratio, s.nan_count, s.escaped, out.display()
    )
}
