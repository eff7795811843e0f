//! The exchange stage on the CPU, the first stage of a step across ranks (before the binning):
//! particles that left the rank's slab migrate to the rank that owns their cell layer now, and
//! the particles in the ghost layers next to each face ([`halo_layers`]) travel to the neighbour as
//! ghosts, which take part in its neighbour sums but are not integrated, counted or written.
//! Alone (one process) the stage does nothing. See docs/scale-out.md.
//!
//! The particles a rank holds are put in the order one process would have them in (by the
//! cell and the place in the cell of the last binning, or by the place in the initial or
//! restored state before the first), so that the stable counting sort gives every cell the
//! same particles in the same order as one process: the neighbour sums add the same terms in
//! the same order, and N ranks compute bit for bit what one computes.

use super::ghost_velocities::{gather_ghost_velocities, scatter_ghost_velocities};
use super::resident_exchange::{OwnHealth, SlabFaces};
use super::CpuSolver;
use crate::model::initial::{FluidParticle, InitialState};
use crate::model::real::{as_arrays, Real, V3};
use crate::model::state::{BackendState, Snapshot, StepFields};
use crate::solver::backend::{StateArray, StatePiece, StateSource};
use super::probes::{self, ProbeInput};
use crate::model::probes::{Probe, ProbeGeometry};
use crate::solver::communicator::{all_max, all_sum, Communicator};
use crate::model::scene::BoundaryPressure;
use crate::solver::decomposition::{cell_runs, halo_layers, imbalance, slab_axis, RankReport, RankStats, Slabs};
use std::ops::Range;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Instant;

/// A rank's share of a simulation across ranks: its communicator and slabs, and what the
/// exchange measured.
#[derive(Clone)]
pub struct RankPart {
    pub(super) comm: Arc<dyn Communicator>,
    pub(super) slabs: Slabs,
    /// The axis the slabs cut.
    pub(super) axis: usize,
    /// Until the first binning: each slot's place in the one-process order (initial index, or
    /// index in a restored state).
    pub(super) first_order: Option<Vec<u64>>,
    /// Fluid particles of the whole simulation.
    pub(super) total_fluid: usize,
    /// Move the slab bounds towards equal counts every this many steps (0: never).
    pub(super) balance_every: u64,
    pub(super) stats: RankStats,
    /// Why this rank could not go on (a collective failed).
    pub(super) failure: Option<String>,
    /// DFSPH: the ghosts of this step's solves ([`GhostLink`]), made after the binning.
    pub(super) link: Option<GhostLink>,
    /// Where the walls near the slab come from when its bounds move.
    pub(super) walls: WallSource,
    /// Wall particles of the whole simulation.
    pub(super) total_walls: usize,
    /// The step whose bounds were balanced already (by a resident step, from the device's
    /// counts, before it fell back to the full path, whose exchange then leaves them).
    pub(super) balanced_step: Option<u64>,
}

impl RankPart {
    /// Whether step `step` may move the slab bounds (every `balance_every` steps, once).
    pub(super) fn balance_due(&self, step: u64) -> bool {
        self.balance_every > 0 && step > 0 && step % self.balance_every == 0 && self.balanced_step != Some(step)
    }

    /// The slab bounds moved towards equal counts (collective), from this rank's own particles
    /// per cell layer of the slab axis (`layers`); true where they moved. Counts the step's
    /// imbalance and the moves in the rank's stats.
    pub(super) fn balance(&mut self, layers: &[f64]) -> anyhow::Result<bool> {
        let counts: Vec<u64> = all_sum(&*self.comm, layers)?.iter().map(|&c| c as u64).collect();
        let per_rank = |s: &Slabs| -> Vec<u64> { (0..s.ranks()).map(|r| s.layers_of(r).map(|l| counts[l as usize]).sum()).collect() };
        let before = imbalance(&per_rank(&self.slabs));
        let moved = self.slabs.rebalanced(&counts);
        self.stats.last_imbalance = before;
        self.stats.max_imbalance = self.stats.max_imbalance.max(before);
        if moved == self.slabs {
            return Ok(false);
        }
        self.slabs = moved;
        self.stats.rebalances += 1;
        Ok(true)
    }

    /// Where this rank's slab lies, and which neighbours it has.
    pub(super) fn faces(&self) -> SlabFaces {
        let (rank, size) = (self.comm.rank(), self.comm.size());
        SlabFaces { axis: self.axis, slab: self.slabs.layers_of(rank), halo: self.slabs.halo, lower: rank > 0, upper: rank + 1 < size }
    }

    /// Ghosts: the own particles of `held` (taken in the order `which`) in the layers next to
    /// each face go to the neighbour on that side; returns the bytes the lower and the upper
    /// neighbour sent, and which of `held` went down and up, in that order. Collective.
    pub(super) fn exchange_ghosts<R: Real>(&self, held: &Held<R>, which: impl IntoIterator<Item = usize>, grid: &crate::model::params::Grid<R>, carried: Carried) -> anyhow::Result<(Vec<u8>, Vec<u8>, [Vec<usize>; 2])> {
        let faces = self.faces();
        let (mut down, mut up) = (Vec::new(), Vec::new());
        for i in which {
            let l = grid.layer(held.x[i], faces.axis);
            if faces.lower && l < faces.slab.start + faces.halo {
                down.push(i);
            }
            if faces.upper && l + faces.halo >= faces.slab.end {
                up.push(i);
            }
        }
        let (from_lower, from_upper) = self.comm.exchange(&held.encode(&down, carried), &held.encode(&up, carried))?;
        Ok((from_lower, from_upper, [down, up]))
    }

    /// Migration: towards the owner's side, one neighbour per round, until no rank holds a
    /// particle of another's slab (one round unless a particle crossed a whole slab). Returns the
    /// particles this rank keeps (those of `held` that stay, in their order, then those that
    /// arrived) and which of them arrived. Collective.
    pub(super) fn migrate<R: Real>(&mut self, mut held: Held<R>, grid: &crate::model::params::Grid<R>, carried: Carried) -> anyhow::Result<(Held<R>, Vec<bool>)> {
        let comm = self.comm.clone();
        let rank = comm.rank();
        let mut arrived = vec![false; held.len()];
        for round in 0.. {
            let (mut stay, mut down, mut up) = (Vec::new(), Vec::new(), Vec::new());
            for i in 0..held.len() {
                match self.slabs.owner(grid.layer(held.x[i], self.axis)).cmp(&rank) {
                    std::cmp::Ordering::Equal => stay.push(i),
                    std::cmp::Ordering::Less => down.push(i),
                    std::cmp::Ordering::Greater => up.push(i),
                }
            }
            let moving = (down.len() + up.len()) as f64;
            if all_sum(&*comm, &[moving])?[0] == 0.0 {
                break;
            }
            anyhow::ensure!(round < comm.size(), "particles still lie outside their rank's slab after {round} rounds of migration");
            self.stats.migrated += moving as u64;
            let (from_lower, from_upper) = comm.exchange(&held.encode(&down, carried), &held.encode(&up, carried))?;
            let mut next = held.picked(&stay);
            arrived = stay.iter().map(|&i| arrived[i]).collect();
            next.decode(&from_lower, carried)?;
            next.decode(&from_upper, carried)?;
            arrived.resize(next.len(), true);
            held = next;
        }
        Ok((held, arrived))
    }
}

/// Where a rank takes the wall particles near its slab from ([`WallSource::near`]).
#[derive(Clone)]
pub enum WallSource {
    /// The walls of a state given whole (`open_with`): every rank keeps a copy.
    Whole(Arc<InitialState>),
    /// The scene, which generates them: no rank holds every wall particle.
    Scene(Arc<crate::model::scene::Scene>),
}

impl WallSource {
    /// The wall particles whose cell layer along `axis` lies within `halo` + 1 layers of
    /// `slab` (the ghosts lie up to `halo` layers out, their neighbours one further), in the
    /// order of the whole scene's walls (so each cell holds the walls one process holds there,
    /// in its order). Akinci's volumes are computed over one more layer, which is then
    /// dropped, so every kept wall has all its wall neighbours.
    pub(super) fn near<R: Real>(&self, grid: &crate::model::params::Grid<R>, axis: usize, slab: Range<u32>, halo: u32) -> InitialState {
        let reach = halo + 1;
        let layer = |p: [f64; 3]| grid.layer(V3::from64(p), axis);
        let within = |reach: u32| move |p: [f64; 3]| {
            let l = layer(p);
            l + reach >= slab.start && l < slab.end + reach
        };
        match self {
            WallSource::Whole(st) => {
                let mut walls = InitialState { wall_positions: st.wall_positions.clone(), wall_masses: st.wall_masses.clone(), wall_boundaries: st.wall_boundaries.clone(), ..InitialState::default() };
                walls.retain_walls(within(reach));
                walls
            }
            WallSource::Scene(scene) => {
                let mut walls = scene.initial_walls_where(within(reach + 1));
                walls.retain_walls(within(reach));
                walls
            }
        }
    }

    /// Wall particles of the whole simulation (counted, not held).
    fn total(&self) -> usize {
        match self {
            WallSource::Whole(st) => st.wall_positions.len(),
            WallSource::Scene(scene) => {
                let count = std::cell::Cell::new(0usize);
                scene.initial_walls_where(|_| {
                    count.set(count.get() + 1);
                    false
                });
                count.get()
            }
        }
    }
}

/// DFSPH across ranks, the ghosts' part in a step's solves (docs/scale-out.md). A Jacobi step
/// changes every velocity from its neighbours' stiffnesses, and the outer layer of ghosts lacks
/// the neighbours beyond it: its new velocities are wrong, and one step later so would be the
/// inner layer's stiffnesses, which the own particles next to the face read. So after every
/// velocity change of the solves (and the prediction) the ghosts take their owners' velocities,
/// one message per neighbour; the solves' error sums and the adaptive step's maxima are the
/// ranks' together, so every rank runs the same iterations with the same dt.
#[derive(Clone)]
pub struct GhostLink {
    comm: Arc<dyn Communicator>,
    /// Own slots whose particles are ghosts of the lower and of the upper neighbour, in cell
    /// order.
    send: [Vec<usize>; 2],
    /// Ghost slots owned by the lower and by the upper neighbour, in cell order (their owner's
    /// order: both sides bin the same particles from the same order).
    receive: [Vec<usize>; 2],
    /// Which slots hold ghosts.
    pub ghosts: Vec<bool>,
    /// Why a message failed, for the rank's failure.
    pub failure: Option<String>,
    /// Seconds spent in the messages (the exchange's share of the step).
    pub seconds: f64,
    /// Where the lists are still to be made (a resident step's link), the sizes the host
    /// knows they have.
    sizes: Option<[usize; 4]>,
}

