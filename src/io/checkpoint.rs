//! Checkpoints: the full state of a run in one file, `DIR/checkpoint.wgsph`, from which
//! `wgsph run --resume DIR` continues bit for bit.
//!
//! Layout (little-endian): the magic `WGSPHCKP`, the format version (u32), the length (u16) and
//! text of the wgsph version that wrote it, the payload length (u64), the payload's CRC-32
//! (u32), then the payload: [`Checkpoint`] serialised with postcard. A checkpoint from another
//! format or wgsph version, or one whose checksum or length does not match, is refused. The file
//! is written beside its target and renamed over it, so the previous checkpoint stays intact
//! until the new one is complete. The payload is written as it is serialised and its length and
//! checksum filled in at the end, so a backend's state goes to the file in pieces as the backend
//! hands them over ([`Backend::visit_state_array`]); reading streams the file too (a checksum
//! pass, then decoding), holding only the decoded state. This is the file format alone: the
//! resumed run is the app's (`app::resume`).

use crate::io::atomic::AtomicFile;
use crate::io::snapshot::format::SnapshotFormat;
use crate::io::surface::MeshFormat;
use crate::model::state::{BackendState, BadStep};
use crate::solver::{Backend, StateArray, StatePiece, StateSource};
use anyhow::Context;
use serde::ser::{Error as _, SerializeSeq, Serializer};
use serde::{Deserialize, Serialize};
use std::cell::RefCell;
use std::path::Path;

/// The checkpoint file in a run directory.
pub const CHECKPOINT_FILE: &str = "checkpoint.wgsph";
const MAGIC: &[u8; 8] = b"WGSPHCKP";
/// Bumped whenever the payload's layout or meaning changes.
pub const FORMAT_VERSION: u32 = 7;
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
    /// A snapshot at the first step reaching each multiple of this simulated time (instead of
    /// every `snapshot_every` steps).
    pub snapshot_interval: Option<f64>,
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
    pub surface_mesh_format: MeshFormat,
    /// The lines of the run's series files (`snapshots/index.csv`, `probes/NAME.csv`) that a run
    /// resumed from this checkpoint keeps, by path in the run directory: a resume that finds
    /// fewer says the file was cut since.
    pub series_lines: Vec<(String, u64)>,
    /// The run directory's run id (its marker's), where it had one: a resume refuses a
    /// checkpoint of another run put into a run directory.
    pub run_id: Option<String>,
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
    let c = read_with(path, |de| Checkpoint::deserialize(de))?;
    check_finite(path, &c)?;
    Ok(c)
}

/// A state whose checksum holds but whose values are not finite was written so by something
/// else than a run (a run never saves a NaN state: it stops before): it is corrupt, and would
/// only go bad at once, of a cause no diagnosis could name.
fn check_finite(path: &Path, c: &Checkpoint) -> Result<(), CheckpointError> {
    let s = &c.state;
    let bad = |what: String| Err(CheckpointError::Corrupt { path: path.display().to_string(), why: format!("{what} is not finite") });
    if !s.time.is_finite() {
        return bad(format!("the time {}", s.time));
    }
    for (i, (x, v)) in s.positions.iter().zip(&s.velocities).enumerate() {
        if !x.iter().chain(v).all(|c| c.is_finite()) {
            return bad(format!("particle {i}'s position or velocity"));
        }
    }
    if let Some(i) = s.densities.iter().position(|d| !d.is_finite()) {
        return bad(format!("particle {i}'s density"));
    }
    Ok(())
}

