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

use super::cell_batches::LaneScratch;
use crate::model::lanes::LANES;
use crate::model::real::{Real, V3};
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
#[derive(Clone, Debug, Default)]
pub struct PairChunk<R> {
    /// `starts[k]..starts[k + 1]`: the pairs of the chunk's particle k.
    pub starts: Vec<u32>,
    pub index: Vec<u32>,
    pub grad: Vec<V3<R>>,
    /// The factors pass's working arrays for eight particles at a time (kept between steps).
    pub work: LaneWork<R>,
}

/// What the factors pass builds a batch of up to eight particles' lists in: the rows of their
/// fluid and wall neighbours (`cell_batches::lane_lists`) and the fluid rows' kernel gradients.
#[derive(Clone, Debug, Default)]
pub struct LaneWork<R> {
    pub rows: Vec<[u32; LANES]>,
    pub gradients: Vec<[[R; 3]; LANES]>,
    pub scratch: LaneScratch,
}

impl<R> LaneWork<R> {
    fn bytes(&self) -> u64 {
        (self.rows.capacity() * 4 * LANES + self.gradients.capacity() * std::mem::size_of::<[[R; 3]; LANES]>()) as u64 + self.scratch.bytes()
    }
}

/// The neighbour lists of every fluid particle, by chunks of [`CHUNK`] particles.
#[derive(Clone, Debug, Default)]
pub struct Pairs<R> {
    pub chunks: Vec<PairChunk<R>>,
}

impl<R: Real> Pairs<R> {
    /// Pairs listed (each pair of particles twice, once from each side).
    pub fn len(&self) -> usize {
        self.chunks.iter().map(|c| c.index.len()).sum()
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    pub fn bytes(&self) -> u64 {
        self.chunks.iter().map(|c| (c.index.capacity() * 4 + c.grad.capacity() * std::mem::size_of::<V3<R>>() + c.starts.capacity() * 4) as u64 + c.work.bytes()).sum()
    }
}

/// What the solves read besides the velocities.
pub struct SolveInput<'a, R> {
    pub pairs: &'a Pairs<R>,
    /// The fluid particle's volume V = m / rho0.
    pub volume: R,
    pub factors: &'a [R],
    pub wall_gradients: &'a [V3<R>],
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

/// v_i -= scale (V sum_j (K_i + K_j) grad W_ij + K_i g_i^w) and the sum of K_i, for every
/// particle: the Jacobi step shared by both solves.
pub fn apply_stiffness<R: Real>(input: &SolveInput<R>, stiffness: &[R], scale: R, velocities: &mut [V3<R>], sums: &mut [R]) {
    input.pairs.chunks.par_iter().zip(velocities.par_chunks_mut(CHUNK)).zip(sums.par_chunks_mut(CHUNK)).enumerate().for_each(|(c, ((chunk, v), sum))| {
        for local in 0..v.len() {
            let i = c * CHUNK + local;
            let ki = stiffness[i];
            v[local] -= stiffness_push(chunk, local, input.volume, stiffness, ki, input.wall_gradients[i]) * scale;
            sum[local] = sum[local] + ki;
        }
    });
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