impl GhostLink {
    /// A link whose lists a device makes after its binning ([`GhostLink::with_lists`]), with
    /// the sizes the host knows they have (sent to the lower and the upper neighbour, received
    /// from each: what a resident step's exchange sent and received) and the check of its ids
    /// (timed with the exchange that made it).
    pub(super) fn unmade(comm: Arc<dyn Communicator>, sizes: [usize; 4], failure: Option<String>) -> GhostLink {
        GhostLink { comm, send: Default::default(), receive: Default::default(), ghosts: Vec::new(), failure, seconds: 0.0, sizes: Some(sizes) }
    }

    /// How many particles the lists hold: sent to the lower and to the upper neighbour, then
    /// received from each.
    pub fn list_sizes(&self) -> [usize; 4] {
        self.sizes.unwrap_or([self.send[0].len(), self.send[1].len(), self.receive[0].len(), self.receive[1].len()])
    }

    /// This link's messages with `lists` a device made from its binning (in
    /// [`list_sizes`](GhostLink::list_sizes)' order, src/solver/cpu/ghost_link.rs); an error
    /// where they hold other counts than the host's (the device binned some particle of the
    /// face layers in another layer than the host's exchange put it).
    pub fn with_lists(&self, lists: [Vec<usize>; 4]) -> Result<GhostLink, String> {
        let sizes = lists.each_ref().map(|l| l.len());
        if sizes != self.list_sizes() {
            return Err(format!("the device's binning lists {sizes:?} particles in the face layers (sent down, sent up, from below, from above) where the exchange has {:?}", self.list_sizes()));
        }
        let [down, up, below, above] = lists;
        Ok(GhostLink { comm: self.comm.clone(), send: [down, up], receive: [below, above], ghosts: Vec::new(), failure: self.failure.clone(), seconds: self.seconds, sizes: None })
    }

    /// The ghosts' velocities (or any per-particle vector) replaced by their owners'.
    pub fn sync<R: Real>(&mut self, values: &mut [V3<R>]) {
        let sent = gather_ghost_velocities(values, &self.sent_slots());
        let received = self.exchange_gathered(&sent);
        scatter_ghost_velocities(values, &self.received_slots(), &received);
    }

    /// How many values go to the neighbours, and how many ghosts take theirs.
    pub fn counts(&self) -> [usize; 2] {
        [self.send[0].len() + self.send[1].len(), self.receive[0].len() + self.receive[1].len()]
    }

    /// The slots whose values go to the lower neighbour, then those to the upper one.
    pub fn sent_slots(&self) -> Vec<usize> {
        [&self.send[0][..], &self.send[1][..]].concat()
    }

    /// The ghosts' slots, those of the lower neighbour's particles first.
    pub fn received_slots(&self) -> Vec<usize> {
        [&self.receive[0][..], &self.receive[1][..]].concat()
    }

    /// The values of [`GhostLink::sent_slots`], in that order, sent to the neighbours; returns
    /// those of [`GhostLink::received_slots`] (a ghost keeps zero where a message failed, and
    /// the failure stops the run).
    pub fn exchange_gathered<R: Real>(&mut self, sent: &[V3<R>]) -> Vec<V3<R>> {
        let t0 = Instant::now();
        // The values as their bits: what arrives is what was sent.
        let (down, up) = sent.split_at(self.send[0].len().min(sent.len()));
        let mut received = vec![V3::zero(); self.receive[0].len() + self.receive[1].len()];
        match self.comm.exchange(bytemuck::cast_slice(as_arrays(down)), bytemuck::cast_slice(as_arrays(up))) {
            Ok((lower, upper)) => {
                let mut at = 0;
                let each = std::mem::size_of::<[R; 3]>();
                for (slots, bytes) in self.receive.iter().zip([lower, upper]) {
                    if bytes.len() != each * slots.len() {
                        self.failure.get_or_insert(format!("a neighbour sent {} bytes for {} ghosts in a DFSPH solve, not {each} each", bytes.len(), slots.len()));
                    } else {
                        for (k, v) in bytes.chunks_exact(each).enumerate() {
                            received[at + k] = V3(bytemuck::pod_read_unaligned(v));
                        }
                    }
                    at += slots.len();
                }
            }
            Err(e) => {
                self.failure.get_or_insert(format!("{e:#}"));
            }
        }
        self.seconds += t0.elapsed().as_secs_f64();
        received
    }

    /// The ranks' sum of an error sum in fixed-point units, exact: the high and low 32 bits
    /// travel apart, and their sums stay far below 2^53. A failed message gives the largest
    /// sum (the solve then runs to its limit, and the failure stops the run).
    pub fn sum_units(&mut self, units: u64) -> u64 {
        let t0 = Instant::now();
        let summed = all_sum(&*self.comm, &[(units >> 32) as f64, (units & 0xffff_ffff) as f64]);
        self.seconds += t0.elapsed().as_secs_f64();
        match summed {
            Ok(v) => ((v[0] as u64) << 32).saturating_add(v[1] as u64),
            Err(e) => {
                self.failure.get_or_insert(format!("{e:#}"));
                u64::MAX
            }
        }
    }

    /// The ranks' largest of each value (NaN where a message failed).
    pub fn max(&mut self, values: &[f64]) -> Vec<f64> {
        let t0 = Instant::now();
        let out = all_max(&*self.comm, values).unwrap_or_else(|e| {
            self.failure.get_or_insert(format!("{e:#}"));
            vec![f64::NAN; values.len()]
        });
        self.seconds += t0.elapsed().as_secs_f64();
        out
    }
}

/// A link's lists over held particles `0..n`: the own particles within `halo` layers of a face
/// with a neighbour go to it (a particle of a thin slab to both), and each ghost takes its
/// values from the neighbour on its side; in the held order.
fn link_lists(n: usize, ghost: impl Fn(usize) -> bool, layer: impl Fn(usize) -> u32, faces: &SlabFaces) -> ([Vec<usize>; 2], [Vec<usize>; 2]) {
    let (mut send, mut receive): ([Vec<usize>; 2], [Vec<usize>; 2]) = Default::default();
    for i in 0..n {
        let l = layer(i);
        if ghost(i) {
            receive[(l >= faces.slab.end) as usize].push(i);
        } else {
            if faces.lower && l < faces.slab.start + faces.halo {
                send[0].push(i);
            }
            if faces.upper && l + faces.halo >= faces.slab.end {
                send[1].push(i);
            }
        }
    }
    (send, receive)
}

/// The check of a link's lists by the particles' ids, one message per neighbour: the ids a rank
/// sends to each neighbour must be those of the neighbour's ghosts on that side, in order.
/// Collective.
pub(super) fn check_link_ids(comm: &dyn Communicator, sent: [Vec<u32>; 2], ghosts: [Vec<u32>; 2]) -> Result<(), String> {
    let (lower, upper) = comm.exchange(bytemuck::cast_slice(&sent[0]), bytemuck::cast_slice(&sent[1])).map_err(|e| format!("{e:#}"))?;
    if lower == bytemuck::cast_slice::<u32, u8>(&ghosts[0]) && upper == bytemuck::cast_slice::<u32, u8>(&ghosts[1]) {
        Ok(())
    } else {
        Err(format!("its ghosts in cell order are not its neighbours' particles in theirs ({} and {} received, {} and {} held)", lower.len() / 4, upper.len() / 4, ghosts[0].len(), ghosts[1].len()))
    }
}

/// What a particle carries through the exchange besides its position, velocity, id and place.
#[derive(Clone, Copy)]
pub struct Carried {
    /// The carried density (continuity density).
    pub density: bool,
    /// DFSPH's warm-start stiffnesses (constant-density and divergence solves), kept by the
    /// particle's owner.
    pub warm: bool,
}

/// Bytes per particle in a message, in the run's float type `R`: position and velocity (six
/// values), id (4 bytes), place in the one-process order (8 bytes), with continuity density the
/// carried density, with DFSPH the two warm-start stiffnesses (a value each). The values travel
/// as their bits (what arrives is what was sent; an f32 run's messages are half what f64 words
/// made them), in the sending machine's byte order: the ranks of a run must share one (x86-64
/// and 64-bit ARM are both little-endian).
fn particle_bytes<R: Real>(carried: Carried) -> usize {
    (6 + carried.density as usize + 2 * carried.warm as usize) * std::mem::size_of::<R>() + 12
}

/// Appends the bits of `field(i)` for each of `which` to a message.
fn put_field<T: bytemuck::Pod>(out: &mut Vec<u8>, which: &[usize], field: impl Fn(usize) -> T) {
    let start = out.len();
    out.resize(start + which.len() * std::mem::size_of::<T>(), 0);
    for (bytes, &i) in out[start..].chunks_exact_mut(std::mem::size_of::<T>()).zip(which) {
        bytes.copy_from_slice(bytemuck::bytes_of(&field(i)));
    }
}

/// The `n` values of one field of a message, from byte `*at` on (moved past them).
fn take_field<'a, T: bytemuck::Pod>(bytes: &'a [u8], n: usize, at: &mut usize) -> impl Iterator<Item = T> + 'a {
    let part = &bytes[*at..*at + n * std::mem::size_of::<T>()];
    *at += part.len();
    part.chunks_exact(std::mem::size_of::<T>()).map(bytemuck::pod_read_unaligned)
}

/// Particles on their way through the exchange, as a structure of arrays: position, velocity,
/// id, with continuity density the carried density, with DFSPH the warm starts, and each
/// particle's place in the one-process order (cell << 32 | place in the cell of the last
/// binning, or its place in the initial or restored state before the first).
#[derive(Clone, Default)]
pub struct Held<R: Real> {
    pub x: Vec<V3<R>>,
    pub v: Vec<V3<R>>,
    pub id: Vec<u32>,
    pub rho: Vec<R>,
    /// DFSPH: the warm-start stiffnesses (constant density, divergence).
    pub warm: Vec<[R; 2]>,
    pub order: Vec<u64>,
}