/// [`read`] with the payload decoded by `decode`.
fn read_with<T>(path: &Path, decode: impl for<'de> FnOnce(&mut PayloadDeserializer<'de>) -> postcard::Result<T>) -> Result<T, CheckpointError> {
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
    match take(8)? {
        Some(m) if m == MAGIC => {}
        // Fewer bytes than the magic, all of them its first ones: a checkpoint cut short.
        None if file_len > 0 && std::fs::read(path).is_ok_and(|b| MAGIC.starts_with(&b)) => return Err(corrupt("the file is truncated")),
        None if file_len == 0 => return Err(corrupt("the file is empty")),
        _ => return Err(CheckpointError::NotACheckpoint(p)),
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
    let mut de = postcard::Deserializer::from_flavor(postcard::de_flavors::io::io::IOReader::new(r.take(payload_len), scratch.as_mut_slice()));
    decode(&mut de).map_err(|e| corrupt(&format!("cannot decode the payload: {e}")))
}

/// The checkpoint of a backend's current state.
pub fn capture(backend: &mut dyn Backend, scene_toml: &str, run: RunRecord) -> anyhow::Result<Checkpoint> {
    Ok(Checkpoint { scene_toml: scene_toml.to_string(), run, state: backend.save_state()? })
}

/// Writes the checkpoint of a backend's current state to `path`: the same bytes as [`write()`]
/// of [`capture`], with the particle arrays taken from the backend in pieces of
/// [`crate::solver::gpu::buffers::STREAM_CHUNK`] particles, so that no host copy of every array
/// is made where the backend keeps them elsewhere (the GPU).
pub fn save(backend: &mut dyn Backend, scene_toml: &str, run: &RunRecord, path: &Path) -> anyhow::Result<()> {
    write_with_state(path, scene_toml, run, |w| write_state_in_pieces(backend, w, crate::solver::gpu::buffers::STREAM_CHUNK))
}

/// Across ranks, what a rank that does not write the checkpoint does while rank 0 [`save`]s
/// it: the same requests for the state's pieces (they are collective), written nowhere.
pub fn take_part_in_save(backend: &mut dyn Backend) -> anyhow::Result<()> {
    write_state_in_pieces(backend, &mut std::io::sink(), crate::solver::gpu::buffers::STREAM_CHUNK)
}

/// Writes the postcard encoding of the backend's [`BackendState`] to `w`, the particle arrays
/// `chunk` particles at a time as the backend hands them over.
pub fn write_state_in_pieces(backend: &mut dyn Backend, w: &mut dyn std::io::Write, chunk: u64) -> anyhow::Result<()> {
    let header = backend.save_state_header()?;
    let failure = RefCell::new(None);
    let cell = RefCell::new(backend);
    let (backend, fail) = (&cell, &failure);
    let array = move |array| StateArrayInPieces { backend, array, chunk, failure: fail };
    let state = StateInPieces {
        kind: &header.kind,
        step: header.step,
        positions: array(StateArray::Positions),
        velocities: array(StateArray::Velocities),
        ids: array(StateArray::Ids),
        non_finite: header.non_finite,
        escaped: header.escaped,
        first_bad_step: header.first_bad_step,
        max_density: header.max_density,
        max_speed: header.max_speed,
        bad_step: header.bad_step,
        time: header.time,
        dt_min_max_last: header.dt_min_max_last,
        gpu_status: &header.gpu_status,
        warm_start: array(StateArray::WarmStart),
        iterations: header.iterations,
        densities: array(StateArray::Densities),
    };
    let result = postcard::to_io(&state, w);
    drop(state);
    match (result, failure.into_inner()) {
        (Ok(_), _) => Ok(()),
        (Err(_), Some(e)) => Err(e),
        (Err(e), None) => Err(anyhow::anyhow!("cannot serialise the state: {e}")),
    }
}

/// Serialises exactly as [`BackendState`] does: postcard writes a struct as its fields in
/// order, so these fields are BackendState's, in its order, with the arrays taken from the
/// backend as they are serialised (the tests compare the bytes with the whole-state checkpoint).
#[derive(Serialize)]
struct StateInPieces<'a, 'b> {
    kind: &'a str,
    step: u64,
    positions: StateArrayInPieces<'a, 'b>,
    velocities: StateArrayInPieces<'a, 'b>,
    ids: StateArrayInPieces<'a, 'b>,
    non_finite: u64,
    escaped: u64,
    first_bad_step: Option<u64>,
    max_density: f64,
    max_speed: f64,
    bad_step: Option<BadStep>,
    time: f64,
    dt_min_max_last: [f64; 3],
    gpu_status: &'a [u32],
    warm_start: StateArrayInPieces<'a, 'b>,
    iterations: crate::model::state::IterationStats,
    densities: StateArrayInPieces<'a, 'b>,
}

/// One particle array of the state, serialised as a sequence handed over piece by piece.
struct StateArrayInPieces<'a, 'b> {
    backend: &'a RefCell<&'b mut dyn Backend>,
    array: StateArray,
    chunk: u64,
    /// Why the backend failed (postcard keeps only that a custom error happened).
    failure: &'a RefCell<Option<anyhow::Error>>,
}

impl Serialize for StateArrayInPieces<'_, '_> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut backend = self.backend.borrow_mut();
        let n = backend.state_array_len(self.array);
        let mut seq = Some(serializer.serialize_seq(Some(n))?);
        let mut serialised: Result<(), S::Error> = Ok(());
        let visited = backend.visit_state_array(self.array, self.chunk, &mut |piece| {
            let seq = seq.as_mut().expect("open until the end");
            let r = match piece {
                StatePiece::Vectors(v) => v.iter().try_for_each(|x| seq.serialize_element(x)),
                StatePiece::Ids(v) => v.iter().try_for_each(|x| seq.serialize_element(x)),
                StatePiece::Pairs(v) => v.iter().try_for_each(|x| seq.serialize_element(x)),
                StatePiece::Scalars(v) => v.iter().try_for_each(|x| seq.serialize_element(x)),
            };
            r.map_err(|e| {
                let why = anyhow::anyhow!("cannot serialise the state: {e}");
                serialised = Err(e);
                why
            })
        });
        serialised?;
        if let Err(e) = visited {
            *self.failure.borrow_mut() = Some(e);
            return Err(S::Error::custom("the backend could not hand its state over"));
        }
        seq.take().expect("still open").end()
    }
}

