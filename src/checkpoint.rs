//! Checkpoints: the full state of a run in one file, `DIR/checkpoint.wgsph`, from which
//! `wgsph run --resume DIR` continues bit for bit.
//!
//! Layout (little-endian): the magic `WGSPHCKP`, the format version (u32), the length (u16) and
//! text of the wgsph version that wrote it, the payload length (u64), the payload's CRC-32
//! (u32), then the payload: [`Checkpoint`] serialised with postcard. A checkpoint from another
//! format or wgsph version, or one whose checksum or length does not match, is refused. The file
//! is written beside its target and renamed over it, so the previous checkpoint stays intact
//! until the new one is complete. The payload is written as it is serialised and its length and
//! checksum filled in at the end, so a backend can stream its state in pieces
//! ([`Backend::write_state_streamed`]); reading streams the file too (a checksum pass, then
//! decoding), holding only the decoded state.

use crate::cli::{InputError, RunArgs};
use crate::cpu::CpuSolver;
use crate::gpu::{GpuContext, GpuSolver};
use crate::sim::Backend;
use crate::export::{SnapshotFormat, SnapshotWriter};
use crate::output::AtomicFile;
use crate::run::{run, ResumedRun, RunOptions};
use crate::scene::{Scene, SceneOrigin};
use crate::sim::BackendState;
use anyhow::Context;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The checkpoint file in a run directory.
pub const CHECKPOINT_FILE: &str = "checkpoint.wgsph";
const MAGIC: &[u8; 8] = b"WGSPHCKP";
/// Bumped whenever the payload's layout or meaning changes.
pub const FORMAT_VERSION: u32 = 2;
/// The wgsph version written into (and required of) checkpoints.
pub const WGSPH_VERSION: &str = env!("CARGO_PKG_VERSION");

/// What a run needs to continue: the scene, how the run was set up, and the backend's state.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Checkpoint {
    /// The resolved scene as TOML (what `DIR/scene.toml` holds).
    pub scene_toml: String,
    pub run: RunRecord,
    pub state: BackendState,
}

/// The settings of the run that wrote a checkpoint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunRecord {
    /// The step the run was heading to.
    pub end_step: u64,
    pub snapshot_every: u64,
    pub check_every: u64,
    pub checkpoint_every: u64,
    pub formats: Vec<SnapshotFormat>,
    /// The adapter (or CPU float type) that computed the state.
    pub adapter: String,
    pub last_snapshot: Option<String>,
    /// The largest speed in the last snapshot (for the diagnosis of a later blow-up).
    pub max_speed: f64,
    /// With adaptive dt, the simulated time the run was heading to.
    pub end_time: Option<f64>,
    pub surface_mesh_every: u64,
    pub surface_mesh_format: crate::surface::MeshFormat,
}

/// A checkpoint that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    #[error("{path}: cannot read the checkpoint: {source}")]
    Io { path: String, source: std::io::Error },
    #[error("{0}: not a wgsph checkpoint (wrong magic bytes)")]
    NotACheckpoint(String),
    #[error("{path}: written by wgsph {version} (checkpoint format {format}); this is wgsph {WGSPH_VERSION} (format {FORMAT_VERSION}), which only resumes its own checkpoints")]
    OtherVersion { path: String, version: String, format: u32 },
    #[error("{path}: the checkpoint is corrupt ({why}); it cannot be resumed")]
    Corrupt { path: String, why: String },
}

/// Writes a checkpoint atomically.
pub fn write(path: &Path, c: &Checkpoint) -> anyhow::Result<()> {
    write_with_state(path, &c.scene_toml, &c.run, |w| {
        postcard::to_io(&c.state, w).context("cannot serialise the checkpoint")?;
        Ok(())
    })
}

