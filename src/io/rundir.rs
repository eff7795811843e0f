//! The run directory: recognised by a marker the run writes first, never clobbered, holding a
//! copy of the exact scene the run used (`DIR/scene.toml`) beside its outputs.
//!
//! A run's output locations (`--out`, and `--frames` when given) are checked before anything
//! is written or removed: each must be a directory wgsph can write in (or one it can create),
//! and one that holds anything must be an earlier run's (it has the marker [`MARKER`]), which
//! only `--overwrite` replaces. Even then only the files a run writes are replaced: anything
//! else in the directory (a user's notes, the scene file being run) is left alone. The start
//! of a run is undone if it fails before its first step ([`StartGuard`]): the earlier run's
//! files are moved aside, not deleted, until then, and put back.

use crate::io::atomic::{is_temporary, write_atomic, TEMP_PREFIX};
use crate::io::checkpoint::CHECKPOINT_FILE;
use crate::io::snapshot::index::INDEX_NAME;
use crate::io::snapshot::vtk::VTK_SERIES_NAME;
use crate::io::snapshot::format::SnapshotFormat;
use crate::io::summary::SUMMARY_FILE;
use crate::io::surface::MeshFormat;
use crate::model::probes::Probes;
use crate::model::scene::Scene;
use anyhow::Context;
use std::cell::RefCell;
use std::path::{Path, PathBuf};

/// An output location the user gave that cannot be used (bad input: exit code 2).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct RunDirError(pub String);

/// The copy of the resolved scene in a run directory.
pub const SCENE_COPY: &str = "scene.toml";
/// The file that marks a directory as a wgsph run's: written first, it holds the wgsph version
/// and the time the run started.
pub const MARKER: &str = ".wgsph-run";
/// The name prefix of the directory an earlier run's files wait in while `--overwrite` starts
/// a new run (removed once the new run took its first step, moved back if it did not).
const REPLACED_PREFIX: &str = ".wgsph-replaced-";
/// The subdirectories a run writes, and the files it writes in them.
pub use crate::io::snapshot::format::SNAPSHOTS_DIR;
const SURFACE_DIR: &str = "surface";
/// The probes' time series and plots (`probes/NAME.csv`, `probes/NAME.png`).
pub const PROBES_DIR: &str = "probes";
/// The subdirectories a run writes into.
const RUN_SUBDIRS: [&str; 3] = [SNAPSHOTS_DIR, SURFACE_DIR, PROBES_DIR];

/// The name of frame `index`'s picture: `frame_00000.png`.
pub fn frame_file_name(index: u64) -> String {
    format!("frame_{index:05}.png")
}

/// What a run writes into its subdirectories, recorded in its marker: `--overwrite` replaces
/// there only the files of the kinds the earlier run wrote, and a failed start removes only
/// those of its own.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RunWrites {
    /// The snapshots' file extensions (`csv`, `vtk`, `ply`).
    pub snapshot_formats: Vec<String>,
    /// The surface meshes' extension, when the run writes them.
    pub surface_format: Option<String>,
    /// The probes' names (`probes/NAME.csv`, `NAME.png`).
    pub probes: Vec<String>,
}

impl RunWrites {
    /// What a run writes: snapshots in `formats`, surface meshes in `surface` (None: none), and
    /// the series of `probes`.
    pub fn of_run(formats: &[SnapshotFormat], surface: Option<MeshFormat>, probes: &Probes) -> RunWrites {
        RunWrites {
            snapshot_formats: formats.iter().map(|f| f.extension().to_string()).collect(),
            surface_format: surface.map(|f| f.extension().to_string()),
            probes: probes.probes.iter().map(|p| p.name.clone()).collect(),
        }
    }

    /// The marker's lines after its first two: `snapshots EXT...`, `surface EXT`, `probes NAME...`.
    fn marker_lines(&self) -> String {
        let mut text = format!("snapshots {}\n", self.snapshot_formats.join(" "));
        if let Some(f) = &self.surface_format {
            text += &format!("surface {f}\n");
        }
        text + &format!("probes {}\n", self.probes.join(" "))
    }