/// Reads a checkpoint keeping only the particles whose index and position `keep` accepts (in
/// the state's order), streaming the file as [`read`] does: what one rank of several reads to
/// resume, without holding every particle. Returns the checkpoint with those particles (and
/// DFSPH's warm starts, by id in the file, those of the kept particles in their order) and
/// their indices in the saved state.
pub fn read_where(path: &Path, keep: &mut dyn FnMut(usize, [f64; 3]) -> bool) -> Result<(Checkpoint, Vec<u64>), CheckpointError> {
    let mut kept = Vec::new();
    let c = read_with(path, |de| serde::de::DeserializeSeed::deserialize(CheckpointSeed { keep, kept: &mut kept }, de))?;
    check_finite(path, &c)?;
    Ok((c, kept))
}

/// Every particle position of a checkpoint's state, in order, none kept (a rank counts them to
/// cut its slabs before it reads its part).
pub fn visit_positions(path: &Path, visit: &mut dyn FnMut([f64; 3])) -> Result<(), CheckpointError> {
    read_where(path, &mut |_, p| {
        visit(p);
        false
    })
    .map(|_| ())
}

/// A checkpoint file as a [`StateSource`]: one rank of several reads its part, streaming.
pub struct CheckpointFile<'a>(pub &'a Path);

impl StateSource for CheckpointFile<'_> {
    fn visit_positions(&mut self, visit: &mut dyn FnMut([f64; 3])) -> anyhow::Result<()> {
        Ok(visit_positions(self.0, visit)?)
    }
    fn read_kept(&mut self, keep: &mut dyn FnMut(usize, [f64; 3]) -> bool) -> anyhow::Result<(BackendState, Vec<u64>)> {
        let (c, kept) = read_where(self.0, keep)?;
        Ok((c.state, kept))
    }
}

