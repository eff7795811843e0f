//! What DFSPH's stages share on the CPU: the neighbour lists with their kernel gradients, the
//! rate of density change and the velocity change of a stiffness (the twins of
//! wgsl/shared/dfsph.wgsl `density_rate` and `stiffness_push`), the Jacobi step both solves
//! take, the warm start, and the fixed-point error sums.
//!
//! In rest-density units (rho^ = rho / rho0, V = m / rho0 the fluid particle's volume,
//! V_b = m_b / rho0 a wall particle's), with the per-particle stiffness K of a solve:
//! - the rate of density change: D_i = V sum_j (v_i - v_j) . grad W_ij + v_i . g_i^w, with
//!   g_i^w = sum_b V_b grad W_ib (walls at rest; fixed, so summed once per step);
//! - the velocity change of stiffness K: dv_i = -s (V sum_j (K_i + K_j) grad W_ij + K_i g_i^w)
//!   (the symmetric pressure force with p / rho^2 = K / (rho0 dt^2); s = 1 / dt in the
//!   constant-density solve, 1 in the divergence solve, whose K is per second);
//! - one Jacobi step sets K_i from the diagonal of that system, alpha_i = 1 / (|V g_i^f + g_i^w|^2
//!   + V^2 sum_j |grad W_ij|^2) (the factor of Bender & Koschier 2017, Eq. 11, in these units).
//!
//! The CPU lists every particle's fluid neighbours with their kernel gradients once per step
//! (`dfsph_factors`), and every later pass of the step reads the list: the same neighbours, in
//! the same order, with the same gradients as the GPU recomputes them from the grid.
//!
//! Where the processor has the eight-lane instructions, the lists are kept as rows of eight
//! (row t holds the t-th neighbour of each of eight consecutive particles, with its gradient;
//! the particles are listed by cells but grouped by eights whatever their cells, so that few
//! entries are empty), and the factors' and the solves' sums run eight particles at a time:
//! each lane adds its own particle's terms in the list's order, so every sum is the
//! one-at-a-time sum bit for bit.

use super::cell_batches::{wide, LaneScratch};
use crate::model::lanes::{Pack, PackV3, LANES};
use crate::model::real::{as_arrays, Real, V3};
use rayon::prelude::*;

/// Particles per chunk of the neighbour lists: a chunk is built and read by one task.
pub const CHUNK: usize = 256;

/// A per-particle error enters a solve's sum as a fixed-point integer with this many fraction
/// bits, clamped to [0, `ERROR_CLAMP`]: integer sums do not depend on the order of the
/// additions, so the GPU's atomic sum and the CPU's are the same number, and so is the decision
/// to stop (2^-30: 1e-9, far below any tolerance).
pub const ERROR_FRACTION_BITS: u32 = 30;
pub const ERROR_CLAMP: f64 = 3.0;

/// A particle's error as fixed-point units (truncated, as WGSL's `u32(f32)`); a non-finite
/// error gives none (the health check reports it).
pub fn error_units<R: Real>(error: R) -> u64 {
    if !error.is_finite() {
        return 0;
    }
    let e = error.max(R::zero()).min(R::of(ERROR_CLAMP));
    (e * R::of((1u64 << ERROR_FRACTION_BITS) as f64)).to64() as u64
}

/// The largest error sum of `n` particles whose average error is at most `tolerance`.
pub fn error_threshold(tolerance: f64, n: usize) -> u64 {
    (tolerance * n as f64 * (1u64 << ERROR_FRACTION_BITS) as f64).floor() as u64
}

/// The average error of an error sum of `n` particles.
pub fn average_error(sum: u64, n: usize) -> f64 {
    sum as f64 / (n.max(1) as f64 * (1u64 << ERROR_FRACTION_BITS) as f64)
}