    /// The record in the marker of run directory `dir`; `None` where the marker holds none (a
    /// marker of an earlier version, which records no kinds: every file named as a run's is).
    fn of_marker(dir: &Path) -> Option<RunWrites> {
        let text = std::fs::read_to_string(dir.join(MARKER)).ok()?;
        let mut writes = RunWrites::default();
        let mut recorded = false;
        for line in text.lines() {
            let mut words = line.split(' ');
            match words.next() {
                Some("snapshots") => {
                    writes.snapshot_formats = words.filter(|w| !w.is_empty()).map(str::to_string).collect();
                    recorded = true;
                }
                Some("surface") => writes.surface_format = words.next().map(str::to_string),
                Some("probes") => writes.probes = words.filter(|w| !w.is_empty()).map(str::to_string).collect(),
                _ => {}
            }
        }
        recorded.then_some(writes)
    }
}

/// What a marked directory holds (its marker's `holds` line): a run's directory (`--out`, its
/// pictures too where `--frames` names the same place), or only a run's pictures (`--frames`).
const HOLDS_RUN: &str = "run";
const HOLDS_FRAMES: &str = "frames";

/// Whether the marked directory `dir` holds only a run's pictures; false for a run's directory
/// and for a marker of an earlier version, which does not say.
fn holds_frames_only(dir: &Path) -> bool {
    std::fs::read_to_string(dir.join(MARKER)).is_ok_and(|t| t.lines().any(|l| l == format!("holds {HOLDS_FRAMES}")))
}

/// Whether `name`, in the directory `sub` of a run directory (`None`: the top), is a file a
/// wgsph run writes there: one that `writes` records, or with `None` any run's.
fn is_run_output(sub: Option<&str>, name: &str, writes: Option<&RunWrites>) -> bool {
    let numbered = |prefix: &str, extensions: &[&str]| {
        name.strip_prefix(prefix).and_then(|rest| rest.split_once('.')).is_some_and(|(digits, ext)| {
            !digits.is_empty() && digits.bytes().all(|b| b.is_ascii_digit()) && extensions.contains(&ext)
        })
    };
    if is_temporary(name) {
        return true;
    }
    match (sub, writes) {
        (None, _) => [MARKER, SUMMARY_FILE, SCENE_COPY, CHECKPOINT_FILE].contains(&name) || numbered("frame_", &["png"]),
        (Some(SNAPSHOTS_DIR), None) => numbered("step_", &["csv", "vtk", "ply"]) || name == VTK_SERIES_NAME || name == INDEX_NAME,
        (Some(SNAPSHOTS_DIR), Some(w)) => {
            let formats: Vec<&str> = w.snapshot_formats.iter().map(String::as_str).collect();
            numbered("step_", &formats) || (name == VTK_SERIES_NAME && formats.contains(&"vtk")) || name == INDEX_NAME
        }
        (Some(SURFACE_DIR), None) => numbered("step_", &["obj", "ply"]),
        (Some(SURFACE_DIR), Some(w)) => w.surface_format.as_deref().is_some_and(|f| numbered("step_", &[f])),
        // A probe's name is letters, digits, '_' and '-' (checked at load).
        (Some(PROBES_DIR), None) => name.rsplit_once('.').is_some_and(|(stem, ext)| {
            !stem.is_empty() && stem.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-') && (ext == "csv" || ext == "png")
        }),
        (Some(PROBES_DIR), Some(w)) => name.rsplit_once('.').is_some_and(|(stem, ext)| w.probes.iter().any(|p| p == stem) && (ext == "csv" || ext == "png")),
        (Some(_), _) => false,
    }
}

/// Where the outputs of a run go, checked (nothing written yet).
#[derive(Debug)]
pub struct RunOutputs {
    locations: Vec<Location>,
    overwrite: bool,
    writes: RunWrites,
    /// The default numbered directory: it must still be free when the run starts.
    numbered: bool,
    /// The id of the run, in its markers and checkpoints ([`run_id`]).
    run_id: String,
}

#[derive(Debug, Clone)]
struct Location {
    /// The flag that named it, for messages.
    flag: &'static str,
    path: PathBuf,
    /// Holds an earlier run (the marker is there).
    earlier_run: bool,
    /// With `--overwrite`: what is there that a run did not write, and stays.
    kept: Vec<String>,
}