impl<R: Real> Held<R> {
    pub fn len(&self) -> usize {
        self.x.len()
    }
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }
    /// Room for `n` more particles in each array the particles carry.
    pub fn reserve(&mut self, n: usize, carried: Carried) {
        self.x.reserve(n);
        self.v.reserve(n);
        self.id.reserve(n);
        self.order.reserve(n);
        if carried.density {
            self.rho.reserve(n);
        }
        if carried.warm {
            self.warm.reserve(n);
        }
    }
    pub(super) fn push_from(&mut self, o: &Held<R>, i: usize) {
        self.x.push(o.x[i]);
        self.v.push(o.v[i]);
        self.id.push(o.id[i]);
        if !o.rho.is_empty() {
            self.rho.push(o.rho[i]);
        }
        if !o.warm.is_empty() {
            self.warm.push(o.warm[i]);
        }
        self.order.push(o.order[i]);
    }
    /// The particles `which`, as a message ([`particle_bytes`] each), field by field: the
    /// positions of all, then their velocities, and so on.
    pub(super) fn encode(&self, which: &[usize], carried: Carried) -> Vec<u8> {
        let mut out = Vec::with_capacity(which.len() * particle_bytes::<R>(carried));
        put_field(&mut out, which, |i| self.x[i].0);
        put_field(&mut out, which, |i| self.v[i].0);
        put_field(&mut out, which, |i| self.id[i]);
        put_field(&mut out, which, |i| self.order[i]);
        if carried.density {
            put_field(&mut out, which, |i| self.rho[i]);
        }
        if carried.warm {
            put_field(&mut out, which, |i| self.warm[i]);
        }
        out
    }
    /// The particles of a message [`Held::encode`] made, appended.
    pub(super) fn decode(&mut self, bytes: &[u8], carried: Carried) -> anyhow::Result<()> {
        let each = particle_bytes::<R>(carried);
        anyhow::ensure!(bytes.len() % each == 0, "a neighbour sent {} bytes, not a whole number of particles of {each} bytes", bytes.len());
        let (n, at) = (bytes.len() / each, &mut 0);
        self.reserve(n, carried);
        self.x.extend(take_field(bytes, n, at).map(V3));
        self.v.extend(take_field(bytes, n, at).map(V3));
        self.id.extend(take_field::<u32>(bytes, n, at));
        self.order.extend(take_field::<u64>(bytes, n, at));
        if carried.density {
            self.rho.extend(take_field::<R>(bytes, n, at));
        }
        if carried.warm {
            self.warm.extend(take_field::<[R; 2]>(bytes, n, at));
        }
        Ok(())
    }
    /// Sorted by the one-process order (the places are unique). The particles come as a few
    /// runs already in that order (those that stayed, each neighbour's migrants and ghosts),
    /// which a stable sort finds and merges in about one pass, where an unstable one sorts
    /// them afresh.
    pub(super) fn sorted(self) -> Held<R> {
        let mut idx: Vec<usize> = (0..self.len()).collect();
        idx.sort_by_key(|&i| self.order[i]);
        self.picked(&idx)
    }
    /// The particles `which`, in that order (array by array: a gather each, where a particle
    /// at a time pushed to six arrays and asked which it carries).
    pub(super) fn picked(&self, which: &[usize]) -> Held<R> {
        fn gather<T: Copy>(from: &[T], which: &[usize]) -> Vec<T> {
            if from.is_empty() {
                return Vec::new();
            }
            which.iter().map(|&i| from[i]).collect()
        }
        Held { x: gather(&self.x, which), v: gather(&self.v, which), id: gather(&self.id, which), rho: gather(&self.rho, which), warm: gather(&self.warm, which), order: gather(&self.order, which) }
    }
}

/// The stages of a step that run on a device across ranks: after the host's exchange, the
/// binning, density, forces and integration of the held particles (own and ghosts, in the
/// one-process order), which come back in cell order with the cell starts of that binning and
/// the density stage's densities and pressures. The host keeps the exchange, the health and
/// the bookkeeping, so both paths share them.
pub trait DeviceStages<R: Real>: Send {
    /// The device in words (the summary's adapter).
    fn describe(&self) -> String;
    /// The wall particles near the rank's slab (again whenever its bounds move), in the
    /// order of the whole scene's walls.
    fn set_walls(&mut self, walls: &InitialState);
    /// Runs step `step` on `held` and writes the result back into it; returns the step's dt
    /// (with adaptive dt chosen from every rank's own particles, the ghosts left out).
    fn run_step(&mut self, step: u64, held: HeldArrays<'_, R>) -> anyhow::Result<f64>;
    /// The binning and density stage of `held` at step `step`, without advancing it (for a
    /// snapshot), written back the same way.
    fn run_fields(&mut self, step: u64, held: HeldArrays<'_, R>) -> anyhow::Result<()>;
    /// A device that keeps the held particles after a step (src/solver/cpu/resident_steps.rs):
    /// the band of the state its last step left, for the rank's slab `faces` (`None` where it
    /// keeps none, or the band outgrows its room).
    fn resident_band(&mut self, _faces: &SlabFaces) -> anyhow::Result<Option<ResidentBand<R>>> {
        Ok(None)
    }
    /// Step `step` from the state the device kept, without its `dropped` slots (sorted) and with
    /// the `received` particles (sorted in the one-process order; `ghosts` says which are
    /// ghosts; with DFSPH carrying their warm starts, and `solves` what the host keeps of the
    /// solves); `None`, and nothing changed, where they do not fit the device's arrays.
    fn run_resident_step(&mut self, _step: u64, _dropped: &[u32], _received: &Held<R>, _ghosts: &[bool], _solves: Option<ResidentSolves<'_>>) -> anyhow::Result<Option<ResidentStep>> {
        Ok(None)
    }
    /// The state the device kept, read back into `held` as a step writes it back.
    fn read_held(&mut self, _held: HeldArrays<'_, R>) -> anyhow::Result<()> {
        anyhow::bail!("this device keeps no particles between steps")
    }
    /// The own particles (ghosts left out) per cell layer along `axis` of the state the device
    /// kept (`None` where it keeps none), for a step that may move the slab bounds.
    fn own_layer_counts(&mut self, _axis: usize) -> anyhow::Result<Option<Vec<u32>>> {
        Ok(None)
    }
    /// The walls near the slab replaced by `walls` where they fit the device's buffers, the
    /// state it kept left as it is; false, and nothing changed, where they do not.
    fn replace_walls(&mut self, _walls: &InitialState) -> bool {
        false
    }
    /// The probes' rows the device sampled since the last call (a scene with probes:
    /// `CpuSolver::probes_on_device`), each its step and every column over the held particles,
    /// the ghosts left out of the forces and fronts.
    fn take_probe_rows(&mut self) -> anyhow::Result<Vec<(u64, Vec<f64>)>> {
        Ok(Vec::new())
    }
    /// Bytes of particles that crossed between the host and the device so far, both ways.
    fn bus_bytes(&self) -> u64 {
        0
    }
}

/// The band of a resident step (see [`DeviceStages::resident_band`]): the slots the rank drops
/// (its ghosts and the own particles that left its slab), sorted, and the band's particles (the
/// leaving ones and those next to a face), in the one-process order, with their slots.
pub struct ResidentBand<R: Real> {
    pub dropped: Vec<u32>,
    pub slots: Vec<u32>,
    pub particles: Held<R>,
}

/// DFSPH on a resident step: what the host keeps of the solves (as [`DfsphHeld`]), and the
/// step's link, checked by the host and made by the device from its binning on the slab
/// `faces`.
pub struct ResidentSolves<'a> {
    pub stats: &'a mut crate::model::state::IterationStats,
    pub link: &'a mut GhostLink,
    pub faces: SlabFaces,
    pub particles: usize,
}

/// What a resident step gives back: its dt and the own particles' health.
pub struct ResidentStep {
    pub dt: f64,
    pub health: OwnHealth,
}

/// Shared so that a cloned solver stays cloneable; a rank's solver is never cloned mid-run.
pub type SharedDeviceStages<R> = Arc<Mutex<Box<dyn DeviceStages<R>>>>;

/// The device stages, also after a panic elsewhere poisoned the lock (their state is whole
/// between calls).
pub fn lock<R: Real>(device: &SharedDeviceStages<R>) -> MutexGuard<'_, Box<dyn DeviceStages<R>>> {
    device.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}

/// Where a rank finds its part of the initial state.
#[derive(Clone, Copy)]
pub(crate) enum InitialSource<'a> {
    /// A state given whole to every rank (`open_with`: a library caller's own particles).
    Whole(&'a InitialState),
    /// The scene: every rank generates its particles one at a time and keeps its own.
    Scene(&'a crate::model::scene::Scene),
}

impl InitialSource<'_> {
    /// Every fluid particle in original order, one at a time.
    fn visit_fluid(&self, mut visit: impl FnMut(FluidParticle)) {
        match self {
            InitialSource::Whole(st) => {
                for (i, (&position, &velocity)) in st.fluid_positions.iter().zip(&st.fluid_velocities).enumerate() {
                    visit(FluidParticle { id: i as u64, position, velocity, density: st.fluid_densities.get(i).copied() });
                }
            }
            InitialSource::Scene(scene) => scene.visit_fluid(visit),
        }
    }

    /// Where the rank's walls come from.
    pub(crate) fn walls(&self) -> WallSource {
        match self {
            InitialSource::Whole(st) => WallSource::Whole(Arc::new(InitialState {
                wall_positions: st.wall_positions.clone(),
                wall_masses: st.wall_masses.clone(),
                wall_boundaries: st.wall_boundaries.clone(),
                ..InitialState::default()
            })),
            InitialSource::Scene(scene) => WallSource::Scene(Arc::new((*scene).clone())),
        }
    }
}

/// The particles a rank holds, handed to the device stages (see [`DeviceStages`]).
pub struct HeldArrays<'a, R: Real> {
    pub positions: &'a mut Vec<V3<R>>,
    pub velocities: &'a mut Vec<V3<R>>,
    pub ids: &'a mut Vec<u32>,
    /// Empty without continuity density.
    pub carried_densities: &'a mut Vec<R>,
    pub densities: &'a mut Vec<R>,
    pub pressures: &'a mut Vec<R>,
    /// Cells + 1 values, written by the device.
    pub starts: &'a mut Vec<u32>,
    /// Which of the particles handed over are ghosts (a neighbour's particles), in their order.
    pub ghosts: &'a [bool],
    /// DFSPH: what the host keeps of the solves between steps.
    pub dfsph: Option<DfsphHeld<'a, R>>,
}

/// DFSPH across ranks on a device: what the host keeps of the solves, lent with the held
/// particles.
pub struct DfsphHeld<'a, R: Real> {
    /// The warm-start stiffnesses (constant density, divergence), at `warm_keys[slot]` for each
    /// held slot; given back by the place of each particle in the upload, with `warm_keys` set
    /// to that place.
    pub warm_pressure: &'a mut Vec<R>,
    pub warm_divergence: &'a mut Vec<R>,
    pub warm_keys: &'a mut Vec<u32>,
    /// The solves' iterations so far (a step adds its own).
    pub stats: &'a mut crate::model::state::IterationStats,
    /// The last step's dt (adaptive dt: the divergence solve and the output pressure read it).
    pub last_dt: f64,
    /// The step's ghosts in the solves ([`GhostLink`], in the held order); a step leaves it in
    /// the device's order, with its messages' seconds and failure. `None` for the fields.
    pub link: Option<&'a mut GhostLink>,
    /// The fluid particles of the whole simulation (the solves' average error is over them).
    pub particles: usize,
    /// The rank's slab, whose face layers the link lists.
    pub faces: Option<SlabFaces>,
    /// Given by a step that samples the probes, for the velocities the prediction started from
    /// (after the divergence solve), in the device's order (the force probes' viscous part).
    pub prediction_start: Option<&'a mut Vec<V3<R>>>,
}