/// One chunk of the neighbour lists: for each of its particles, the fluid neighbours within the
/// support (itself excluded: its gradient is zero) and grad W_ij, in the GPU's visiting order.
/// Either one particle after the other (`starts`, `index`, `grad`) or, on the lane path, in rows
/// of eight particles (`batches`, `rows`, `row_grads`); the other form is empty.
#[derive(Clone, Debug, Default)]
pub struct PairChunk<R> {
    /// `starts[k]..starts[k + 1]`: the pairs of the chunk's particle k.
    pub starts: Vec<u32>,
    pub index: Vec<u32>,
    pub grad: Vec<V3<R>>,
    /// The chunk's particles by batches of eight consecutive ones (fewer in the last).
    pub batches: Vec<RowBatch>,
    /// Row t of a batch: the t-th pair of each lane...
    pub rows: Vec<[u32; LANES]>,
    /// ... and its gradient, x, y and z of the eight lanes. The entries that a one-at-a-time
    /// list leaves out (the particle itself, one at the same spot, and the entries past a lane's
    /// list, which are the lane's own particle) have a zero gradient: their term is a signed
    /// zero, which leaves the sum's bits as they are (a sum that starts at +0 is never -0, and
    /// the velocities and stiffnesses are finite while a run is healthy), so the solves' sums
    /// take every entry without a mask.
    pub row_grads: Vec<[[R; LANES]; 3]>,
    /// The largest particle index in `rows` (for [`RowGather::unchecked`]).
    pub max_index: u32,
    /// The factors pass's working arrays for eight particles at a time (kept between steps).
    pub work: LaneWork<R>,
}

/// Up to eight consecutive particles of a chunk and where their rows are.
#[derive(Clone, Copy, Debug, Default)]
pub struct RowBatch {
    /// The batch's first particle in the chunk, and its number of particles.
    pub local: u32,
    pub lanes: u32,
    /// Its rows: `first_row..first_row + rows` of the chunk's rows.
    pub first_row: u32,
    pub rows: u32,
    /// The length of each lane's list (0 past `lanes`).
    pub counts: [u32; LANES],
}

/// What the factors pass lists one cell's batch of up to eight particles in
/// (`cell_batches::lane_lists`): their fluid and wall neighbours' rows and the listing's
/// scratch arrays; and each particle's sums over the walls, by its place in the chunk.
#[derive(Clone, Debug, Default)]
pub struct LaneWork<R> {
    pub rows: Vec<[u32; LANES]>,
    pub wall_rows: Vec<[u32; LANES]>,
    pub scratch: LaneScratch,
    pub walls: Vec<WallSums<R>>,
}

/// A particle's sums over its wall neighbours: sum_b m_b W_ib and sum_b m_b grad W_ib.
#[derive(Clone, Copy, Debug, Default)]
pub struct WallSums<R> {
    pub sum: R,
    pub gradient: V3<R>,
}

impl<R> LaneWork<R> {
    fn bytes(&self) -> u64 {
        let rows = (self.rows.capacity() + self.wall_rows.capacity()) * 4 * LANES;
        (rows + self.walls.capacity() * std::mem::size_of::<WallSums<R>>()) as u64 + self.scratch.bytes()
    }
}

impl<R> PairChunk<R> {
    /// Empties both forms of the lists.
    pub fn clear(&mut self) {
        self.starts.clear();
        self.index.clear();
        self.grad.clear();
        self.batches.clear();
        self.rows.clear();
        self.row_grads.clear();
        self.max_index = 0;
    }

    fn bytes(&self) -> u64 {
        let lists = self.index.capacity() * 4 + self.grad.capacity() * std::mem::size_of::<V3<R>>() + self.starts.capacity() * 4;
        let rows = self.batches.capacity() * std::mem::size_of::<RowBatch>() + self.rows.capacity() * 4 * LANES + self.row_grads.capacity() * std::mem::size_of::<[[R; LANES]; 3]>();
        (lists + rows) as u64 + self.work.bytes()
    }
}