impl RunOutputs {
    /// Checks the output locations of a new run before anything is written or removed: `out`,
    /// and `frames` when pictures are written. `inputs` are files the run reads (its scene),
    /// which it must never replace. `numbered`: `out` is the default numbered directory.
    /// `writes`: what the run will write into its subdirectories.
    pub fn check(out: &Path, frames: Option<&Path>, overwrite: bool, numbered: bool, inputs: &[&Path], writes: RunWrites) -> anyhow::Result<RunOutputs> {
        // The default directory is named after the scene: a message about it names the scene's
        // name, not a flag the user did not give.
        let flag = if numbered { "the run directory named after the scene's name (no --out given)" } else { "--out" };
        let mut locations = vec![Location { flag, path: out.to_path_buf(), earlier_run: false, kept: Vec::new() }];
        if let Some(f) = frames {
            if !same_place(f, out) {
                locations.push(Location { flag: "--frames", path: f.to_path_buf(), earlier_run: false, kept: Vec::new() });
            }
        }
        for l in &mut locations {
            (l.earlier_run, l.kept) = check_location(l, overwrite, inputs, &writes)?;
        }
        // Unique enough to tell two runs apart: the time to the nanosecond and the process.
        let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_nanos());
        let run_id = format!("{nanos:x}-{:x}", std::process::id());
        Ok(RunOutputs { locations, overwrite, writes, numbered, run_id })
    }

    /// Makes the locations ready for the run: an earlier run's files (with `--overwrite`) are
    /// moved aside, the directories created and the marker written first. The returned guard
    /// undoes all of this unless [`StartGuard::commit`] is called once the run took its first
    /// step.
    pub fn prepare(self) -> anyhow::Result<StartGuard> {
        let guard = StartGuard { dirs: Vec::new(), created: Vec::new(), replaced: RefCell::new(Vec::new()), committed: RefCell::new(false) };
        let mut guard = guard;
        for (i, l) in self.locations.iter().enumerate() {
            if i == 0 && self.numbered {
                // The default directory is new: if another run took it meanwhile, stop.
                create_missing_parents(&l.path, &mut guard.created)?;
                std::fs::create_dir(&l.path).map_err(|e| {
                    RunDirError(format!("cannot create the run directory {}: {e} (another run may have just taken it; run again)", l.path.display()))
                })?;
                guard.created.push(l.path.clone());
            } else {
                create_missing_parents(&l.path, &mut guard.created)?;
                if !l.path.exists() {
                    std::fs::create_dir(&l.path).with_context(|| format!("{} {}: cannot create it", l.flag, l.path.display()))?;
                    guard.created.push(l.path.clone());
                }
            }
            let subdirs_before = RUN_SUBDIRS.map(|s| l.path.join(s).is_dir());
            if l.earlier_run && self.overwrite {
                let stash = move_outputs_aside(&l.path)?;
                guard.replaced.borrow_mut().push(stash);
            }
            guard.dirs.push((l.path.clone(), subdirs_before));
            let holds = if i == 0 { HOLDS_RUN } else { HOLDS_FRAMES };
            write_marker(&l.path.join(MARKER), "started", &format!("{}holds {holds}\nrun {}\n", self.writes.marker_lines(), self.run_id))?;
        }
        Ok(guard)
    }

    /// The run directory (`--out`).
    pub fn out(&self) -> &Path {
        &self.locations[0].path
    }

    /// What `--overwrite` leaves in place because no run wrote it: (directory, names).
    pub fn kept(&self) -> Vec<(&Path, &[String])> {
        self.locations.iter().filter(|l| !l.kept.is_empty()).map(|l| (l.path.as_path(), l.kept.as_slice())).collect()
    }
}

/// Whether two paths are the same directory (as written, or once both exist).
fn same_place(a: &Path, b: &Path) -> bool {
    a == b || matches!((a.canonicalize(), b.canonicalize()), (Ok(x), Ok(y)) if x == y)
}