impl<R: Real> CpuSolver<R> {
    /// One rank's part on a device: like [`CpuSolver::new_part`], with the step's stages after
    /// the exchange run by `device`.
    pub(crate) fn new_part_on(params: &crate::model::params::Params, initial: InitialSource<'_>, comm: Arc<dyn Communicator>, balance_every: u64, device: Box<dyn DeviceStages<R>>) -> anyhow::Result<Self> {
        Self::new_part_with(params, initial, comm, balance_every, Some(device))
    }

    /// The wall particles near this rank's slab, from the scene (or the whole state given).
    pub(super) fn walls_near_slab(&self) -> InitialState {
        let part = self.ranks.as_deref().expect("across ranks");
        part.walls.near(&self.grid, part.axis, part.slabs.layers_of(part.comm.rank()), part.slabs.halo)
    }

    /// The held arrays, lent to the device stages, with which of them are `ghosts` (and with
    /// DFSPH, the step's ghost link, and the room for the velocities the prediction started
    /// from where the step samples probes).
    pub(super) fn held_arrays<'a>(&'a mut self, ghosts: &'a [bool], with_link: bool, prediction_start: bool) -> HeldArrays<'a, R> {
        let particles = self.ranks.as_ref().map_or(self.positions.len(), |part| part.total_fluid);
        let faces = self.ranks.as_deref().map(|part| part.faces());
        let link = match with_link {
            true => self.ranks.as_deref_mut().and_then(|part| part.link.as_mut()),
            false => None,
        };
        HeldArrays {
            ghosts,
            dfsph: self.dfsph.as_mut().map(|d| DfsphHeld {
                warm_pressure: &mut d.warm_pressure,
                warm_divergence: &mut d.warm_divergence,
                warm_keys: &mut self.warm_keys,
                stats: &mut d.stats,
                last_dt: d.last_dt,
                link,
                particles,
                faces,
                prediction_start: if prediction_start { Some(&mut self.scratch_v3) } else { None },
            }),
            positions: &mut self.positions,
            velocities: &mut self.velocities,
            ids: &mut self.ids,
            carried_densities: &mut self.carried_densities,
            densities: &mut self.densities,
            pressures: &mut self.pressures,
            starts: &mut self.starts,
        }
    }

    /// The device's binning and density of the held particles (a snapshot's fields).
    fn fields_on_device(&mut self) {
        self.lists.clear();
        let step = self.step;
        let ghosts = self.ghost_flags();
        let ran = self.on_device(|s, device| device.run_fields(step, s.held_arrays(&ghosts, false, false)));
        if let Err(e) = ran {
            if let Some(part) = &mut self.ranks {
                part.failure.get_or_insert(format!("rank {} of {}: the device's density stage failed: {e:#}", part.comm.rank(), part.comm.size()));
            }
        }
    }

    /// A step whose stages after the exchange run on the device; the health is taken from the
    /// own particles the device gave back, and reduced over the ranks as on the host. True
    /// where the device ran it (and keeps what it gave back).
    pub(super) fn step_on_device(&mut self) -> bool {
        // Probes are sampled on the host from the state the step starts from: the device bins it
        // and evaluates its density stage (as for a snapshot), and the CPU path's probe stage
        // reads the result with its own particles counted (probes_across_ranks). A device that
        // failed here has recorded its rank's failure; the collectives below still run, so no
        // rank waits for it, and the step's health stops every rank.
        // With DFSPH, as on the CPU path, the point probes (and the rest, to be sampled again) now,
        // the force and front probes after the solves, on the step's first positions.
        let dfsph = self.dfsph.is_some();
        let mut dfsph_points = None;
        let sampling = self.probes_due();
        let on_device = self.probes_on_device();
        if sampling && !on_device {
            self.fields_on_device();
            self.compute_wall_pressure();
            match dfsph {
                true => dfsph_points = Some(self.sample_probe_points()),
                false => self.sample_probes(),
            }
        }
        // The binned state's positions: the step bins them again in the same order (its binning
        // is stable and they are sorted), so its slots are these.
        let first_positions = dfsph_points.is_some().then(|| self.positions.clone());
        self.lists.clear();
        let step = self.step;
        let ghosts = self.ghost_flags();
        // DFSPH: the ghosts' part in the solves, in the held order (the device follows its own
        // binning with it).
        if dfsph {
            self.link_ghosts();
        }
        let ran = self.on_device(|s, device| device.run_step(step, s.held_arrays(&ghosts, dfsph, first_positions.is_some())));
        self.unlink_ghosts();
        let dt = match ran {
            Ok(dt) => dt,
            Err(e) => {
                if let Some(part) = &mut self.ranks {
                    part.failure.get_or_insert(format!("rank {} of {}: the device step failed: {e:#}", part.comm.rank(), part.comm.size()));
                }
                return false;
            }
        };

        if let Some(d) = &mut self.dfsph {
            d.last_dt = dt;
            d.dt = dt;
        }
        if let (Some(values), Some(mut positions)) = (dfsph_points, first_positions) {
            self.sample_dfsph_forces_on_device(values, dt, &mut positions);
        }
        if sampling && on_device {
            self.sample_probes_from_device();
        } else if sampling {
            // The host sampled them: the device's own rows are not used (read, so that its row
            // buffer never fills).
            let _ = self.on_device(|_, device| device.take_probe_rows());
        }
        let n = self.positions.len();
        self.accelerations.resize(n, V3::zero());
        let domain = (V3::<R>::from64(self.params.domain_min), V3::<R>::from64(self.params.domain_max));
        let mut found = super::integrate::StepHealth::default();
        for own in self.own_slots() {
            for i in own {
                let (x, v) = (self.positions[i], self.velocities[i]);
                let finite = x.is_finite() && v.is_finite();
                let inside = (0..3).all(|k| x.0[k] >= domain.0 .0[k] && x.0[k] <= domain.1 .0[k]);
                let speed = if finite { v.length().to64() } else { 0.0 };
                found = found.add(super::integrate::StepHealth { non_finite: (!finite) as u32, escaped: (finite && !inside) as u32, max_speed: speed });
            }
        }
        let max_density = self.largest_density();
        let (found, max_density) = self.all_step_health(found, max_density);
        self.health.max_density = self.health.max_density.max(max_density);
        self.record_step(dt, found, max_density);
        true
    }

    /// DFSPH on device ranks, after a step that samples the probes: the force and front probes
    /// from the step's first `positions` (the binned state's, in the same slots), the solves'
    /// stiffness sums (which the device gave back as the warm starts) and the velocities the
    /// prediction started from (given back for this step).
    fn sample_dfsph_forces_on_device(&mut self, values: Vec<f64>, dt: f64, positions: &mut Vec<V3<R>>) {
        let n = self.positions.len();
        let Some(d) = self.dfsph.as_mut() else { return };
        if positions.len() != n || self.scratch_v3.len() != n {
            // Only where the device gave back less than it was asked for (its failure stops the
            // run): the probes' collectives still run, so that no rank waits.
            self.scratch_v3.resize(n, V3::zero());
            positions.resize(n, V3::zero());
        }
        let key = |slot: usize| self.warm_keys.get(slot).map_or(slot, |&k| k as usize);
        d.pressure_sum = (0..n).map(|slot| d.warm_pressure.get(key(slot)).copied().unwrap_or(R::zero())).collect();
        d.divergence_sum = (0..n).map(|slot| d.warm_divergence.get(key(slot)).copied().unwrap_or(R::zero())).collect();
        std::mem::swap(&mut self.positions, positions);
        self.sample_dfsph_forces(values, dt);
        std::mem::swap(&mut self.positions, positions);
    }

    /// DFSPH across ranks: this step's [`GhostLink`] (which slots to send to each neighbour and
    /// which to receive), checked once by the particles' ids; on the CPU path after the binning,
    /// with device stages in the order of the upload (the device puts it in its own cell order).
    /// Where a resident step that fell back to this path has checked the step's link already,
    /// its lists are made again without a second check, so that every rank exchanges as many
    /// messages.
    pub(super) fn link_ghosts(&mut self) {
        let Some(part) = self.ranks.as_deref() else { return };
        let faces = part.faces();
        let ghosts = self.ghost_flags();
        let layer = |i: usize| self.grid.layer(self.positions[i], faces.axis);
        let (send, receive) = link_lists(self.positions.len(), |i| ghosts[i], layer, &faces);
        let (failure, seconds) = part.link.as_ref().map_or((None, 0.0), |l| (l.failure.clone(), l.seconds));
        let checked = part.link.is_some();
        let mut link = GhostLink { comm: part.comm.clone(), send, receive, ghosts, failure, seconds, sizes: None };
        if !checked {
            let t0 = Instant::now();
            let ids = |slots: &[usize]| slots.iter().map(|&i| self.ids[i]).collect::<Vec<u32>>();
            let sent = [ids(&link.send[0]), ids(&link.send[1])];
            let held = [ids(&link.receive[0]), ids(&link.receive[1])];
            if let Err(e) = check_link_ids(&*link.comm, sent, held) {
                link.failure.get_or_insert(e);
            }
            link.seconds += t0.elapsed().as_secs_f64();
        }
        self.ranks.as_deref_mut().expect("across ranks").link = Some(link);
    }

    /// Whether each rank's device samples the probes (across ranks on devices): wgsl/sim/
    /// probes.wgsl runs on the held particles within the step, as on one device (with DFSPH the
    /// points after the factors, the rest after the solves), and the host adds the ranks' rows
    /// ([`device_probes_across_ranks`]), so a step that samples probes needs no particle on
    /// the host and may stay resident. A scene with a gauge whose vertical line crosses the
    /// slabs (cut along y) is sampled on the host instead, level by level.
    pub(super) fn probes_on_device(&self) -> bool {
        let Some(part) = self.ranks.as_deref() else { return false };
        let gauge = || self.params.probes.probes.iter().any(|p| matches!(p.geometry, ProbeGeometry::Gauge { .. }));
        self.device.is_some() && !self.params.probes.is_empty() && !(part.axis == 1 && gauge())
    }