/// The neighbour lists of every fluid particle, by chunks of [`CHUNK`] particles.
#[derive(Clone, Debug, Default)]
pub struct Pairs<R> {
    pub chunks: Vec<PairChunk<R>>,
}

impl<R: Real> Pairs<R> {
    pub fn bytes(&self) -> u64 {
        self.chunks.iter().map(PairChunk::bytes).sum()
    }
}

/// What the solves read besides the velocities.
pub struct SolveInput<'a, R> {
    pub pairs: &'a Pairs<R>,
    /// The fluid particle's volume V = m / rho0.
    pub volume: R,
    pub factors: &'a [R],
    pub wall_gradients: &'a [V3<R>],
    /// Across ranks, which slots hold ghosts, whose errors their owner counts (empty alone).
    pub ghosts: &'a [bool],
}

impl<R: Real> SolveInput<'_, R> {
    /// Whether the error of the particle in `slot` counts towards this rank's sum.
    #[inline(always)]
    pub fn counts(&self, slot: usize) -> bool {
        self.ghosts.is_empty() || !self.ghosts[slot]
    }

    /// [`error_units_lanes`] of a batch's lanes whose errors count.
    #[inline(always)]
    pub fn lane_error_units(&self, error: Pack<R>, lanes: &BatchLanes) -> u64 {
        if self.ghosts.is_empty() {
            return error_units_lanes(error, lanes.count);
        }
        let errors = error.to_array();
        (0..lanes.count).filter(|&k| !self.ghosts[lanes.slots[k] as usize]).map(|k| error_units(errors[k])).sum()
    }
}

/// D_i = V sum_j (v_i - v_j) . grad W_ij + v_i . g_i^w: the rate of change of rho_i / rho0
/// (wgsl/shared/dfsph.wgsl `density_rate`).
#[inline]
pub fn density_rate<R: Real>(chunk: &PairChunk<R>, local: usize, volume: R, velocities: &[V3<R>], vi: V3<R>, wall_gradient: V3<R>) -> R {
    let (a, b) = (chunk.starts[local] as usize, chunk.starts[local + 1] as usize);
    let mut sum = R::zero();
    for (&j, &g) in chunk.index[a..b].iter().zip(&chunk.grad[a..b]) {
        sum = sum + (vi - velocities[j as usize]).dot(g);
    }
    sum * volume + vi.dot(wall_gradient)
}

/// V sum_j (K_i + K_j) grad W_ij + K_i g_i^w: the velocity change of the stiffness K, before its
/// sign and scale (wgsl/shared/dfsph.wgsl `stiffness_push`).
#[inline]
pub fn stiffness_push<R: Real>(chunk: &PairChunk<R>, local: usize, volume: R, stiffness: &[R], ki: R, wall_gradient: V3<R>) -> V3<R> {
    let (a, b) = (chunk.starts[local] as usize, chunk.starts[local + 1] as usize);
    let mut sum = V3::zero();
    for (&j, &g) in chunk.index[a..b].iter().zip(&chunk.grad[a..b]) {
        sum += g * (ki + stiffness[j as usize]);
    }
    sum * volume + wall_gradient * ki
}

/// The chunk's batches in order (`first`: the chunk's first slot), each with its lanes, on the
/// eight-lane instructions (`each` is compiled into them: mark it `#[inline(always)]`).
#[inline(always)]
fn each_batch<R: Real>(chunk: &PairChunk<R>, first: usize, mut each: impl FnMut(&RowBatch, &BatchLanes)) {
    wide(
        #[inline(always)]
        || {
            for batch in &chunk.batches {
                each(batch, &BatchLanes::of(first, batch));
            }
        },
    )
}