/// Writes a checkpoint atomically whose state `write_state` serialises (with postcard, as
/// [`BackendState`]) into the writer it is given, in pieces if it likes: the payload goes to
/// the file as it comes, and its length and checksum are filled into the header at the end.
pub fn write_with_state(
    path: &Path,
    scene_toml: &str,
    run: &RunRecord,
    write_state: impl FnOnce(&mut dyn std::io::Write) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    use std::io::{Seek, SeekFrom, Write};
    let mut file = AtomicFile::create(path)?;
    let cannot = || format!("cannot write {}", path.display());
    file.write_all(MAGIC).with_context(cannot)?;
    file.write_all(&FORMAT_VERSION.to_le_bytes()).with_context(cannot)?;
    file.write_all(&(WGSPH_VERSION.len() as u16).to_le_bytes()).with_context(cannot)?;
    file.write_all(WGSPH_VERSION.as_bytes()).with_context(cannot)?;
    let length_at = file.stream_position().with_context(cannot)?;
    file.write_all(&[0; 12]).with_context(cannot)?;
    let mut payload = Payload { out: &mut file, crc: crc32fast::Hasher::new(), len: 0, failure: None };
    // Checkpoint's fields in order: postcard writes a struct as its fields one after the other.
    let written = match postcard::to_io(&(scene_toml, run), &mut payload) {
        Ok(_) => write_state(&mut payload),
        Err(e) => Err(anyhow::Error::from(e).context("cannot serialise the checkpoint")),
    };
    if let Some(e) = payload.failure.take() {
        return Err(e).with_context(cannot);
    }
    written?;
    let (len, crc) = (payload.len, payload.crc.finalize());
    file.seek(SeekFrom::Start(length_at)).with_context(cannot)?;
    file.write_all(&len.to_le_bytes()).with_context(cannot)?;
    file.write_all(&crc.to_le_bytes()).with_context(cannot)?;
    file.commit()
}

/// The payload on its way to the file: counted and checksummed as it is written.
struct Payload<'a> {
    out: &'a mut AtomicFile,
    crc: crc32fast::Hasher,
    len: u64,
    /// The first write error (postcard reports only that the output failed).
    failure: Option<std::io::Error>,
}

impl std::io::Write for Payload<'_> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        match self.out.write(buf) {
            Ok(n) => {
                self.crc.update(&buf[..n]);
                self.len += n as u64;
                Ok(n)
            }
            Err(e) => {
                let again = std::io::Error::new(e.kind(), e.to_string());
                self.failure.get_or_insert(e);
                Err(again)
            }
        }
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }
}