    /// After a device step that sampled the probes ([`Self::probes_on_device`]): the device's
    /// row of this step, added over the ranks. A rank whose device gave no row still takes
    /// part in the collectives (with zeros and a flag that it failed), so no rank waits; every
    /// rank then leaves the step's sample out and stops, the failed one with its error.
    pub(super) fn sample_probes_from_device(&mut self) {
        let (step, count) = (self.step, self.params.probes.value_count());
        let rows = self.on_device(|_, device| device.take_probe_rows());
        let (device, mut failure) = match rows.map(|rows| rows.into_iter().find(|r| r.0 == step)) {
            Ok(Some((_, values))) if values.len() == count => (values, None),
            Ok(_) => (vec![0.0; count], Some(format!("the device sampled no probe row of step {step}"))),
            Err(e) => (vec![0.0; count], Some(format!("reading the device's probe rows failed: {e:#}"))),
        };
        let part = self.ranks.as_deref().expect("across ranks");
        if let Some(e) = failure.as_mut() {
            *e = format!("rank {} of {}: {e}", part.comm.rank(), part.comm.size());
        }
        let grid = self.grid;
        let evaluates = |x: [f64; 3]| part.slabs.owner(grid.layer(V3::<R>::from64(x), part.axis)) == part.comm.rank();
        let p = &self.params.probes;
        let t0 = Instant::now();
        let (values, reduced) = device_probes_across_ranks(&*part.comm, &p.probes, &p.offsets(), device, failure.is_some(), evaluates);
        if let Some(part) = self.ranks.as_deref_mut() {
            part.stats.exchange_seconds += t0.elapsed().as_secs_f64();
        }
        match failure.or(reduced) {
            Some(e) => self.note_failure(Some(e)),
            None => self.push_probe_sample(values),
        }
    }

    /// Every probe's values read from `input` by the ranks together ([`probes_across_ranks`]),
    /// and the error of a failed collective.
    pub(super) fn probes_on_ranks(&self, input: &ProbeInput<R>) -> (Vec<f64>, Option<String>) {
        let part = self.ranks.as_deref().expect("across ranks");
        let p = &self.params.probes;
        probes_across_ranks(input, part, &self.own_slots(), &p.probes, &p.offsets())
    }

    /// Keeps the first failure of this rank (across ranks; alone nothing fails this way).
    pub(super) fn note_failure(&mut self, failure: Option<String>) {
        if let (Some(e), Some(part)) = (failure, self.ranks.as_mut()) {
            part.failure.get_or_insert(e);
        }
    }

    /// A call to the rank's device (`call` with this solver and the locked device), counted in
    /// the rank's device time less what the DFSPH solves inside it spent exchanging across ranks
    /// (that goes to the exchange time when the link is undone).
    pub(super) fn on_device<T>(&mut self, call: impl FnOnce(&mut Self, &mut dyn DeviceStages<R>) -> T) -> T {
        let device = self.device.clone().expect("only with device stages");
        let (started, linked) = (Instant::now(), self.link_seconds());
        let out = call(self, &mut **lock(&device));
        let exchanged = self.link_seconds() - linked;
        if let Some(part) = self.ranks.as_deref_mut() {
            part.stats.device_seconds += (started.elapsed().as_secs_f64() - exchanged).max(0.0);
        }
        out
    }

    fn link_seconds(&self) -> f64 {
        self.ranks.as_deref().and_then(|p| p.link.as_ref()).map_or(0.0, |link| link.seconds)
    }

    /// After a DFSPH step across ranks: what its link measured and met goes to the rank's.
    pub(super) fn unlink_ghosts(&mut self) {
        let Some(part) = self.ranks.as_deref_mut() else { return };
        if let Some(link) = part.link.take() {
            part.stats.exchange_seconds += link.seconds;
            if let Some(e) = link.failure {
                part.failure.get_or_insert(format!("rank {} of {}: {e}", part.comm.rank(), part.comm.size()));
            }
        }
    }

    /// Which held particles are ghosts: those outside this rank's slab (the exchange's own
    /// test, on the same positions; before or after the binning).
    fn ghost_flags(&self) -> Vec<bool> {
        let Some(part) = &self.ranks else { return Vec::new() };
        let mine = part.slabs.layers_of(part.comm.rank());
        self.positions.iter().map(|&x| !mine.contains(&self.grid.layer(x, part.axis))).collect()
    }

    /// The solver of one rank's part of a simulation across the ranks of `comm`: the fluid
    /// particles of `initial` whose cell layer lies in this rank's slab (slabs of equal
    /// counts), and the wall particles near it. `balance_every`: steps between moves of the
    /// slab bounds (0: never). From a scene, the particles are generated one at a time (the
    /// fluid twice: to count it per layer, then to keep this rank's), so no rank holds every
    /// particle.
    pub(crate) fn new_part(params: &crate::model::params::Params, initial: InitialSource<'_>, comm: Arc<dyn Communicator>, balance_every: u64) -> anyhow::Result<Self> {
        Self::new_part_with(params, initial, comm, balance_every, None)
    }

    /// [`CpuSolver::new_part`], with the stages after the exchange on `device` where given.
    fn new_part_with(params: &crate::model::params::Params, initial: InitialSource<'_>, comm: Arc<dyn Communicator>, balance_every: u64, device: Option<Box<dyn DeviceStages<R>>>) -> anyhow::Result<Self> {
        let grid = params.grid.cast::<R>();
        let axis = slab_axis(grid.dims);
        let layer_of = |p: [f64; 3]| grid.layer(V3::from64(p), axis);
        let mut counts = vec![0u64; grid.dims[axis] as usize];
        initial.visit_fluid(|p| counts[layer_of(p.position) as usize] += 1);
        let total = counts.iter().sum::<u64>() as usize;
        let slabs = Slabs::balanced(&counts, comm.size(), halo_layers(params.boundary_pressure == BoundaryPressure::Adami, params.surface_tension > 0.0))?;
        let mine = slabs.layers_of(comm.rank());
        let walls = initial.walls();
        let mut part = walls.near(&grid, axis, mine.clone(), slabs.halo);
        let mut chosen = Vec::new();
        initial.visit_fluid(|p| {
            if mine.contains(&layer_of(p.position)) {
                chosen.push(p.id);
                part.fluid_positions.push(p.position);
                part.fluid_velocities.push(p.velocity);
                if let Some(d) = p.density {
                    part.fluid_densities.push(d);
                }
            }
        });
        let mut solver = Self::new(params, &part);
        if let Some(mut device) = device {
            device.set_walls(&part);
            solver.device = Some(Arc::new(Mutex::new(device)));
        }
        solver.ids = chosen.iter().map(|&i| i as u32).collect();
        if solver.dfsph.is_some() {
            // In the held particles' order (they start from zero, as alone).
            solver.warm_keys = (0..chosen.len() as u32).collect();
        }
        let counts_per_rank: Vec<u64> = (0..comm.size()).map(|r| slabs.layers_of(r).map(|l| counts[l as usize]).sum()).collect();
        let start_imbalance = imbalance(&counts_per_rank);
        solver.ranks = Some(Box::new(RankPart {
            comm,
            slabs,
            axis,
            first_order: Some(chosen),
            total_fluid: total,
            balance_every,
            stats: RankStats { last_imbalance: start_imbalance, max_imbalance: start_imbalance, ..RankStats::default() },
            failure: None,
            link: None,
            total_walls: walls.total(),
            walls,
            balanced_step: None,
        }));
        Ok(solver)
    }

    /// The slots of this rank's own particles, as ranges of the cell-sorted arrays: all of
    /// them alone, and across ranks those of its slab's cells (one range for slabs across z,
    /// one per row of cells otherwise; the ghosts lie outside them).
    pub(super) fn own_slots(&self) -> Vec<Range<usize>> {
        match &self.ranks {
            Some(part) if part.first_order.is_none() => self
                .own_cells(part)
                .into_iter()
                .map(|cells| self.starts[cells.start] as usize..self.starts[cells.end] as usize)
                .filter(|slots| !slots.is_empty())
                .collect(),
            _ => vec![0..self.positions.len()],
        }
    }

    /// The runs of cell keys of this rank's slab.
    fn own_cells(&self, part: &RankPart) -> Vec<Range<usize>> {
        cell_runs(self.grid.dims, part.axis, part.slabs.layers_of(part.comm.rank()))
    }

    /// This rank's part, when the simulation runs across ranks.
    pub fn rank_report(&self) -> Option<RankReport> {
        let p = self.ranks.as_ref()?;
        Some(RankReport {
            rank: p.comm.rank(),
            ranks: p.comm.size(),
            transport: p.comm.describe(),
            axis: p.axis,
            bounds: p.slabs.bounds.clone(),
            own_particles: self.own_count(),
            walls: self.walls().0.len(),
            node_rank: p.comm.node_rank().0,
            node_ranks: p.comm.node_rank().1,
            threads: rayon::current_num_threads(),
            adapter: crate::solver::backend::Backend::adapter(self),
            stats: RankStats { bus_bytes: self.device.as_ref().map_or(0, |d| lock(d).bus_bytes()), ..p.stats.clone() },
        })
    }

    /// Why this rank stopped, when a collective failed.
    pub(super) fn rank_failure(&self) -> Option<&str> {
        self.ranks.as_ref().and_then(|p| p.failure.as_deref())
    }

    /// The exchange stage: migration, then ghosts (nothing alone). `balance`: whether the
    /// slab bounds may move at this step (the steps' exchanges, not a snapshot's).
    pub(super) fn exchange(&mut self, balance: bool) {
        if self.ranks.is_none() {
            return;
        }
        let t0 = Instant::now();
        if let Err(e) = self.exchange_across_ranks(balance) {
            if let Some(part) = &mut self.ranks {
                part.failure.get_or_insert(format!("{e:#}"));
            }
        }
        if let Some(part) = &mut self.ranks {
            part.stats.exchange_seconds += t0.elapsed().as_secs_f64();
        }
    }

    /// The own particles with their places in the one-process order (ghosts dropped).
    fn own_particles(&mut self) -> Held<R> {
        let own = self.own_slots();
        let part = self.ranks.as_mut().expect("only across ranks");
        let order: Vec<u64> = match part.first_order.take() {
            Some(order) => order,
            None => {
                // Cell key and place in the cell, from the cell starts of the last binning.
                let part = self.ranks.as_ref().expect("only across ranks");
                let mut order = Vec::new();
                for cells in self.own_cells(part) {
                    for cell in cells {
                        let (a, b) = (self.starts[cell], self.starts[cell + 1]);
                        order.extend((0..b - a).map(|k| ((cell as u64) << 32) | k as u64));
                    }
                }
                order
            }
        };
        let mut held = Held { order, ..Held::default() };
        for slots in own {
            held.x.extend_from_slice(&self.positions[slots.clone()]);
            held.v.extend_from_slice(&self.velocities[slots.clone()]);
            held.id.extend_from_slice(&self.ids[slots.clone()]);
            if !self.carried_densities.is_empty() {
                held.rho.extend_from_slice(&self.carried_densities[slots.clone()]);
            }
            if let Some(d) = &self.dfsph {
                held.warm.extend(self.warm_keys[slots].iter().map(|&k| [d.warm_pressure[k as usize], d.warm_divergence[k as usize]]));
            }
        }
        held
    }