/// Decodes a checkpoint's payload with a deserialiser `'de` of postcard over the file.
type PayloadDeserializer<'de> = postcard::Deserializer<'de, postcard::de_flavors::io::io::IOReader<'de, std::io::Take<std::io::BufReader<std::fs::File>>>>;

/// The seed of a [`Checkpoint`] whose particle arrays keep what `keep` accepts: postcard
/// stores a struct as its fields in order, so the checkpoint is read as a tuple of its fields.
struct CheckpointSeed<'k> {
    keep: &'k mut dyn FnMut(usize, [f64; 3]) -> bool,
    kept: &'k mut Vec<u64>,
}

/// The fields of [`BackendState`], in its order (the tests check a filtered read that keeps
/// every particle against [`read`]).
const STATE_FIELDS: usize = 17;

impl<'de> serde::de::DeserializeSeed<'de> for CheckpointSeed<'_> {
    type Value = Checkpoint;
    fn deserialize<D: serde::Deserializer<'de>>(self, de: D) -> Result<Checkpoint, D::Error> {
        de.deserialize_tuple(3, self)
    }
}

impl<'de> serde::de::Visitor<'de> for CheckpointSeed<'_> {
    type Value = Checkpoint;
    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("a wgsph checkpoint")
    }
    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Checkpoint, A::Error> {
        use serde::de::Error;
        let missing = || A::Error::custom("the checkpoint ends early");
        let scene_toml: String = seq.next_element()?.ok_or_else(missing)?;
        let run: RunRecord = seq.next_element()?.ok_or_else(missing)?;
        let state = seq.next_element_seed(StateSeed { keep: self.keep, kept: self.kept })?.ok_or_else(missing)?;
        Ok(Checkpoint { scene_toml, run, state })
    }
}

struct StateSeed<'k> {
    keep: &'k mut dyn FnMut(usize, [f64; 3]) -> bool,
    kept: &'k mut Vec<u64>,
}

impl<'de> serde::de::DeserializeSeed<'de> for StateSeed<'_> {
    type Value = BackendState;
    fn deserialize<D: serde::Deserializer<'de>>(self, de: D) -> Result<BackendState, D::Error> {
        de.deserialize_tuple(STATE_FIELDS, self)
    }
}

impl<'de> serde::de::Visitor<'de> for StateSeed<'_> {
    type Value = BackendState;
    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("a saved state")
    }
    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<BackendState, A::Error> {
        use serde::de::Error;
        let missing = || A::Error::custom("the saved state ends early");
        let kind = seq.next_element()?.ok_or_else(missing)?;
        let step = seq.next_element()?.ok_or_else(missing)?;
        let positions = seq.next_element_seed(KeptPositions { keep: self.keep, kept: &mut *self.kept })?.ok_or_else(missing)?;
        let kept: &[u64] = self.kept;
        let velocities = seq.next_element_seed(Kept::<[f64; 3]>::at(kept))?.ok_or_else(missing)?;
        let ids: Vec<u32> = seq.next_element_seed(Kept::<u32>::at(kept))?.ok_or_else(missing)?;
        Ok(BackendState {
            kind,
            step,
            positions,
            velocities,
            ids: ids.clone(),
            non_finite: seq.next_element()?.ok_or_else(missing)?,
            escaped: seq.next_element()?.ok_or_else(missing)?,
            first_bad_step: seq.next_element()?.ok_or_else(missing)?,
            max_density: seq.next_element()?.ok_or_else(missing)?,
            max_speed: seq.next_element()?.ok_or_else(missing)?,
            bad_step: seq.next_element()?.ok_or_else(missing)?,
            time: seq.next_element()?.ok_or_else(missing)?,
            dt_min_max_last: seq.next_element()?.ok_or_else(missing)?,
            gpu_status: seq.next_element()?.ok_or_else(missing)?,
            warm_start: seq.next_element_seed(KeptById::of(&ids))?.ok_or_else(missing)?,
            iterations: seq.next_element()?.ok_or_else(missing)?,
            densities: seq.next_element_seed(Kept::<f64>::at(kept))?.ok_or_else(missing)?,
        })
    }
}