/// A batch's rows in order: each row's neighbours and their gradients, for the solves' sums
/// (every entry counts: those a one-at-a-time list leaves out add a zero, see
/// [`PairChunk::row_grads`]).
#[inline(always)]
fn batch_rows<R: Real>(chunk: &PairChunk<R>, batch: &RowBatch, mut each: impl FnMut(&[u32; LANES], PackV3<R>)) {
    let rows = batch.first_row as usize..(batch.first_row + batch.rows) as usize;
    for (row, g) in chunk.rows[rows.clone()].iter().zip(&chunk.row_grads[rows]) {
        each(row, row_gradient(g));
    }
}

/// Values loaded by the rows of one chunk: with each index checked against the slice
/// (`CHECKED`), or with none checked where the chunk's largest index was checked once
/// ([`RowGather::unchecked`]), which takes the checks out of the solves' inner loops.
#[derive(Clone, Copy)]
struct RowGather<'a, T, const CHECKED: bool> {
    values: &'a [T],
}

impl<'a, T> RowGather<'a, T, true> {
    fn checked(values: &'a [T]) -> Self {
        RowGather { values }
    }
}

impl<'a, T> RowGather<'a, T, false> {
    /// The loads without checks, where every index of `chunk`'s rows and the one after it lie
    /// inside `values` (the three-component loads read 16 bytes, into the next element).
    fn unchecked<R>(values: &'a [T], chunk: &PairChunk<R>) -> Option<Self> {
        (chunk.max_index as usize + 1 < values.len()).then_some(RowGather { values })
    }
}

impl<R: Real, const CHECKED: bool> RowGather<'_, [R; 3], CHECKED> {
    #[inline(always)]
    fn vectors(self, row: &[u32; LANES]) -> PackV3<R> {
        if CHECKED {
            PackV3::gather(self.values, row)
        } else {
            // SAFETY: every index of the chunk's rows is below len - 1 (`unchecked`).
            unsafe { PackV3::gather_unchecked(self.values, row) }
        }
    }
}

impl<R: Real, const CHECKED: bool> RowGather<'_, R, CHECKED> {
    #[inline(always)]
    fn scalars(self, row: &[u32; LANES]) -> Pack<R> {
        if CHECKED {
            Pack::gather(self.values, row)
        } else {
            // SAFETY: every index of the chunk's rows is below len - 1 (`unchecked`).
            unsafe { Pack::gather_unchecked(self.values, row) }
        }
    }
}

/// A row's gradients as three packs.
#[inline(always)]
fn row_gradient<R: Real>(g: &[[R; LANES]; 3]) -> PackV3<R> {
    PackV3 { x: Pack::from_array(g[0]), y: Pack::from_array(g[1]), z: Pack::from_array(g[2]) }
}

/// D_i of one particle or of a batch's lanes.
pub enum Rates<'a, R: Real> {
    /// The particle's place in its chunk, and its D_i.
    One(usize, R),
    /// Eight lanes' D_i, each the scalar value bit for bit; lanes past `count` hold the batch's
    /// first particle again and must be left out.
    Eight(&'a BatchLanes, Pack<R>),
}

impl<R: Real> Rates<'_, R> {
    /// Each particle's D_i in turn, to `each(local, D_i)` (for the passes that run once a step).
    #[inline(always)]
    pub fn each_particle(self, mut each: impl FnMut(usize, R)) {
        match self {
            Rates::One(local, d) => each(local, d),
            Rates::Eight(lanes, d) => {
                for (lane, &d) in d.to_array().iter().enumerate().take(lanes.count) {
                    each(lanes.local + lane, d);
                }
            }
        }
    }
}

/// D_i (as [`density_rate`]) of every particle of chunk `c` (of `count` particles), given to
/// `each` in the chunk's order: one particle at a time on the scalar path, eight at a time on
/// the lane path.
#[inline(always)]
pub fn density_rates<R: Real>(input: &SolveInput<R>, c: usize, count: usize, velocities: &[V3<R>], mut each: impl FnMut(Rates<R>)) {
    let chunk = &input.pairs.chunks[c];
    let first = c * CHUNK;
    if chunk.batches.is_empty() {
        for local in 0..count {
            let i = first + local;
            each(Rates::One(local, density_rate(chunk, local, input.volume, velocities, velocities[i], input.wall_gradients[i])));
        }
        return;
    }
    let v = as_arrays(velocities);
    match RowGather::unchecked(v, chunk) {
        Some(v) => rates_by_rows(input, chunk, first, v, &mut each),
        None => rates_by_rows(input, chunk, first, RowGather::checked(v), &mut each),
    }
}