    fn exchange_across_ranks(&mut self, balance: bool) -> anyhow::Result<()> {
        let carried = Carried { density: self.params.continuity_density, warm: self.dfsph.is_some() };
        let held = self.own_particles();
        let grid = self.grid;
        let step = self.step;
        let part = self.ranks.as_mut().expect("only across ranks");
        let axis = part.axis;
        let layer_of = |grid: &crate::model::params::Grid<R>, p: V3<R>| grid.layer(p, axis);
        let mut slab_moved = false;
        if balance && part.balance_due(step) {
            let mut layers = vec![0.0; grid.dims[axis] as usize];
            for &p in &held.x {
                layers[layer_of(&grid, p) as usize] += 1.0;
            }
            slab_moved = part.balance(&layers)?;
        }
        let (held, _) = part.migrate(held, &grid, carried)?;
        let held = held.sorted();
        let (from_lower, from_upper, _) = part.exchange_ghosts(&held, 0..held.len(), &grid, carried)?;
        let own_count = held.len();
        let mut all = held;
        all.decode(&from_lower, carried)?;
        all.decode(&from_upper, carried)?;
        part.stats.ghosts = all.len() - own_count;
        self.install_held(all.sorted());
        if slab_moved {
            // The walls near the new bounds (the ones near the old are dropped).
            let walls = self.walls_near_slab();
            self.install_walls(&walls);
        }
        Ok(())
    }

    /// `all` (in the one-process order) as the particles the rank holds, the arrays that follow
    /// them sized to match.
    pub(super) fn install_held(&mut self, all: Held<R>) {
        let n = all.len();
        self.positions = all.x;
        self.velocities = all.v;
        self.ids = all.id;
        self.carried_densities = all.rho;
        if let Some(d) = &mut self.dfsph {
            // Each held particle's warm start is its owner's, in the held order.
            d.warm_pressure = all.warm.iter().map(|w| w[0]).collect();
            d.warm_divergence = all.warm.iter().map(|w| w[1]).collect();
            d.resize(n);
            self.warm_keys = (0..n as u32).collect();
        }
        self.size_held_arrays();
    }

    /// The arrays that follow the held particles sized to their count.
    pub(super) fn size_held_arrays(&mut self) {
        let n = self.positions.len();
        for v in [&mut self.densities, &mut self.pressures] {
            v.resize(n, R::zero());
        }
        self.accelerations.resize(n, V3::zero());
        self.keys.resize(n, 0);
        self.sorted.resize(n, 0);
    }

    /// The own slots with their places in the one-process order.
    fn own_order(&self) -> Vec<(usize, u64)> {
        let part = self.ranks.as_ref().expect("only across ranks");
        if let Some(first) = &part.first_order {
            return first.iter().enumerate().map(|(slot, &o)| (slot, o)).collect();
        }
        let mut out = Vec::new();
        for cell in self.own_cells(part).into_iter().flatten() {
            let (a, b) = (self.starts[cell] as usize, self.starts[cell + 1] as usize);
            out.extend((a..b).map(|slot| (slot, ((cell as u64) << 32) | (slot - a) as u64)));
        }
        out
    }

    /// Across ranks: every rank's rows `f(slot)` of its own particles, each after its place in
    /// the one-process order (two words), in rank order, on rank 0 (`None` on the others).
    fn gather_own(&mut self, width: usize, row: impl Fn(&Self, usize) -> Vec<f64>) -> anyhow::Result<Option<Vec<f64>>> {
        let own = self.own_order();
        let mut mine = Vec::with_capacity((width + 2) * own.len());
        for (slot, order) in own {
            mine.push((order >> 32) as f64);
            mine.push((order & 0xffff_ffff) as f64);
            mine.extend(row(self, slot));
        }
        let comm = self.ranks.as_ref().expect("only across ranks").comm.clone();
        let t0 = Instant::now();
        let all = comm.gather(&mine)?;
        if let Some(part) = &mut self.ranks {
            part.stats.exchange_seconds += t0.elapsed().as_secs_f64();
        }
        Ok(all.map(|parts| parts.concat()))
    }

    /// [`CpuSolver::snapshot`] across ranks: each rank bins its particles with fresh ghosts
    /// and evaluates density; the rows are gathered on rank 0, which writes the files (the
    /// other ranks get a snapshot of no particle, at the same step and time).
    pub(super) fn snapshot_across_ranks(&mut self) -> anyhow::Result<Snapshot> {
        self.snapshot_fields_across_ranks()?;
        let rows = self.gather_own(9, Self::snapshot_row)?;
        let Some(rows) = rows else { return Ok(Snapshot::with_len(0, self.step, self.time())) };
        let n = self.ranks.as_ref().map_or(0, |p| p.total_fluid);
        let mut s = Snapshot::with_len(n, self.step, self.time());
        for r in rows.chunks_exact(11).map(|r| &r[2..]) {
            let id = r[0] as usize;
            s.positions[id] = [r[1], r[2], r[3]];
            s.velocities[id] = [r[4], r[5], r[6]];
            s.densities[id] = r[7];
            s.pressures[id] = r[8];
        }
        Ok(s)
    }

    /// A snapshot's row of the particle in `slot`: its id, then `x y z vx vy vz density pressure`.
    fn snapshot_row(&self, slot: usize) -> Vec<f64> {
        let (x, v) = (self.positions[slot].to64(), self.velocities[slot].to64());
        vec![self.ids[slot] as f64, x[0], x[1], x[2], v[0], v[1], v[2], self.densities[slot].to64(), self.pressures[slot].to64()]
    }

    /// [`crate::solver::Backend::snapshot_piece`]: the fields of a snapshot as for
    /// [`CpuSolver::snapshot`], then every own particle's row to the rank whose block of ids
    /// holds it (one all-to-all), which puts its rows in id order.
    pub(super) fn snapshot_piece_across_ranks(&mut self) -> anyhow::Result<crate::solver::backend::SnapshotPiece> {
        self.snapshot_fields_across_ranks()?;
        let part = self.ranks.as_ref().expect("only across ranks");
        let (comm, total) = (part.comm.clone(), part.total_fluid as u64);
        let size = comm.size();
        let blocks: Vec<Range<u64>> = (0..size).map(|r| crate::solver::backend::id_block(total, size, r)).collect();
        let mut parts = vec![Vec::new(); size];
        for (slot, _) in self.own_order() {
            let id = self.ids[slot] as u64;
            let owner = blocks.partition_point(|b| b.end <= id);
            parts[owner].extend(self.snapshot_row(slot));
        }
        let t0 = Instant::now();
        let received = comm.all_to_all(&parts);
        if let Some(part) = &mut self.ranks {
            part.stats.exchange_seconds += t0.elapsed().as_secs_f64();
        }
        let mine = blocks[comm.rank()].clone();
        let mut rows = vec![[f64::NAN; 8]; (mine.end - mine.start) as usize];
        let mut filled = 0;
        for r in received?.iter().flat_map(|p| p.chunks_exact(9)) {
            let id = r[0] as u64;
            anyhow::ensure!(mine.contains(&id), "rank {} of {size} received the snapshot row of particle {id}, outside its block {mine:?}", comm.rank());
            rows[(id - mine.start) as usize].copy_from_slice(&r[1..]);
            filled += 1;
        }
        anyhow::ensure!(filled == rows.len(), "rank {} of {size} received {filled} snapshot rows for its block of {} particles", comm.rank(), rows.len());
        Ok(crate::solver::backend::SnapshotPiece { step: self.step, time: self.time(), total, first: mine.start, rows, comm })
    }

    /// A snapshot's fields on every rank: the exchange with fresh ghosts, the binning and the
    /// density (and the pressure of the last solve, for DFSPH).
    fn snapshot_fields_across_ranks(&mut self) -> anyhow::Result<()> {
        self.take_back_held();
        self.exchange(false);
        if self.rank_failure().is_none() && self.device.is_some() {
            self.fields_on_device();
        } else {
            // Each particle's warm start (DFSPH's last pressure) is its owner's.
            self.snapshot_fields();
        }
        if let Some(e) = self.rank_failure() {
            anyhow::bail!("{e}");
        }
        Ok(())
    }

    /// [`CpuSolver::step_fields`] across ranks, gathered on rank 0 (empty on the others).
    pub(super) fn step_fields_across_ranks(&mut self) -> anyhow::Result<StepFields> {
        self.take_back_held();
        let rows = self.gather_own(6, |s, i| {
            let a = s.accelerations[i].to64();
            vec![s.ids[i] as f64, s.densities[i].to64(), s.pressures[i].to64(), a[0], a[1], a[2]]
        })?;
        let n = if rows.is_some() { self.ranks.as_ref().map_or(0, |p| p.total_fluid) } else { 0 };
        let rows = rows.unwrap_or_default();
        let mut out = StepFields { densities: vec![0.0; n], pressures: vec![0.0; n], accelerations: vec![[0.0; 3]; n] };
        for r in rows.chunks_exact(8).map(|r| &r[2..]) {
            let id = r[0] as usize;
            out.densities[id] = r[1];
            out.pressures[id] = r[2];
            out.accelerations[id] = [r[3], r[4], r[5]];
        }
        Ok(out)
    }

    /// Every rank's [`RankReport`], in rank order (collective).
    pub(super) fn gather_rank_reports(&mut self) -> anyhow::Result<Option<Vec<RankReport>>> {
        let Some(mine) = self.rank_report() else { return Ok(None) };
        let comm = self.ranks.as_ref().expect("across ranks").comm.clone();
        let s = &mine.stats;
        let all = comm.all_gather(&[mine.own_particles as f64, s.exchange_seconds, s.migrated as f64, s.ghosts as f64, mine.node_rank as f64, mine.node_ranks as f64, mine.threads as f64, mine.walls as f64, s.resident_steps as f64, s.bus_bytes as f64, s.device_seconds])?;
        // The adapters' names travel as bytes, padded to the longest.
        let longest = all_max(comm.as_ref(), &[mine.adapter.len() as f64])?[0] as usize;
        let mut name: Vec<f64> = mine.adapter.bytes().map(f64::from).collect();
        name.resize(longest, 0.0);
        let names: Vec<String> = comm.all_gather(&name)?.iter().map(|b| String::from_utf8_lossy(&b.iter().take_while(|&&c| c != 0.0).map(|&c| c as u8).collect::<Vec<u8>>()).into_owned()).collect();
        Ok(Some(
            all.iter()
                .enumerate()
                .map(|(rank, r)| RankReport {
                    rank,
                    own_particles: r[0] as usize,
                    walls: r[7] as usize,
                    node_rank: r[4] as usize,
                    node_ranks: r[5] as usize,
                    threads: r[6] as usize,
                    adapter: names[rank].clone(),
                    stats: RankStats { exchange_seconds: r[1], migrated: r[2] as u64, ghosts: r[3] as usize, resident_steps: r[8] as u64, bus_bytes: r[9] as u64, device_seconds: r[10], ..s.clone() },
                    ..mine.clone()
                })
                .collect(),
        ))
    }