/// Checks one output location; returns whether it holds an earlier run, and what of it
/// `--overwrite` keeps (the names at its top that no run wrote).
fn check_location(l: &Location, overwrite: bool, inputs: &[&Path], writes: &RunWrites) -> anyhow::Result<(bool, Vec<String>)> {
    let (flag, path) = (l.flag, &l.path);
    let bad = |why: String| -> anyhow::Error { RunDirError(format!("{flag} {}: {why}", path.display())).into() };
    if !path.exists() {
        // A name longer than file systems hold (255 bytes) would fail only when created.
        if let Some(long) = path.components().map(|c| c.as_os_str()).find(|c| c.len() > 255) {
            return Err(bad(format!("cannot be created: the name {}... is {} bytes long; a file system holds at most 255", &long.to_string_lossy().chars().take(20).collect::<String>(), long.len())));
        }
        // It will be created: its nearest existing ancestor must be a writable directory.
        let mut ancestor = path.parent();
        while let Some(a) = ancestor {
            if a.as_os_str().is_empty() || a.exists() {
                break;
            }
            ancestor = a.parent();
        }
        let a = ancestor.filter(|a| !a.as_os_str().is_empty()).unwrap_or(Path::new("."));
        if !a.is_dir() {
            return Err(bad(format!("cannot be created: {} is not a directory", a.display())));
        }
        probe_writable(a).map_err(|e| bad(format!("cannot be created: cannot write in {}: {e}", a.display())))?;
        return Ok((false, Vec::new()));
    }
    if !path.is_dir() {
        return Err(bad("is a file, not a directory".into()));
    }
    let names = list(path).map_err(|e| bad(format!("cannot read the directory: {e}")))?;
    let earlier_run = names.iter().any(|n| n == MARKER);
    check_subdirs(path).map_err(bad)?;
    let mut kept = Vec::new();
    if !names.is_empty() {
        let shown = shown_names(&names);
        if !earlier_run {
            return Err(bad(format!(
                "the directory is not empty (it holds {shown}) and is not a wgsph run directory (it has no {MARKER}); wgsph writes only into a new or empty directory{}",
                if overwrite { ", and --overwrite only replaces what a wgsph run wrote" } else { "" }
            )));
        }
        if !overwrite {
            return Err(bad(format!(
                "holds an earlier wgsph run; choose another directory, {}or replace that run with --overwrite",
                if flag == "--out" { "continue it with --resume (when it has a checkpoint), " } else { "" }
            )));
        }
        // Pictures do not replace a run: --overwrite at --frames would remove an earlier run's
        // snapshots, summary and checkpoint for a few PNG files.
        if flag == "--frames" && !holds_frames_only(path) {
            return Err(bad(format!(
                "is an earlier run's directory (it holds {}), not a directory of pictures: --overwrite there would remove that run to write this run's pictures; \
                 give --frames another directory (or this run's --out)",
                shown
            )));
        }
        // Only the files a run writes are replaced; the run's inputs must not be among them.
        let outputs = run_outputs(path).map_err(|e| bad(format!("cannot read the directory: {e}")))?;
        for input in inputs {
            if let Ok(input) = input.canonicalize() {
                if let Some(o) = outputs.iter().find(|o| o.canonicalize().is_ok_and(|o| o == input)) {
                    return Err(bad(format!(
                        "--overwrite would replace {}, the scene this run reads; copy it out of the directory first, or choose another directory",
                        o.display()
                    )));
                }
            }
        }
        // A directory where this run writes a file would stop it part way.
        check_output_entries(path, Some(writes)).map_err(bad)?;
        // A file named as this run's output that the earlier run did not write (a user's, of
        // another kind) would be replaced by this run, or removed by a failed start: it is in
        // the way.
        let earlier = RunWrites::of_marker(path);
        for sub in RUN_SUBDIRS {
            let d = path.join(sub);
            if !d.is_dir() {
                continue;
            }
            probe_writable(&d).map_err(|e| bad(format!("cannot replace the earlier run's files: cannot write in {}: {e}", d.display())))?;
            let names = list(&d).map_err(|e| bad(format!("cannot read {}: {e}", d.display())))?;
            if let Some(n) = names.iter().find(|n| is_run_output(Some(sub), n, Some(writes)) && !is_run_output(Some(sub), n, earlier.as_ref())) {
                return Err(bad(format!(
                    "{} is in the way: this run writes a file of that name, and the earlier run did not write it; move it, or choose another directory",
                    d.join(n).display()
                )));
            }
        }
        kept = names
            .iter()
            .filter(|n| {
                let p = path.join(n);
                let run_dir = (RUN_SUBDIRS.contains(&n.as_str()) || n.starts_with(REPLACED_PREFIX)) && is_real_dir(&p);
                !run_dir && !(is_run_output(None, n, None) && p.is_file())
            })
            .cloned()
            .collect();
        for sub in RUN_SUBDIRS.iter().filter(|sub| is_real_dir(&path.join(sub))) {
            let names = list(&path.join(sub)).map_err(|e| bad(format!("cannot read {}: {e}", path.join(sub).display())))?;
            kept.extend(names.into_iter().filter(|n| !is_run_output(Some(sub), n, earlier.as_ref())).map(|n| format!("{sub}/{n}")));
        }
    }
    probe_writable(path).map_err(|e| bad(format!("cannot write there: {e}")))?;
    Ok((earlier_run, kept))
}

