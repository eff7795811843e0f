//! Output files, always written atomically: to a temporary file beside the target, then renamed,
//! so a reader never sees a half-written file and an interrupted run leaves the old one intact.
//!
//! The temporary files are named `.wgsph-tmp-XXXXXXXXXXXXXXXX-NAME` (NAME the target's): a
//! process killed while writing leaves one behind, and [`remove_leftover_temporaries`] (what
//! `wgsph run --resume` calls) recognises them by that name and removes them. Errors name the
//! target, never the temporary file.

use anyhow::Context;
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The name prefix of every temporary file the atomic writer creates.
pub const TEMP_PREFIX: &str = ".wgsph-tmp-";

/// Writes `path` atomically with the bytes `write` produces.
pub fn write_atomic(path: &Path, write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>) -> anyhow::Result<()> {
    let mut file = AtomicFile::create(path)?;
    write(&mut file).with_context(|| format!("cannot write {}", path.display()))?;
    file.commit()
}

/// A file written atomically: the bytes go (buffered) to a temporary file beside `path`, which
/// [`AtomicFile::commit`] renames over it; dropped without a commit, the temporary file is
/// removed and `path` is left as it was. Unlike [`write_atomic`] it can seek (files whose
/// sections are written out of order) and several can be open at once.
pub struct AtomicFile {
    path: PathBuf,
    temporary: PathBuf,
    token: u64,
    out: Option<std::io::BufWriter<File>>,
}

impl AtomicFile {
    pub fn create(path: &Path) -> anyhow::Result<Self> {
        let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create directory {}", dir.display()))?;
        // A new file gets the permissions any new file would (0666 less the umask).
        let mut attempt = 0;
        let (file, temporary, token) = loop {
            let token = rand::random::<u64>();
            let temporary = temporary_path(path, token);
            match std::fs::OpenOptions::new().write(true).create_new(true).open(&temporary) {
                Ok(f) => break (f, temporary, token),
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && attempt < 16 => attempt += 1,
                Err(e) => return Err(e).with_context(|| format!("cannot write {}", path.display())),
            }
        };
        Ok(AtomicFile { path: path.to_path_buf(), temporary, token, out: Some(std::io::BufWriter::new(file)) })
    }

    /// The random part of the temporary file's name: with the target's path it names the
    /// temporary file ([`temporary_path`]), which other processes writing pieces of the same
    /// file open (`io::snapshot::pieces`).
    pub fn token(&self) -> u64 {
        self.token
    }

    /// The file this one replaces once committed.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Flushes the bytes and renames the temporary file over the target.
    pub fn commit(mut self) -> anyhow::Result<()> {
        let out = self.out.take().expect("an uncommitted file has its writer");
        let cannot = || format!("cannot write {}", self.path.display());
        let file = out.into_inner().map_err(|e| e.into_error()).with_context(cannot)?;
        file.sync_all().with_context(cannot)?;
        drop(file);
        std::fs::rename(&self.temporary, &self.path).with_context(|| format!("cannot move the finished file to {}", self.path.display()))?;
        // Renamed: nothing is left to remove.
        self.temporary = PathBuf::new();
        Ok(())
    }

    fn writer(&mut self) -> &mut std::io::BufWriter<File> {
        self.out.as_mut().expect("an uncommitted file has its writer")
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if !self.temporary.as_os_str().is_empty() {
            // Not committed: the buffered bytes are dropped with the file, not written.
            if let Some(out) = self.out.take() {
                let (file, _unwritten) = out.into_parts();
                drop(file);
            }
            let _ = std::fs::remove_file(&self.temporary);
        }
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.writer().write(buf)
    }
    fn write_all(&mut self, buf: &[u8]) -> std::io::Result<()> {
        self.writer().write_all(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.writer().flush()
    }
}

impl std::io::Seek for AtomicFile {
    fn seek(&mut self, pos: std::io::SeekFrom) -> std::io::Result<u64> {
        self.writer().seek(pos)
    }
}

/// The temporary file of the [`AtomicFile`] for `path` whose [`AtomicFile::token`] is `token`.
pub fn temporary_path(path: &Path, token: u64) -> PathBuf {
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    dir.join(format!("{TEMP_PREFIX}{token:016x}-{name}"))
}

/// Whether `name` is that of a temporary file of the atomic writer.
pub fn is_temporary(name: &str) -> bool {
    name.starts_with(TEMP_PREFIX)
}

/// Removes the atomic writer's temporary files in `dir` (not in its subdirectories), which a
/// process killed while writing leaves behind; returns the files removed. A missing `dir` has
/// none.
pub fn remove_leftover_temporaries(dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let entries = match std::fs::read_dir(dir) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(e).with_context(|| format!("cannot list {}", dir.display())),
    };
    let mut removed = Vec::new();
    for entry in entries {
        let entry = entry.with_context(|| format!("cannot list {}", dir.display()))?;
        let is_file = entry.file_type().map(|t| t.is_file()).unwrap_or(false);
        if is_file && is_temporary(&entry.file_name().to_string_lossy()) {
            std::fs::remove_file(entry.path()).with_context(|| format!("cannot remove {}", entry.path().display()))?;
            removed.push(entry.path());
        }
    }
    Ok(removed)
}