/// The lane path of [`density_rates`].
#[inline(always)]
fn rates_by_rows<R: Real, const CHECKED: bool>(input: &SolveInput<R>, chunk: &PairChunk<R>, first: usize, v: RowGather<'_, [R; 3], CHECKED>, each: &mut impl FnMut(Rates<R>)) {
    let wall_gradients = as_arrays(input.wall_gradients);
    each_batch(chunk, first, #[inline(always)] |batch, lanes| {
        let vi = PackV3::gather(v.values, &lanes.slots);
        let mut sum = Pack::zero();
        batch_rows(chunk, batch, #[inline(always)] |row, g| sum = sum + (vi - v.vectors(row)).dot(g));
        // The end of `density_rate`.
        each(Rates::Eight(lanes, sum * Pack::splat(input.volume) + vi.dot(PackV3::gather(wall_gradients, &lanes.slots))));
    })
}

/// The particles of a batch's lanes.
pub struct BatchLanes {
    /// Their slots; lanes past `count` repeat the first.
    pub slots: [u32; LANES],
    /// The first one's place in its chunk, and how many there are.
    pub local: usize,
    pub count: usize,
}

impl BatchLanes {
    /// Lanes past the batch's particles repeat its first: they are left out wherever they
    /// would count.
    #[inline(always)]
    pub fn of(first: usize, batch: &RowBatch) -> BatchLanes {
        let (local, count) = (batch.local as usize, batch.lanes as usize);
        let slots = std::array::from_fn(|k| (first + local + if k < count { k } else { 0 }) as u32);
        BatchLanes { slots, local, count }
    }

    /// The lanes' places in their chunk (`first`: the chunk's first slot).
    #[inline(always)]
    pub fn locals(&self, first: usize) -> [u32; LANES] {
        self.slots.map(|s| s - first as u32)
    }

    /// Writes the first `count` lanes of `values` to `out` from `local` on.
    #[inline(always)]
    pub fn store<R: Real>(&self, values: Pack<R>, out: &mut [R]) {
        out[self.local..self.local + self.count].copy_from_slice(&values.to_array()[..self.count]);
    }
}

/// [`error_units`] of the first `count` lanes, summed.
#[inline(always)]
pub fn error_units_lanes<R: Real>(error: Pack<R>, count: usize) -> u64 {
    let (zero, clamp, inf) = (Pack::zero(), Pack::splat(R::of(ERROR_CLAMP)), Pack::splat(R::infinity()));
    let finite = error.lt(inf).and(Pack::splat(R::neg_infinity()).lt(error));
    // As error.max(0).min(clamp): a non-positive error (whatever the sign of its zero) counts 0.
    let clamped = Pack::select(zero.lt(error), error, zero);
    let clamped = Pack::select(clamped.lt(clamp), clamped, clamp);
    let scaled = Pack::select(finite, clamped * Pack::splat(R::of((1u64 << ERROR_FRACTION_BITS) as f64)), zero).to_array();
    scaled.iter().take(count).map(|&e| e.to64() as u64).sum()
}