/// A run writes into its subdirectories, and replaces (or, resumed, removes the partial files
/// of) what an earlier run wrote there: one that is a link would send both into a directory
/// that is not the run's. Each must be a directory of its own, or absent.
fn check_subdirs(path: &Path) -> Result<(), String> {
    for sub in RUN_SUBDIRS {
        let d = path.join(sub);
        match std::fs::symlink_metadata(&d) {
            Ok(m) if m.file_type().is_symlink() => {
                return Err(format!(
                    "{} is a link{}; a run writes its {sub}/ only into a directory of its own: remove the link, or choose another directory",
                    d.display(),
                    std::fs::read_link(&d).map(|t| format!(" to {}", t.display())).unwrap_or_default()
                ));
            }
            Ok(m) if !m.is_dir() => {
                return Err(format!("{} is a file, where a run writes its {sub}/ directory; move it, or choose another directory", d.display()));
            }
            _ => {}
        }
    }
    Ok(())
}

/// A directory where a run writes one of its files (`snapshots/step_000010.csv/`, a probe's
/// `NAME.png/`): the run would fail when it got there, after its steps. `writes`: what the run
/// writes into its subdirectories (`None`: any run's files).
fn check_output_entries(path: &Path, writes: Option<&RunWrites>) -> Result<(), String> {
    let is_dir = |p: &Path| std::fs::symlink_metadata(p).is_ok_and(|m| m.is_dir());
    let in_the_way = |p: PathBuf| format!("{} is a directory, where the run writes a file; move it away, or choose another directory", p.display());
    for name in list(path).map_err(|e| format!("cannot read the directory: {e}"))? {
        if !is_temporary(&name) && is_run_output(None, &name, None) && is_dir(&path.join(&name)) {
            return Err(in_the_way(path.join(name)));
        }
    }
    for sub in RUN_SUBDIRS.iter().filter(|s| is_real_dir(&path.join(s))) {
        let d = path.join(sub);
        for name in list(&d).map_err(|e| format!("cannot read {}: {e}", d.display()))? {
            if !is_temporary(&name) && is_run_output(Some(sub), &name, writes) && is_dir(&d.join(&name)) {
                return Err(in_the_way(d.join(name)));
            }
        }
    }
    Ok(())
}

/// Checks a run directory that `--resume` continues, before anything is read or removed: its
/// subdirectories are its own (not links), and the files it rewrites whole (the summary, the
/// indexes) are files, not directories, so that the run does not fail after all its steps.
pub fn check_resumable(dir: &Path) -> Result<(), RunDirError> {
    let bad = |why: String| RunDirError(format!("--resume {}: {why}", dir.display()));
    check_subdirs(dir).map_err(bad)?;
    // The summary, the indexes and the snapshots among them.
    check_output_entries(dir, RunWrites::of_marker(dir).as_ref()).map_err(bad)
}

/// The id of the run in run directory `dir` (its marker's `run` line), where it has one: a
/// checkpoint records it, so that a checkpoint put into another run's directory is refused.
pub fn run_id(dir: &Path) -> Option<String> {
    let text = std::fs::read_to_string(dir.join(MARKER)).ok()?;
    text.lines().find_map(|l| l.strip_prefix("run ").map(str::to_string))
}

/// Writes the marker of run directory `dir` again where it is missing (deleted since the run
/// started), from what the resumed run writes and its checkpoint's `run_id`: without it a later
/// `--overwrite` would take the run's files for a user's and refuse them. True when it was
/// written.
pub fn restore_marker(dir: &Path, writes: &RunWrites, run_id: Option<&str>) -> anyhow::Result<bool> {
    let path = dir.join(MARKER);
    if std::fs::symlink_metadata(&path).is_ok() {
        return Ok(false);
    }
    let id = run_id.map(|id| format!("run {id}\n")).unwrap_or_default();
    write_marker(&path, "resumed", &format!("{}holds {HOLDS_RUN}\n{id}", writes.marker_lines()))?;
    Ok(true)
}

