//! Output files, always written atomically: to a temporary file beside the target, then renamed,
//! so a reader never sees a half-written file and an interrupted run leaves the old one intact.

use anyhow::Context;
use std::io::Write;
use std::path::{Path, PathBuf};

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
    out: std::io::BufWriter<tempfile::NamedTempFile>,
}

impl AtomicFile {
    pub fn create(path: &Path) -> anyhow::Result<Self> {
        let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        std::fs::create_dir_all(dir).with_context(|| format!("cannot create directory {}", dir.display()))?;
        let mut builder = tempfile::Builder::new();
        // Temporary files are private (0600) by default; an output file gets the permissions any
        // new file would (0666 less the umask).
        #[cfg(unix)]
        builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
        let tmp = builder.tempfile_in(dir).with_context(|| format!("cannot create a file in {}", dir.display()))?;
        Ok(AtomicFile { path: path.to_path_buf(), out: std::io::BufWriter::new(tmp) })
    }

    /// The file this one replaces once committed.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Flushes the bytes and renames the temporary file over the target.
    pub fn commit(self) -> anyhow::Result<()> {
        let path = self.path;
        let tmp = self.out.into_inner().map_err(|e| e.into_error()).with_context(|| format!("cannot write {}", path.display()))?;
        tmp.as_file().sync_all().ok();
        tmp.persist(&path).with_context(|| format!("cannot move the finished file to {}", path.display()))?;
        Ok(())
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.out.write(buf)
    }
    fn write_all(&mut self, buf: &[u8]) -> std::io::Result<()> {
        self.out.write_all(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }
}

impl std::io::Seek for AtomicFile {
    fn seek(&mut self, pos: std::io::SeekFrom) -> std::io::Result<u64> {
        self.out.seek(pos)
    }
}