/// Reads and checks a checkpoint, streaming the file: one pass checks the payload's length
/// and checksum, a second decodes it, so the host never holds the file's bytes besides the
/// state decoded from them.
pub fn read(path: &Path) -> Result<Checkpoint, CheckpointError> {
    use std::io::{BufReader, Read, Seek, SeekFrom};
    let p = path.display().to_string();
    let io = |source| CheckpointError::Io { path: p.clone(), source };
    let corrupt = |why: &str| CheckpointError::Corrupt { path: p.clone(), why: why.into() };
    let file = std::fs::File::open(path).map_err(io)?;
    let file_len = file.metadata().map_err(io)?.len();
    let mut r = BufReader::with_capacity(1 << 20, file);
    // Reads exactly n bytes of the header; None when the file ends first.
    let mut take = |n: usize| -> Result<Option<Vec<u8>>, CheckpointError> {
        let mut bytes = vec![0; n];
        match r.read_exact(&mut bytes) {
            Ok(()) => Ok(Some(bytes)),
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => Ok(None),
            Err(e) => Err(io(e)),
        }
    };
    if take(8)?.as_deref() != Some(MAGIC.as_slice()) {
        return Err(CheckpointError::NotACheckpoint(p));
    }
    let truncated = || corrupt("the file is truncated");
    let format = u32::from_le_bytes(take(4)?.ok_or_else(truncated)?.try_into().expect("4 bytes"));
    let len = u16::from_le_bytes(take(2)?.ok_or_else(truncated)?.try_into().expect("2 bytes")) as usize;
    let version = String::from_utf8_lossy(&take(len)?.ok_or_else(truncated)?).into_owned();
    if format != FORMAT_VERSION || version != WGSPH_VERSION {
        return Err(CheckpointError::OtherVersion { path: p, version, format });
    }
    let payload_len = u64::from_le_bytes(take(8)?.ok_or_else(truncated)?.try_into().expect("8 bytes"));
    let crc = u32::from_le_bytes(take(4)?.ok_or_else(truncated)?.try_into().expect("4 bytes"));
    let payload_at = (8 + 4 + 2 + len + 8 + 4) as u64;
    let have = file_len - payload_at;
    if have != payload_len {
        return Err(corrupt(&format!("the payload has {have} bytes, the header says {payload_len}")));
    }
    let mut hasher = crc32fast::Hasher::new();
    let mut piece = vec![0u8; 1 << 20];
    loop {
        let n = r.read(&mut piece).map_err(io)?;
        if n == 0 {
            break;
        }
        hasher.update(&piece[..n]);
    }
    if hasher.finalize() != crc {
        return Err(corrupt("checksum mismatch"));
    }
    r.seek(SeekFrom::Start(payload_at)).map_err(io)?;
    // Room for the payload's strings (the scene's TOML and the run's names), which postcard
    // decodes through this buffer; the particle arrays go straight into the state.
    let mut scratch = vec![0u8; (payload_len as usize).min(16 << 20)];
    postcard::from_io((r.take(payload_len), scratch.as_mut_slice()))
        .map(|(c, _)| c)
        .map_err(|e| corrupt(&format!("cannot decode the payload: {e}")))
}

/// `wgsph run --resume DIR`: continues the run in DIR from its checkpoint, to the end it was
/// heading to, or for `--steps N` / `--time T` more.
pub fn resume_run(dir: &Path, args: &RunArgs) -> anyhow::Result<i32> {
    let path = dir.join(CHECKPOINT_FILE);
    if !path.exists() {
        return Err(InputError(format!(
            "--resume {}: there is no checkpoint {} (write one with --checkpoint-every K)",
            dir.display(),
            path.display()
        ))
        .into());
    }
    let c = read(&path).map_err(|e| InputError(format!("--resume: {e}")))?;
    let scene = Scene::from_toml_str(&c.scene_toml, &SceneOrigin::File(path.clone()))?;
    let params = scene.params();
    let step = c.state.step;
    let end = match (args.steps, args.time) {
        (Some(n), _) => step + n,
        (None, Some(t)) => step + crate::run::steps_for_time(&params, Some(t)),
        (None, None) => c.run.end_step,
    };
    if end <= step {
        return Err(InputError(format!(
            "--resume {}: the run already reached step {step} (its end); give --steps N or --time T to continue further",
            dir.display()
        ))
        .into());
    }
    let mut backend = make_backend_of_kind(&scene, &c.state.kind)?;
    // The CPU path gives the same bits with any number of threads; a GPU may not on another adapter.
    if c.state.kind == "gpu" && backend.adapter() != c.run.adapter {
        eprintln!(
            "warning: the checkpoint was computed on {}; this run uses {}: it continues the run, but not bit for bit as the original adapter would",
            c.run.adapter,
            backend.adapter()
        );
    }
    let summary = resume_with(backend.as_mut(), dir, &c, end, !args.quiet)?;
    crate::cli::report_run(&summary, dir, args.quiet)
}