/// The file that marks a directory as one a report command (`wgsph tradeoff`, `wgsph
/// validate`) wrote.
pub const REPORT_MARKER: &str = ".wgsph-report";

/// Makes `dir` ready for a report command's files (given as `flag`): a new or empty directory,
/// or one such a command wrote before (it has [`REPORT_MARKER`]), whose files of the same name
/// the command replaces; anything else is refused before any work (exit 2), never written into.
pub fn prepare_report_dir(flag: &str, dir: &Path) -> Result<(), RunDirError> {
    let bad = |why: String| RunDirError(format!("{flag} {}: {why}", dir.display()));
    match std::fs::symlink_metadata(dir) {
        Ok(m) if m.is_dir() => {
            let names = list(dir).map_err(|e| bad(format!("cannot read the directory: {e}")))?;
            if !names.is_empty() && !names.iter().any(|n| n == REPORT_MARKER) {
                return Err(bad(format!(
                    "the directory is not empty (it holds {}) and no wgsph report was written there (it has no {REPORT_MARKER}); choose a new or empty directory",
                    shown_names(&names)
                )));
            }
        }
        Ok(_) if dir.is_dir() => return Err(bad("is a link to a directory; give the directory itself".into())),
        Ok(_) => return Err(bad("is a file, not a directory".into())),
        Err(_) => {
            let mut created = Vec::new();
            create_missing_parents(&dir.join("x"), &mut created).map_err(|e| bad(format!("cannot be created: {e:#}")))?;
        }
    }
    probe_writable(dir).map_err(|e| bad(format!("cannot write there: {e}")))?;
    write_marker(&dir.join(REPORT_MARKER), "written", "").map_err(|e| bad(format!("cannot write there: {e:#}")))
}

/// Whether `path` is a directory itself, not a link to one.
fn is_real_dir(path: &Path) -> bool {
    std::fs::symlink_metadata(path).is_ok_and(|m| m.is_dir())
}

/// The names in a directory, sorted.
fn list(dir: &Path) -> std::io::Result<Vec<String>> {
    let mut names = Vec::new();
    for e in std::fs::read_dir(dir)? {
        names.push(e?.file_name().to_string_lossy().into_owned());
    }
    names.sort();
    Ok(names)
}

/// A few names of a listing, for a message.
fn shown_names(names: &[String]) -> String {
    let mut shown: Vec<&str> = names.iter().take(4).map(String::as_str).collect();
    if names.len() > 4 {
        shown.push("...");
    }
    match names.len() {
        1 => shown.join(", "),
        n => format!("{} ({n} entries)", shown.join(", ")),
    }
}

/// Whether a file can be created in `dir`: creates one and removes it.
fn probe_writable(dir: &Path) -> std::io::Result<()> {
    let probe = dir.join(format!("{TEMP_PREFIX}{:016x}-probe", rand::random::<u64>()));
    std::fs::OpenOptions::new().write(true).create_new(true).open(&probe)?;
    std::fs::remove_file(&probe)
}

/// The files of `dir` (a run directory) that a run writes, in it and its subdirectories.
fn run_outputs(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    let writes = RunWrites::of_marker(dir);
    let mut out = Vec::new();
    for name in list(dir)? {
        let path = dir.join(&name);
        if name.starts_with(REPLACED_PREFIX) && is_real_dir(&path) {
            // Left by a start that was killed: an earlier run's files, already set aside.
            out.push(path);
        } else if RUN_SUBDIRS.contains(&name.as_str()) && is_real_dir(&path) {
            for inner in list(&path)? {
                if is_run_output(Some(&name), &inner, writes.as_ref()) && path.join(&inner).is_file() {
                    out.push(path.join(inner));
                }
            }
        } else if is_run_output(None, &name, None) && path.is_file() {
            out.push(path);
        }
    }
    Ok(out)
}

/// Creates the missing parents of `path`, recording each one created.
fn create_missing_parents(path: &Path, created: &mut Vec<PathBuf>) -> anyhow::Result<()> {
    let mut missing = Vec::new();
    let mut p = path.parent();
    while let Some(a) = p {
        if a.as_os_str().is_empty() || a.exists() {
            break;
        }
        missing.push(a.to_path_buf());
        p = a.parent();
    }
    for d in missing.into_iter().rev() {
        std::fs::create_dir(&d).with_context(|| format!("cannot create {}", d.display()))?;
        created.push(d);
    }
    Ok(())
}