    /// [`CpuSolver::save_state`] across ranks (collective): the state one process would save,
    /// its arrays streamed to rank 0 as a checkpoint streams them, in one piece each; the other
    /// ranks' holds the step, time and health, and no particle.
    pub(super) fn save_state_across_ranks(&mut self) -> anyhow::Result<BackendState> {
        let mut state = self.state_header_across_ranks();
        for array in [StateArray::Positions, StateArray::Velocities, StateArray::Ids, StateArray::WarmStart, StateArray::Densities] {
            self.visit_state_array_across_ranks(array, u64::MAX, &mut |piece| {
                match piece {
                    StatePiece::Vectors(v) if array == StateArray::Positions => state.positions = v.to_vec(),
                    StatePiece::Vectors(v) => state.velocities = v.to_vec(),
                    StatePiece::Ids(v) => state.ids = v.to_vec(),
                    StatePiece::Pairs(v) => state.warm_start = v.to_vec(),
                    StatePiece::Scalars(v) => state.densities = v.to_vec(),
                }
                Ok(())
            })?;
        }
        Ok(state)
    }

    /// [`crate::solver::Backend::save_state_header`] across ranks: this rank's step, time,
    /// health and dt, which every rank shares (no particle is gathered).
    pub(super) fn state_header_across_ranks(&self) -> BackendState {
        crate::solver::backend::state_header(self.save_state())
    }

    /// Each own slot's place in the one-process order of the saved state: its index in the
    /// initial or restored state before the first binning; after it, the particles of the
    /// cells before its cell (the ranks' cell runs and their counts, all-gathered) plus its
    /// place in the cell. Sorted by place.
    fn places_in_one_process_order(&self) -> anyhow::Result<Vec<(usize, u64)>> {
        let part = self.ranks.as_ref().expect("only across ranks");
        if let Some(first) = &part.first_order {
            let mut places: Vec<(usize, u64)> = first.iter().enumerate().map(|(slot, &o)| (slot, o)).collect();
            places.sort_unstable_by_key(|p| p.1);
            return Ok(places);
        }
        let runs = self.own_cells(part);
        let mine: Vec<f64> = runs.iter().flat_map(|r| [r.start as f64, (self.starts[r.end] - self.starts[r.start]) as f64]).collect();
        let mut all: Vec<(u64, u64)> = part.comm.all_gather(&mine)?.iter().flat_map(|r| r.chunks_exact(2).map(|c| (c[0] as u64, c[1] as u64)).collect::<Vec<_>>()).collect();
        all.sort_unstable();
        // The particles before each run's first cell.
        let mut before = std::collections::HashMap::with_capacity(runs.len());
        let mut running = 0u64;
        for (cell, count) in all {
            before.insert(cell, running);
            running += count;
        }
        let mut places = Vec::with_capacity(self.positions.len());
        for run in runs {
            let (first, offset) = (self.starts[run.start] as usize, before[&(run.start as u64)]);
            places.extend((first..self.starts[run.end] as usize).map(|slot| (slot, offset + (slot - first) as u64)));
        }
        places.sort_unstable_by_key(|p| p.1);
        Ok(places)
    }

    /// [`crate::solver::Backend::visit_state_array`] across ranks (collective): for each piece
    /// of `chunk` places of the saved state's order (by id for DFSPH's warm starts), every rank
    /// sends its own particles' values there to rank 0, which hands the piece to `visit`; the
    /// other ranks visit nothing. No rank holds more than its own particles and one piece.
    pub(super) fn visit_state_array_across_ranks(&mut self, array: StateArray, chunk: u64, visit: &mut dyn FnMut(StatePiece) -> anyhow::Result<()>) -> anyhow::Result<()> {
        self.take_back_held();
        let total = crate::solver::backend::Backend::state_array_len(self, array) as u64;
        let mut places = self.places_in_one_process_order()?;
        if array == StateArray::WarmStart {
            places = places.iter().map(|&(slot, _)| (slot, self.ids[slot] as u64)).collect();
            places.sort_unstable_by_key(|p| p.1);
        }
        let width = match array {
            StateArray::Positions | StateArray::Velocities => 3,
            StateArray::WarmStart => 2,
            StateArray::Ids | StateArray::Densities => 1,
        };
        let value = |slot: usize| -> Vec<f64> {
            match array {
                StateArray::Positions => self.positions[slot].to64().to_vec(),
                StateArray::Velocities => self.velocities[slot].to64().to_vec(),
                StateArray::Ids => vec![self.ids[slot] as f64],
                StateArray::Densities => vec![self.carried_densities[slot].to64()],
                StateArray::WarmStart => {
                    let (d, k) = (self.dfsph.as_ref().expect("DFSPH's array"), self.warm_keys[slot] as usize);
                    vec![d.warm_pressure[k].to64(), d.warm_divergence[k].to64()]
                }
            }
        };
        let comm = self.ranks.as_ref().expect("only across ranks").comm.clone();
        let chunk = chunk.max(1);
        let mut next = 0;
        let mut start = 0u64;
        while start < total {
            let end = start.saturating_add(chunk).min(total);
            let mut mine = Vec::new();
            while next < places.len() && places[next].1 < end {
                mine.push((places[next].1 - start) as f64);
                mine.extend(value(places[next].0));
                next += 1;
            }
            let t0 = Instant::now();
            let gathered = comm.gather(&mine)?;
            if let Some(part) = &mut self.ranks {
                part.stats.exchange_seconds += t0.elapsed().as_secs_f64();
            }
            if let Some(parts) = gathered {
                let n = (end - start) as usize;
                let mut values = vec![f64::NAN; n * width];
                let mut filled = 0;
                for row in parts.iter().flat_map(|p| p.chunks_exact(width + 1)) {
                    let at = row[0] as usize;
                    anyhow::ensure!(at < n, "a rank sent place {} of a piece of {n}", at);
                    values[at * width..(at + 1) * width].copy_from_slice(&row[1..]);
                    filled += 1;
                }
                anyhow::ensure!(filled == n, "the ranks sent {filled} of the {n} values of places {start}..{end} of the saved state's {array:?}");
                match array {
                    StateArray::Positions | StateArray::Velocities => visit(StatePiece::Vectors(&values.chunks_exact(3).map(|v| [v[0], v[1], v[2]]).collect::<Vec<_>>()))?,
                    StateArray::WarmStart => visit(StatePiece::Pairs(&values.chunks_exact(2).map(|v| [v[0], v[1]]).collect::<Vec<_>>()))?,
                    StateArray::Ids => visit(StatePiece::Ids(&values.iter().map(|&v| v as u32).collect::<Vec<_>>()))?,
                    StateArray::Densities => visit(StatePiece::Scalars(&values))?,
                }
            }
            start = end;
        }
        Ok(())
    }

    /// [`CpuSolver::restore_state`] across ranks (any rank count saved it), each rank reading
    /// its part of `source`: the positions counted per cell layer cut slabs of equal counts,
    /// and this rank takes the particles of its slab, in the state's order, and the walls
    /// near it.
    pub(super) fn restore_state_across_ranks(&mut self, source: &mut dyn StateSource) -> anyhow::Result<()> {
        // The device's particles are replaced with the rest: the next step uploads them.
        self.forget_device_state();
        let part = self.ranks.as_ref().expect("only across ranks");
        let grid = self.grid;
        let axis = part.axis;
        let layer_of = |p: [f64; 3]| grid.layer(V3::<R>::from64(p), axis);
        let mut counts = vec![0u64; grid.dims[axis] as usize];
        let mut total = 0usize;
        source.visit_positions(&mut |p| {
            counts[layer_of(p) as usize] += 1;
            total += 1;
        })?;
        anyhow::ensure!(total == part.total_fluid, "the state holds {total} particles; the scene has {}", part.total_fluid);
        let slabs = Slabs::balanced(&counts, part.comm.size(), part.slabs.halo)?;
        let mine = slabs.layers_of(part.comm.rank());
        let (local, chosen) = source.read_kept(&mut |_, p| mine.contains(&layer_of(p)))?;
        let kind = self.saved_kind();
        anyhow::ensure!(local.kind == kind, "the state was saved by the {} backend, not {kind}", local.kind);
        anyhow::ensure!(local.velocities.len() == chosen.len() && local.ids.len() == chosen.len(), "the state's arrays differ in length");
        anyhow::ensure!(local.ids.iter().all(|&id| (id as usize) < total), "the state's particle ids are not a permutation");
        let state = &local;
        let n = chosen.len();
        self.positions = local.positions.iter().map(|&p| V3::from64(p)).collect();
        self.velocities = local.velocities.iter().map(|&v| V3::from64(v)).collect();
        self.ids = local.ids.clone();
        anyhow::ensure!(
            local.densities.is_empty() == !self.params.continuity_density,
            "the state holds {} carried densities for {} particles; the scene's density method needs {}",
            local.densities.len(),
            chosen.len(),
            if self.params.continuity_density { "one per particle" } else { "none" }
        );
        self.carried_densities = local.densities.iter().map(|&d| R::of(d)).collect();
        for v in [&mut self.densities, &mut self.pressures] {
            v.resize(n, R::zero());
        }
        self.accelerations.resize(n, V3::zero());
        self.keys.resize(n, 0);
        self.sorted.resize(n, 0);
        self.step = state.step;
        self.probe_samples.clear();
        self.health = state.health();
        self.time = state.time;
        let [min, max, last] = state.dt_min_max_last;
        self.dt_stats = crate::model::state::DtStats { min, max, last, ..Default::default() };
        if let Some(d) = &mut self.dfsph {
            // The held particles' (the part read holds them in its particles' order).
            anyhow::ensure!(state.warm_start.len() == n, "the state holds {} warm-start stiffnesses for DFSPH for this rank's {n} particles", state.warm_start.len());
            d.warm_pressure = state.warm_start.iter().map(|w| R::of(w[0])).collect();
            d.warm_divergence = state.warm_start.iter().map(|w| R::of(w[1])).collect();
            self.warm_keys = (0..n as u32).collect();
            d.stats = state.iterations;
            d.last_dt = if state.step > 0 { last } else { 0.0 };
            d.resize(n);
        }
        let part = self.ranks.as_mut().expect("only across ranks");
        part.slabs = slabs;
        part.first_order = Some(chosen);
        part.failure = None;
        // The walls near the slab cut for the state.
        let walls = self.walls_near_slab();
        self.install_walls(&walls);
        Ok(())
    }

