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
//!
//! What a rank's device runs is in rank_device.rs, what the ranks gather and restore together
//! (snapshots, states, probes) in rank_gather.rs.

use super::ghost_velocities::{gather_ghost_velocities, scatter_ghost_velocities};
use super::resident_exchange::SlabFaces;
use super::CpuSolver;
use crate::model::initial::{FluidParticle, InitialState};
use crate::model::real::{as_arrays, Real, V3};
use crate::solver::communicator::{all_max, all_sum, Communicator};
use crate::model::scene::BoundaryPressure;
use crate::solver::decomposition::{cell_runs, halo_layers, imbalance, slab_axis, RankReport, RankStats, Slabs};
use std::ops::Range;
use std::sync::Arc;
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

impl<R: Real> CpuSolver<R> {

    /// The wall particles near this rank's slab, from the scene (or the whole state given).
    pub(super) fn walls_near_slab(&self) -> InitialState {
        let part = self.ranks.as_deref().expect("across ranks");
        part.walls.near(&self.grid, part.axis, part.slabs.layers_of(part.comm.rank()), part.slabs.halo)
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

    /// Keeps the first failure of this rank (across ranks; alone nothing fails this way).
    pub(super) fn note_failure(&mut self, failure: Option<String>) {
        if let (Some(e), Some(part)) = (failure, self.ranks.as_mut()) {
            part.failure.get_or_insert(e);
        }
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
    pub(super) fn ghost_flags(&self) -> Vec<bool> {
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
        Ok(Self::new_part_and_walls(params, initial, comm, balance_every)?.0)
    }

    /// [`CpuSolver::new_part`], and the rank's part of the initial state (its fluid and the
    /// walls near its slab), which a device takes its walls from.
    pub(super) fn new_part_and_walls(params: &crate::model::params::Params, initial: InitialSource<'_>, comm: Arc<dyn Communicator>, balance_every: u64) -> anyhow::Result<(Self, InitialState)> {
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
        Ok((solver, part))
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
    pub(super) fn own_cells(&self, part: &RankPart) -> Vec<Range<usize>> {
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
            stats: RankStats { bus_bytes: self.device_bus_bytes(), ..p.stats.clone() },
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
}
