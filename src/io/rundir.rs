//! The run directory: never clobbered without `--overwrite`, and holding a copy of the exact
//! scene the run used (`DIR/scene.toml`) beside its outputs.

use crate::io::atomic::write_atomic;
use crate::model::scene::Scene;
use std::path::Path;

/// An output location the user gave that cannot be used (bad input: exit code 2).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct RunDirError(pub String);

/// The copy of the resolved scene in a run directory.
pub const SCENE_COPY: &str = "scene.toml";

/// Makes `out` ready for a new run. An existing non-empty directory (or a file) is refused
/// unless `overwrite` is set, in which case it is removed first. A directory that contains the
/// working directory is never removed.
pub fn prepare_out_dir(out: &Path, overwrite: bool) -> anyhow::Result<()> {
    if out.is_file() {
        return Err(RunDirError(format!("--out {}: is a file, not a directory", out.display())).into());
    }
    let non_empty = out.is_dir() && std::fs::read_dir(out)?.next().is_some();
    if non_empty {
        if !overwrite {
            return Err(RunDirError(format!(
                "--out {}: the directory exists and is not empty; choose another with --out, resume it with --resume, or replace it with --overwrite",
                out.display()
            ))
            .into());
        }
        let target = out.canonicalize()?;
        let cwd = std::env::current_dir()?.canonicalize()?;
        if cwd.starts_with(&target) {
            return Err(RunDirError(format!(
                "--out {} --overwrite: refusing to remove a directory that contains the working directory",
                out.display()
            ))
            .into());
        }
        std::fs::remove_dir_all(out).map_err(|e| anyhow::anyhow!("cannot remove {} for --overwrite: {e}", out.display()))?;
    }
    std::fs::create_dir_all(out).map_err(|e| anyhow::anyhow!("cannot create {}: {e}", out.display()))?;
    Ok(())
}

/// Writes the resolved scene (after `--particles` and imports) as `DIR/scene.toml`, which
/// `wgsph run DIR/scene.toml` runs again.
pub fn write_scene_copy(out: &Path, scene: &Scene) -> anyhow::Result<()> {
    let text = scene.to_toml();
    write_atomic(&out.join(SCENE_COPY), |w| w.write_all(text.as_bytes()))
}