/// An earlier run's files, moved into a hidden directory of their run directory.
#[derive(Debug)]
struct Replaced {
    dir: PathBuf,
    stash: PathBuf,
    /// Paths relative to `dir`.
    files: Vec<PathBuf>,
}

fn move_outputs_aside(dir: &Path) -> anyhow::Result<Replaced> {
    let outputs = run_outputs(dir).with_context(|| format!("cannot read {}", dir.display()))?;
    let stash = dir.join(format!("{REPLACED_PREFIX}{:016x}", rand::random::<u64>()));
    std::fs::create_dir(&stash).with_context(|| format!("cannot create {}", stash.display()))?;
    let mut replaced = Replaced { dir: dir.to_path_buf(), stash, files: Vec::new() };
    for o in outputs {
        let rel = o.strip_prefix(dir).expect("outputs lie in their directory").to_path_buf();
        let to = replaced.stash.join(&rel);
        if let Some(p) = to.parent() {
            std::fs::create_dir_all(p).with_context(|| format!("cannot create {}", p.display()))?;
        }
        if let Err(e) = std::fs::rename(&o, &to) {
            // Put back what was moved, so that the failed start changes nothing.
            let _ = replaced.restore();
            return Err(e).with_context(|| format!("cannot move {} aside to replace it", o.display()));
        }
        replaced.files.push(rel);
    }
    Ok(replaced)
}

impl Replaced {
    fn restore(&self) -> anyhow::Result<()> {
        for rel in &self.files {
            let (from, to) = (self.stash.join(rel), self.dir.join(rel));
            if let Some(p) = to.parent() {
                std::fs::create_dir_all(p).with_context(|| format!("cannot create {}", p.display()))?;
            }
            std::fs::rename(&from, &to).with_context(|| format!("cannot move {} back to {}", from.display(), to.display()))?;
        }
        std::fs::remove_dir_all(&self.stash).with_context(|| format!("cannot remove {}", self.stash.display()))
    }

    fn discard(&self) -> anyhow::Result<()> {
        std::fs::remove_dir_all(&self.stash).with_context(|| format!("cannot remove the replaced run's files in {}", self.stash.display()))
    }
}

/// The start of a run, undone unless committed: what [`RunOutputs::prepare`] did and what the
/// run wrote since. Dropped uncommitted (the run failed before its first step), it removes the
/// files a run writes from its directories, puts an earlier run's files back, and removes the
/// directories it created (when empty).
#[derive(Debug)]
pub struct StartGuard {
    /// Each location, with whether its snapshots/ and surface/ existed before.
    dirs: Vec<(PathBuf, [bool; 3])>,
    /// Directories created, parents first.
    created: Vec<PathBuf>,
    replaced: RefCell<Vec<Replaced>>,
    committed: RefCell<bool>,
}

impl StartGuard {
    /// The run took its first step: its start stays, and an earlier run's files it replaces
    /// are removed.
    pub fn commit(&self) -> anyhow::Result<()> {
        if self.committed.replace(true) {
            return Ok(());
        }
        for r in self.replaced.borrow_mut().drain(..) {
            r.discard()?;
        }
        Ok(())
    }

    /// Undoes the start (see [`StartGuard`]); what dropping it uncommitted does, with errors.
    pub fn rollback(self) -> anyhow::Result<()> {
        let result = self.undo();
        self.committed.replace(true);
        result
    }

    fn undo(&self) -> anyhow::Result<()> {
        let replaced = self.replaced.borrow_mut().drain(..).collect::<Vec<_>>();
        for (dir, subdirs_before) in &self.dirs {
            let stashes: Vec<&Path> = replaced.iter().filter(|r| &r.dir == dir).map(|r| r.stash.as_path()).collect();
            for f in run_outputs(dir).unwrap_or_default() {
                if !stashes.contains(&f.as_path()) {
                    let _ = if f.is_dir() { Ok(()) } else { std::fs::remove_file(&f) };
                }
            }
            for r in replaced.iter().filter(|r| &r.dir == dir) {
                r.restore()?;
            }
            for (sub, existed) in RUN_SUBDIRS.iter().zip(subdirs_before) {
                if !existed {
                    let _ = std::fs::remove_dir(dir.join(sub));
                }
            }
        }
        for d in self.created.iter().rev() {
            let _ = std::fs::remove_dir(d);
        }
        Ok(())
    }
}