/// v_i -= scale (V sum_j (K_i + K_j) grad W_ij + K_i g_i^w) and the sum of K_i, for every
/// particle: the Jacobi step shared by both solves.
pub fn apply_stiffness<R: Real>(input: &SolveInput<R>, stiffness: &[R], scale: R, velocities: &mut [V3<R>], sums: &mut [R]) {
    input.pairs.chunks.par_iter().zip(velocities.par_chunks_mut(CHUNK)).zip(sums.par_chunks_mut(CHUNK)).enumerate().for_each(|(c, ((chunk, v), sum))| {
        let first = c * CHUNK;
        if chunk.batches.is_empty() {
            for local in 0..v.len() {
                let i = first + local;
                let ki = stiffness[i];
                v[local] -= stiffness_push(chunk, local, input.volume, stiffness, ki, input.wall_gradients[i]) * scale;
                sum[local] = sum[local] + ki;
            }
            return;
        }
        match RowGather::unchecked(stiffness, chunk) {
            Some(k) => push_by_rows(input, chunk, first, k, scale, v, sum),
            None => push_by_rows(input, chunk, first, RowGather::checked(stiffness), scale, v, sum),
        }
    });
}

/// The lane path of [`apply_stiffness`] on one chunk (`v` and `sum`: its particles').
#[inline(always)]
fn push_by_rows<R: Real, const CHECKED: bool>(input: &SolveInput<R>, chunk: &PairChunk<R>, first: usize, stiffness: RowGather<'_, R, CHECKED>, scale: R, v: &mut [V3<R>], sum: &mut [R]) {
    let wall_gradients = as_arrays(input.wall_gradients);
    each_batch(chunk, first, #[inline(always)] |batch, lanes| {
        let ki = Pack::gather(stiffness.values, &lanes.slots);
        let mut push = PackV3::zero();
        batch_rows(chunk, batch, #[inline(always)] |row, g| push = push + g.scale(ki + stiffness.scalars(row)));
        // The end of `stiffness_push`, and v_i -= push * scale.
        let push = push.scale(Pack::splat(input.volume)) + PackV3::gather(wall_gradients, &lanes.slots).scale(ki);
        let local = lanes.locals(first);
        let vi = PackV3::gather(as_arrays(v), &local) - push.scale(Pack::splat(scale));
        let (vi, sum_i) = (vi.to_arrays(), (Pack::gather(sum, &local) + ki).to_array());
        for k in 0..lanes.count {
            v[lanes.local + k] = V3(vi[k]);
            sum[lanes.local + k] = sum_i[k];
        }
    })
}

/// Where a solve starts: `share` of the last step's stiffness sum, kept by particle id.
pub struct WarmStart<'a, R> {
    pub ids: &'a [u32],
    pub last: &'a [R],
    pub share: R,
}

/// The share of the last step's stiffness both solves start from (where the particle is being
/// compressed): half, as in SPlisHSPlasH. The whole of it measured unstable: a stiffness that
/// answered a passing compression (an impact, the first step's settling) pushes again in the
/// next step, with nothing to stop it, since a solve only ever adds pushing stiffness.
pub const WARM_START_SHARE: f64 = 0.5;


/// Below this, the denominator of alpha (in 1/m^2) counts as zero: a particle with so few
/// neighbours is not pushed.
pub fn factor_epsilon(h: f64) -> f64 {
    1e-6 / (h * h)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lanes_count_the_scalar_units<R: Real>() {
        let values = [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, -0.0, 0.0, -1.5, 3.5, 3.0, 1e-4, 0.7, 2.999, 1e-12];
        for window in values.windows(LANES) {
            let errors: [R; LANES] = std::array::from_fn(|k| R::of(window[k]));
            for count in [LANES, 5, 1] {
                let scalar: u64 = errors.iter().take(count).map(|&e| error_units(e)).sum();
                let lanes = wide(|| error_units_lanes(Pack::from_array(errors), count));
                assert_eq!(lanes, scalar, "errors {window:?}, {count} lanes");
            }
        }
    }

    #[test]
    fn error_units_of_eight_lanes_are_the_scalar_units() {
        if !super::super::cell_batches::lanes_available() {
            return;
        }
        lanes_count_the_scalar_units::<f32>();
        lanes_count_the_scalar_units::<f64>();
    }
}