/// The positions `keep` accepts, with their indices noted in `kept`.
struct KeptPositions<'k> {
    keep: &'k mut dyn FnMut(usize, [f64; 3]) -> bool,
    kept: &'k mut Vec<u64>,
}

impl<'de> serde::de::DeserializeSeed<'de> for KeptPositions<'_> {
    type Value = Vec<[f64; 3]>;
    fn deserialize<D: serde::Deserializer<'de>>(self, de: D) -> Result<Vec<[f64; 3]>, D::Error> {
        de.deserialize_seq(self)
    }
}

impl<'de> serde::de::Visitor<'de> for KeptPositions<'_> {
    type Value = Vec<[f64; 3]>;
    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("the positions")
    }
    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Vec<[f64; 3]>, A::Error> {
        let mut out = Vec::new();
        let mut i = 0;
        while let Some(p) = seq.next_element::<[f64; 3]>()? {
            if (self.keep)(i, p) {
                out.push(p);
                self.kept.push(i as u64);
            }
            i += 1;
        }
        Ok(out)
    }
}

/// The elements of an array by particle id at the `ids` of the kept particles, in their
/// order; an empty array stays empty (WCSPH has no warm starts).
struct KeptById {
    /// Each kept id's place among the kept particles.
    place: std::collections::HashMap<u32, usize>,
}

impl KeptById {
    fn of(ids: &[u32]) -> Self {
        KeptById { place: ids.iter().enumerate().map(|(k, &id)| (id, k)).collect() }
    }
}

impl<'de> serde::de::DeserializeSeed<'de> for KeptById {
    type Value = Vec<[f64; 2]>;
    fn deserialize<D: serde::Deserializer<'de>>(self, de: D) -> Result<Vec<[f64; 2]>, D::Error> {
        de.deserialize_seq(self)
    }
}

impl<'de> serde::de::Visitor<'de> for KeptById {
    type Value = Vec<[f64; 2]>;
    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("an array by particle id")
    }
    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Vec<[f64; 2]>, A::Error> {
        let mut out = Vec::new();
        let mut id = 0u32;
        let mut found = 0;
        while let Some(x) = seq.next_element::<[f64; 2]>()? {
            if let Some(&k) = self.place.get(&id) {
                if out.is_empty() {
                    out = vec![[f64::NAN; 2]; self.place.len()];
                }
                out[k] = x;
                found += 1;
            }
            id += 1;
        }
        if found != self.place.len() && id > 0 {
            return Err(serde::de::Error::custom(format!("the warm starts of {} of {} particles are missing", self.place.len() - found, self.place.len())));
        }
        Ok(out)
    }
}

/// The elements of a particle array at the `kept` indices (ascending); an empty array stays
/// empty (the carried densities of a scene without continuity density).
struct Kept<'k, T> {
    kept: &'k [u64],
    _element: std::marker::PhantomData<T>,
}

impl<'k, T> Kept<'k, T> {
    fn at(kept: &'k [u64]) -> Self {
        Kept { kept, _element: std::marker::PhantomData }
    }
}

impl<'de, T: Deserialize<'de>> serde::de::DeserializeSeed<'de> for Kept<'_, T> {
    type Value = Vec<T>;
    fn deserialize<D: serde::Deserializer<'de>>(self, de: D) -> Result<Vec<T>, D::Error> {
        de.deserialize_seq(self)
    }
}

impl<'de, T: Deserialize<'de>> serde::de::Visitor<'de> for Kept<'_, T> {
    type Value = Vec<T>;
    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("a particle array")
    }
    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Vec<T>, A::Error> {
        let mut out = Vec::with_capacity(self.kept.len());
        let (mut i, mut next) = (0u64, 0);
        while let Some(x) = seq.next_element::<T>()? {
            if next < self.kept.len() && self.kept[next] == i {
                out.push(x);
                next += 1;
            }
            i += 1;
        }
        Ok(out)
    }
}