impl Drop for StartGuard {
    fn drop(&mut self) {
        if !*self.committed.borrow() {
            if let Err(e) = self.undo() {
                eprintln!("warning: undoing the failed start: {e:#}");
            }
        }
    }
}

/// Writes a marker file that says wgsph made its directory: a run directory's, a report's.
fn write_marker(path: &Path, what: &str, more: &str) -> anyhow::Result<()> {
    let text = format!("wgsph {}\n{what} {}\n{more}", env!("CARGO_PKG_VERSION"), utc_now());
    write_atomic(path, |w| w.write_all(text.as_bytes()))
}

/// The time now as `YYYY-MM-DDTHH:MM:SSZ`.
fn utc_now() -> String {
    let secs = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_secs()).unwrap_or(0);
    let (days, rem) = ((secs / 86_400) as i64, secs % 86_400);
    // Days since 1970-01-01 to a civil date (H. Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!("{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}Z", rem / 3600, rem / 60 % 60, rem % 60)
}

/// The default run directory of a scene: `parent/NAME-NNN`, numbered one past the highest
/// number there, so that every run gets a new directory and the newest has the highest number.
pub fn numbered_run_dir(parent: &Path, scene_name: &str) -> PathBuf {
    let name: String = scene_name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '_' || c == '-' { c } else { '_' }).collect();
    let name = if name.is_empty() { "run".to_string() } else { name };
    let prefix = format!("{name}-");
    let highest = std::fs::read_dir(parent)
        .map(|entries| {
            entries
                .filter_map(|e| e.ok())
                .filter_map(|e| e.file_name().to_string_lossy().strip_prefix(&prefix).and_then(|n| n.parse::<u64>().ok()))
                .max()
                .unwrap_or(0)
        })
        .unwrap_or(0);
    // One past the highest, or where that number does not exist, the first free one.
    let next = highest.checked_add(1).unwrap_or_else(|| (1..).find(|n| !parent.join(format!("{name}-{n:03}")).exists()).unwrap_or(1));
    parent.join(format!("{name}-{next:03}"))
}

/// Writes the resolved scene (after `--set`, `--particles` and imports) as `DIR/scene.toml`,
/// which `wgsph run DIR/scene.toml` runs again.
pub fn write_scene_copy(out: &Path, scene: &Scene) -> anyhow::Result<()> {
    let text = scene.to_toml();
    write_atomic(&out.join(SCENE_COPY), |w| w.write_all(text.as_bytes()))
}

/// Removes the snapshots and surface meshes of the run in `dir` (of the kinds `writes` records)
/// from steps after `step`: a run resumed at `step` computes its steps again, and one that
/// ends earlier than the run went before would leave files that its index no longer lists.
pub fn remove_steps_after(dir: &Path, step: u64, writes: &RunWrites) -> anyhow::Result<Vec<PathBuf>> {
    let mut removed = Vec::new();
    for sub in [SNAPSHOTS_DIR, SURFACE_DIR] {
        let d = dir.join(sub);
        if !is_real_dir(&d) {
            continue;
        }
        for name in list(&d).with_context(|| format!("cannot read {}", d.display()))? {
            let later = crate::io::snapshot::format::step_of_name(&name).is_some_and(|s| s > step);
            let p = d.join(&name);
            if later && name.starts_with("step_") && is_run_output(Some(sub), &name, Some(writes)) && p.is_file() {
                std::fs::remove_file(&p).with_context(|| format!("cannot remove {}", p.display()))?;
                removed.push(p);
            }
        }
    }
    Ok(removed)
}

/// Removes the partial files a killed run left in its directory (the atomic writer's
/// temporary files, in the directory, `snapshots/` and `surface/`); returns them.
pub fn remove_partial_files(dir: &Path) -> anyhow::Result<Vec<PathBuf>> {
    let mut removed = crate::io::atomic::remove_leftover_temporaries(dir)?;
    for sub in RUN_SUBDIRS {
        removed.extend(crate::io::atomic::remove_leftover_temporaries(&dir.join(sub))?);
    }
    Ok(removed)
}