/// Restores `c` into `backend` (a fresh one of the kind that saved it) and runs on to step
/// `end`, writing into `dir` with the settings of the interrupted run.
pub fn resume_with(backend: &mut dyn Backend, dir: &Path, c: &Checkpoint, end: u64, progress: bool) -> anyhow::Result<crate::output::Summary> {
    let step = c.state.step;
    backend.restore_state(&c.state).with_context(|| format!("cannot restore the checkpoint in {}", dir.display()))?;
    log::info!("resuming {} at step {step} towards step {end}", dir.display());
    let opts = RunOptions {
        steps: end.saturating_sub(step),
        out: dir.to_path_buf(),
        snapshot_every: c.run.snapshot_every,
        check_every: c.run.check_every,
        progress,
        formats: c.run.formats.clone(),
        checkpoint_every: c.run.checkpoint_every,
        resumed: Some(ResumedRun { last_snapshot: c.run.last_snapshot.as_ref().map(PathBuf::from), max_speed: c.run.max_speed }),
        frames: None,
        end_time: c.run.end_time,
        surface_mesh_every: c.run.surface_mesh_every,
        surface_mesh_format: c.run.surface_mesh_format,
    };
    let scene = Scene::from_toml_str(&c.scene_toml, &SceneOrigin::Text)?;
    run(backend, &scene, &opts)
}

/// A fresh backend of the kind that saved a state (`gpu`, `cpu f32`, `cpu f64`).
fn make_backend_of_kind(scene: &Scene, kind: &str) -> anyhow::Result<Box<dyn Backend>> {
    let (params, initial) = (scene.params(), scene.initial_state());
    Ok(match kind {
        "gpu" => Box::new(GpuSolver::new(GpuContext::new()?, &params, &initial)?),
        "cpu f64" => Box::new(CpuSolver::<f64>::new(&params, &initial)),
        "cpu f32" => Box::new(CpuSolver::<f32>::new(&params, &initial)),
        other => anyhow::bail!("the checkpoint names an unknown backend '{other}'"),
    })
}

/// The checkpoint of a run's current state.
pub fn capture(
    backend: &mut dyn Backend,
    scene: &Scene,
    opts: &RunOptions,
    end_step: u64,
    last_snapshot: Option<&Path>,
    max_speed: f64,
) -> anyhow::Result<Checkpoint> {
    Ok(Checkpoint {
        scene_toml: scene.to_toml(),
        run: run_record(backend, opts, end_step, last_snapshot, max_speed),
        state: backend.save_state()?,
    })
}

/// Writes the checkpoint of a run's current state to `path`: the same bytes as [`write()`] of
/// [`capture`], with the state streamed in pieces where the backend can (the GPU), so that no
/// host copy of every array is made.
pub fn save(
    backend: &mut dyn Backend,
    scene: &Scene,
    opts: &RunOptions,
    end_step: u64,
    last_snapshot: Option<&Path>,
    max_speed: f64,
    path: &Path,
) -> anyhow::Result<()> {
    let run = run_record(backend, opts, end_step, last_snapshot, max_speed);
    write_with_state(path, &scene.to_toml(), &run, |w| match backend.write_state_streamed(w) {
        Some(written) => written,
        None => {
            postcard::to_io(&backend.save_state()?, w).context("cannot serialise the checkpoint")?;
            Ok(())
        }
    })
}

/// The settings of the run, as a checkpoint records them.
pub fn run_record(backend: &dyn Backend, opts: &RunOptions, end_step: u64, last_snapshot: Option<&Path>, max_speed: f64) -> RunRecord {
    RunRecord {
        end_step,
        snapshot_every: opts.snapshot_every,
        check_every: opts.check_every,
        checkpoint_every: opts.checkpoint_every,
        formats: opts.formats.clone(),
        adapter: backend.adapter(),
        last_snapshot: last_snapshot.map(|p| p.display().to_string()),
        max_speed,
        end_time: opts.end_time,
        surface_mesh_every: opts.surface_mesh_every,
        surface_mesh_format: opts.surface_mesh_format,
    }
}

/// The snapshot writer of a run; a resumed run keeps the series index up to its first step.
pub(crate) fn snapshot_writer(opts: &RunOptions, start_step: u64) -> anyhow::Result<SnapshotWriter> {
    if opts.resumed.is_some() {
        SnapshotWriter::resume(&opts.out, &opts.formats, start_step)
    } else {
        Ok(SnapshotWriter::new(&opts.out, &opts.formats))
    }
}