    /// Across ranks: the step's maxima (largest speed, acceleration) over every rank; alone
    /// they are returned as they are.
    pub(super) fn all_max(&mut self, values: &[f64]) -> Vec<f64> {
        let Some(part) = &mut self.ranks else { return values.to_vec() };
        let t0 = Instant::now();
        let out = match crate::solver::communicator::all_max(&*part.comm, values) {
            Ok(v) => v,
            Err(e) => {
                part.failure.get_or_insert(format!("{e:#}"));
                // NaN makes the step count as bad on this rank, which then stops.
                vec![f64::NAN; values.len()]
            }
        };
        part.stats.exchange_seconds += t0.elapsed().as_secs_f64();
        out
    }

    /// Across ranks: the step's health found on every rank (counts added, speeds and the
    /// largest density the largest); alone returned as it is.
    pub(super) fn all_step_health(&mut self, found: super::integrate::StepHealth, max_density: f64) -> (super::integrate::StepHealth, f64) {
        let Some(part) = &mut self.ranks else { return (found, max_density) };
        let t0 = Instant::now();
        let reduced = part.comm.all_gather(&[found.non_finite as f64, found.escaped as f64, found.max_speed, max_density]);
        part.stats.exchange_seconds += t0.elapsed().as_secs_f64();
        match reduced {
            Ok(all) => {
                let mut out = super::integrate::StepHealth::default();
                let mut density = 0.0f64;
                for r in &all {
                    out = out.add(super::integrate::StepHealth { non_finite: r[0] as u32, escaped: r[1] as u32, max_speed: r[2] });
                    density = density.max(r[3]);
                }
                (out, density)
            }
            Err(e) => {
                part.failure.get_or_insert(format!("{e:#}"));
                (super::integrate::StepHealth { non_finite: 1, ..found }, max_density)
            }
        }
    }
}

/// The probes' sample across ranks, the same on every rank: each point probe and each level of
/// a gauge evaluated by the rank whose slab holds it (its neighbourhood is whole there: the
/// rank's own particles and two ghost layers), the force probes and fronts over each rank's own
/// particles (`own`, not its ghosts); then added over the ranks in rank order (the values of
/// points and gauge levels come from one rank and zeros, so they are the one-process run's bits;
/// force sums are added in another grouping) and the fronts' farthest taken over the ranks that
/// saw fluid in their band. Returns the values and the error of a failed collective.
pub(super) fn probes_across_ranks<R: Real>(input: &ProbeInput<R>, part: &RankPart, own: &[Range<usize>], list: &[Probe], offsets: &[usize]) -> (Vec<f64>, Option<String>) {
    let rank = part.comm.rank();
    let evaluates = |x: V3<R>| part.slabs.owner(input.grid.layer(x, part.axis)) == rank;
    let count = offsets.last().zip(list.last()).map_or(0, |(&at, p)| at + p.geometry.columns().len());
    let mut local = vec![R::zero(); count];
    // Forces and fronts over the own particles.
    let mut counted = vec![false; input.fluid.positions.len()];
    for slots in own {
        counted[slots.clone()].fill(true);
    }
    let mut partials = Vec::new();
    probes::probe_particles(input, list, Some(&counted), &mut partials);
    probes::probe_finish(list, offsets, &partials, &mut local);
    // The point probes of this slab.
    let (mine, mine_at): (Vec<Probe>, Vec<usize>) = list
        .iter()
        .zip(offsets)
        .filter(|(p, _)| matches!(p.geometry, ProbeGeometry::Point { position } if evaluates(V3::from64(position))))
        .map(|(p, &at)| (p.clone(), at))
        .unzip();
    probes::probe_points(input, &mine, &mine_at, &mut local);
    // Every column, then each gauge's level fractions (this slab's levels).
    let mut sums: Vec<f64> = local.iter().map(|v| v.to64()).collect();
    for probe in list {
        if let ProbeGeometry::Gauge { x, z, bottom, top, step } = probe.geometry {
            let f = probes::gauge_fractions(input, R::of(x), R::of(z), R::of(bottom), R::of(top), R::of(step), evaluates);
            sums.extend(f.iter().map(|v| v.to64()));
        }
    }
    let (mut values, fractions) = match add_probes_over_ranks(&*part.comm, list, offsets, sums) {
        Ok(added) => added,
        Err(e) => return (vec![f64::NAN; count], Some(e)),
    };
    let mut level = 0;
    for (probe, &at) in list.iter().zip(offsets) {
        if let ProbeGeometry::Gauge { bottom, top, step, .. } = probe.geometry {
            let (bottom, top, step) = (R::of(bottom), R::of(top), R::of(step));
            let levels = probes::gauge_levels(bottom, top, step).len();
            let fractions = &fractions[level..level + levels];
            let surface = probes::surface_from_fractions(bottom, top, step, |k, _| R::of(fractions[k]));
            values[at] = surface.to64();
            values[at + 1] = (surface - bottom).to64();
            level += levels;
        }
    }
    (values, None)
}

/// The probes' sample across ranks from each rank's device (wgsl/sim/probes.wgsl on the held
/// particles, the ghosts left out of the forces and fronts): `device` holds every column as
/// the device computed it; a point's and a gauge's values are kept by the rank that
/// `evaluates` them (whose neighbourhood of them is whole, so they are the one-process run's
/// bits) and zeroed elsewhere, then the ranks add them up as [`probes_across_ranks`] does.
///
/// `failed` says that this rank's device gave no row (`device` then holds zeros): the ranks add
/// that flag with the values, so each of them learns of it in the same collective and returns
/// an error instead of a sample that lacks the failed rank's part.
pub(super) fn device_probes_across_ranks(comm: &dyn Communicator, list: &[Probe], offsets: &[usize], mut device: Vec<f64>, failed: bool, evaluates: impl Fn([f64; 3]) -> bool) -> (Vec<f64>, Option<String>) {
    let count = device.len();
    for (probe, &at) in list.iter().zip(offsets) {
        let point = match probe.geometry {
            ProbeGeometry::Point { position } => position,
            // The gauge's line lies in one cell layer of the slab axis (probes_on_device).
            ProbeGeometry::Gauge { x, z, bottom, .. } => [x, bottom, z],
            _ => continue,
        };
        if !evaluates(point) {
            device[at..at + probe.geometry.columns().len()].fill(0.0);
        }
    }
    device.push(if failed { 1.0 } else { 0.0 });
    match add_probes_over_ranks(comm, list, offsets, device) {
        Ok((values, failed_ranks)) if failed_ranks[0] == 0.0 => (values, None),
        Ok((values, failed_ranks)) => {
            let n = failed_ranks[0];
            (values, Some(format!("{n} rank(s) of {} sampled no probe row of this step on their device; the step's sample is left out", comm.size())))
        }
        Err(e) => (vec![f64::NAN; count], Some(e)),
    }
}

/// The ranks' probe sums added up (collective): `sums` holds every column of this rank
/// (a front's farthest and count from its own particles), then any further sums to add; each
/// front's farthest is taken over the ranks that saw fluid in its band. Returns the columns and
/// the further sums.
fn add_probes_over_ranks(comm: &dyn Communicator, list: &[Probe], offsets: &[usize], mut sums: Vec<f64>) -> Result<(Vec<f64>, Vec<f64>), String> {
    let count = offsets.last().zip(list.last()).map_or(0, |(&at, p)| at + p.geometry.columns().len());
    let mut farthest = Vec::new();
    for (probe, &at) in list.iter().zip(offsets) {
        if let ProbeGeometry::Front { .. } = probe.geometry {
            farthest.push(if sums[at + 1] > 0.0 { sums[at] } else { f64::NEG_INFINITY });
            sums[at] = 0.0;
        }
    }
    let (mut sums, farthest) = all_sum(comm, &sums).and_then(|s| Ok((s, all_max(comm, &farthest)?))).map_err(|e| format!("{e:#}"))?;
    let further = sums.split_off(count);
    let mut front = 0;
    for (probe, &at) in list.iter().zip(offsets) {
        if let ProbeGeometry::Front { .. } = probe.geometry {
            sums[at] = if sums[at + 1] > 0.0 { farthest[front] } else { 0.0 };
            front += 1;
        }
    }
    Ok((sums, further))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::probes::ProbeInterval;
    use crate::solver::communicator::LocalGroup;

    /// A device row of a point (read by rank 0) and a front (over both ranks), added over two
    /// ranks; then the same with rank 1's device failing: both ranks return its error and no
    /// sample, where they once returned NaN columns for the writer to write.
    #[test]
    fn a_rank_whose_device_gave_no_probe_row_fails_the_sample_on_every_rank() {
        let list = vec![
            Probe { name: "p".into(), interval: ProbeInterval::Steps(1), geometry: ProbeGeometry::Point { position: [0.1, 0.2, 0.3] } },
            Probe { name: "f".into(), interval: ProbeInterval::Steps(1), geometry: ProbeGeometry::Front { direction: [1.0, 0.0, 0.0], floor: 0.0, height: 0.1 } },
        ];
        let offsets = vec![0, 6];
        let rows = [vec![1.0, 2.0, 3.0, 4.0, 5.0, 0.5, 0.7, 10.0], vec![9.0, 9.0, 9.0, 9.0, 9.0, 9.0, 0.9, 5.0]];
        for failing in [None, Some(1)] {
            let results: Vec<(Vec<f64>, Option<String>)> = std::thread::scope(|s| {
                let handles: Vec<_> = LocalGroup::new(2)
                    .into_iter()
                    .map(|comm| {
                        let (list, offsets) = (&list, &offsets);
                        let rank = comm.rank();
                        let failed = failing == Some(rank);
                        let row = if failed { vec![0.0; 8] } else { rows[rank].clone() };
                        s.spawn(move || device_probes_across_ranks(&comm, list, offsets, row, failed, |_| rank == 0))
                    })
                    .collect();
                handles.into_iter().map(|h| h.join().unwrap()).collect()
            });
            for (rank, (values, error)) in results.iter().enumerate() {
                match failing {
                    None => {
                        assert!(error.is_none(), "rank {rank}: {error:?}");
                        assert_eq!(values, &vec![1.0, 2.0, 3.0, 4.0, 5.0, 0.5, 0.9, 15.0], "rank {rank}");
                    }
                    Some(_) => {
                        let e = error.as_deref().unwrap_or_else(|| panic!("rank {rank} took a sample that lacks rank 1's part: {values:?}"));
                        assert!(e.contains("1 rank(s) of 2 sampled no probe row"), "rank {rank}: {e}");
                        assert!(values.iter().all(|v| v.is_finite()), "rank {rank}: {values:?}");
                    }
                }
            }
        }
    }
}
