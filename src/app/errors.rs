//! Errors in what the user gave, and the process exit codes: 0 success, 1 a run that went bad
//! or a failed check, 2 bad input (a scene, a flag, an unusable path, a GPU asked for where
//! there is none, a scene beyond the adapter's limits), 130 / 143 a run stopped by SIGINT /
//! SIGTERM (see `run::report_run`).

use crate::io::atomic::AtomicFile;
use crate::io::rundir::RunDirError;
use crate::model::scene::SceneError;
use crate::solver::gpu::memory::GpuMemoryError;
use crate::solver::gpu::GpuError;

/// An error in what the user gave: exit code 2.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct InputError(pub String);

/// The exit code of a command that failed with `e`.
pub fn exit_code(e: &anyhow::Error) -> i32 {
    // A scene or a setting beyond what the adapter allows, or no adapter for --backend gpu, is
    // bad input too.
    let too_big = e.downcast_ref::<GpuMemoryError>().is_some() || e.downcast_ref::<GpuError>().is_some();
    let bad_input = e.downcast_ref::<SceneError>().is_some() || e.downcast_ref::<InputError>().is_some() || e.downcast_ref::<RunDirError>().is_some();
    if too_big || bad_input {
        2
    } else {
        1
    }
}

/// The file a command's `--out FILE.json` names, opened before the command's work so that an
/// unusable path is bad input (exit 2) and not a failure after minutes of measuring. Nothing
/// replaces the path until the returned file is committed, and an existing file is replaced
/// only where `ours` recognises its text as what the command writes (`what`): a user's file of
/// the same name is refused, never overwritten.
pub fn output_file(flag: &str, path: &std::path::Path, what: &str, ours: &dyn Fn(&str) -> bool) -> Result<AtomicFile, InputError> {
    let cannot = |why: String| InputError(format!("{flag} {}: {why}; allowed: the path of a file in a directory this user can write", path.display()));
    if path.is_dir() {
        return Err(cannot("is a directory".into()));
    }
    check_replaceable(flag, path, what, ours)?;
    AtomicFile::create(path).map_err(|e| cannot(format!("{:#}", e).replace(&format!("cannot write {}: ", path.display()), "cannot be written: ")))
}

/// Refuses an existing `path` that is not a file wgsph wrote (`ours` judges its text, read up to
/// 64 MiB; a file that is not text, or is longer, is not one): what a command replaces must be
/// its own earlier output.
fn check_replaceable(flag: &str, path: &std::path::Path, what: &str, ours: &dyn Fn(&str) -> bool) -> Result<(), InputError> {
    use std::io::Read;
    let Ok(meta) = std::fs::symlink_metadata(path) else { return Ok(()) };
    let mut text = String::new();
    let readable = meta.is_file()
        && std::fs::File::open(path).and_then(|f| f.take(64 << 20).read_to_string(&mut text)).is_ok()
        && (text.len() as u64) < (64 << 20);
    if readable && ours(&text) {
        return Ok(());
    }
    Err(InputError(format!(
        "{flag} {}: exists and is not {what} that wgsph wrote; wgsph replaces only its own output: remove it, or choose another name",
        path.display()
    )))
}
