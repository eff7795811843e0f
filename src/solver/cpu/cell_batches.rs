//! How the CPU path walks the neighbours eight particles at a time: consecutive particles of one
//! cell in batches of [`LANES`] (they share one stencil of 27 cells), and each particle's
//! neighbour lists (fluid and walls), built once per step by the density stage and read again
//! by the forces.
//!
//! A batch's lists are stored as rows of [`LANES`] indices: row t holds the t-th neighbour of
//! every lane, so that the density and forces passes walk the eight lists together, each lane
//! computing its own particle's sum in vector registers (see [`crate::model::lanes`]). A lane's
//! list holds the particles of the stencil in the order the GPU visits them (the 9 runs of
//! cells, each run in cell order), keeping those closer than h (`!(r^2 >= h^2)`, the scalar
//! loops' test with the same arithmetic): the pairs the scalar loops skip are left out, so every
//! lane's sum is the scalar sum bit for bit, whatever the number of threads.
//!
//! The batches are grouped in chunks of [`BATCHES_PER_CHUNK`], the unit of parallel work; a
//! chunk's arrays are kept from step to step, so that stepping allocates nothing once the lists
//! have reached their size.

use crate::model::kernels::Neighbours;
use crate::model::lanes::{Mask, Pack, PackV3, LANES};
use crate::model::params::Grid;
use crate::model::real::{as_arrays, Real};
use rayon::prelude::*;

/// Batches per chunk (about 256 particles in a full fluid).
pub const BATCHES_PER_CHUNK: usize = 32;

/// Up to [`LANES`] consecutive particles of one cell, and where their neighbour lists are.
#[derive(Clone, Copy, Debug, Default)]
pub struct Batch {
    /// The batch's first particle (in cell order) and its number of particles.
    pub first: u32,
    pub lanes: u32,
    cell: [u32; 3],
    fluid: Lists,
    walls: Lists,
}

impl Batch {
    /// The particle of each lane; lanes past the batch's particles repeat its first (they are
    /// masked out wherever they would count).
    #[inline(always)]
    pub fn indices(&self) -> [u32; LANES] {
        let mut index = [self.first; LANES];
        for k in 1..self.lanes as usize {
            index[k] = self.first + k as u32;
        }
        index
    }
}

/// The lists of one batch's lanes: `rows` rows from `offset` in its chunk's rows, and the
/// length of each lane's list.
#[derive(Clone, Copy, Debug, Default)]
struct Lists {
    offset: u32,
    rows: u32,
    counts: [u32; LANES],
}

/// One chunk of batches, consecutive in cell order, and their lists.
#[derive(Clone, Debug, Default)]
pub struct ListChunk {
    pub batches: Vec<Batch>,
    fluid_rows: Vec<[u32; LANES]>,
    wall_rows: Vec<[u32; LANES]>,
    found: Candidates,
}

impl ListChunk {
    /// The particles of the chunk: `first..end`.
    pub fn particles(&self) -> std::ops::Range<usize> {
        match (self.batches.first(), self.batches.last()) {
            (Some(a), Some(b)) => a.first as usize..(b.first + b.lanes) as usize,
            _ => 0..0,
        }
    }

    /// The rows of a batch's fluid neighbour lists, and how long each lane's list is.
    #[inline(always)]
    pub fn fluid_rows(&self, batch: &Batch) -> (&[[u32; LANES]], [u32; LANES]) {
        let l = &batch.fluid;
        (&self.fluid_rows[l.offset as usize..(l.offset + l.rows) as usize], l.counts)
    }

    /// The rows of a batch's wall neighbour lists, and how long each lane's list is.
    #[inline(always)]
    pub fn wall_rows(&self, batch: &Batch) -> (&[[u32; LANES]], [u32; LANES]) {
        let l = &batch.walls;
        (&self.wall_rows[l.offset as usize..(l.offset + l.rows) as usize], l.counts)
    }

    fn bytes(&self) -> u64 {
        let rows = (self.fluid_rows.capacity() + self.wall_rows.capacity()) * 4 * LANES;
        (self.batches.capacity() * std::mem::size_of::<Batch>() + rows + self.found.index.capacity() * 4 + self.found.lanes.capacity()) as u64
    }
}

/// Walks rows of lists of lengths `counts`, giving the lanes that have an entry in each row.
pub struct RowMasks<R: Real> {
    row: Pack<R>,
    counts: Pack<R>,
}

impl<R: Real> RowMasks<R> {
    #[inline(always)]
    pub fn new(counts: &[u32; LANES]) -> Self {
        // Small integers, exact in either float type.
        let mut lengths = [R::zero(); LANES];
        for k in 0..LANES {
            lengths[k] = R::of(counts[k] as f64);
        }
        RowMasks { row: Pack::zero(), counts: Pack::from_array(lengths) }
    }
    /// The mask of the next row.
    #[inline(always)]
    pub fn next_row(&mut self) -> Mask<R> {
        let live = self.row.lt(self.counts);
        self.row = self.row + Pack::splat(R::one());
        live
    }
}

/// The batches of every fluid particle and their neighbour lists, for the current positions.
#[derive(Clone, Debug, Default)]
pub struct NeighbourLists {
    chunks: Vec<ListChunk>,
    /// Chunks in use (the others keep their arrays for a later step).
    used: usize,
    /// Each particle's cell, for the batching.
    cells: Vec<[u32; 3]>,
}

impl NeighbourLists {
    /// The chunks of the last [`NeighbourLists::build`].
    pub fn chunks(&self) -> &[ListChunk] {
        &self.chunks[..self.used]
    }

    /// No lists: the forces then walk each particle's stencil.
    pub fn clear(&mut self) {
        self.used = 0;
    }

    /// Bytes held by the lists.
    pub fn bytes(&self) -> u64 {
        self.chunks.iter().map(ListChunk::bytes).sum::<u64>() + self.cells.capacity() as u64 * 12
    }

    /// `values` cut into the particles of each chunk (the chunks cover every particle in order).
    pub fn split<'a, T>(&self, mut values: &'a mut [T]) -> Vec<&'a mut [T]> {
        let mut parts = Vec::with_capacity(self.used);
        for chunk in self.chunks() {
            let (part, rest) = values.split_at_mut(chunk.particles().len());
            parts.push(part);
            values = rest;
        }
        parts
    }

    /// Batches for the cell-sorted particles, and every particle's neighbours in `fluid` and
    /// `walls` closer than h (`h2` = h^2); without walls (`walls.positions` empty) no wall list.
    pub fn build<R: Real>(&mut self, grid: &Grid<R>, fluid: Neighbours<R>, walls: Neighbours<R>, h2: R) {
        self.batch(grid, fluid.positions);
        let with_walls = !walls.positions.is_empty();
        self.chunks[..self.used].par_iter_mut().for_each(|chunk| {
            wide(
                #[inline(always)]
                || {
                    let ListChunk { batches, fluid_rows, wall_rows, found } = chunk;
                    fluid_rows.clear();
                    wall_rows.clear();
                    for batch in batches.iter_mut() {
                        let live = Mask::first(batch.lanes as usize);
                        let xi = PackV3::gather(as_arrays(fluid.positions), &batch.indices());
                        let runs = Runs::of(grid, batch.cell);
                        let lanes = batch.lanes as usize;
                        batch.fluid = list(fluid_rows, found, xi, live, lanes, fluid, &runs, h2);
                        if with_walls {
                            batch.walls = list(wall_rows, found, xi, live, lanes, walls, &runs, h2);
                        }
                    }
                },
            )
        });
    }

    /// The batches of the particles in their order: runs of up to [`LANES`] consecutive
    /// particles in the same cell (by their current positions, as the scalar loops find their
    /// stencil: between two rebuilds of the grid a particle may have left the cell it was
    /// sorted into), dealt into chunks.
    fn batch<R: Real>(&mut self, grid: &Grid<R>, positions: &[crate::model::real::V3<R>]) {
        for chunk in &mut self.chunks {
            chunk.batches.clear();
        }
        self.used = 0;
        // The cells in parallel, the batches (cheap) in order.
        let mut cells = std::mem::take(&mut self.cells);
        cells.resize(positions.len(), [0; 3]);
        cells.par_iter_mut().zip(positions.par_iter()).for_each(|(c, &x)| *c = grid.cell_coords(x));
        let mut open: Option<Batch> = None;
        for (i, &cell) in cells.iter().enumerate() {
            match &mut open {
                Some(b) if b.cell == cell && (b.lanes as usize) < LANES => b.lanes += 1,
                _ => {
                    if let Some(b) = open.take() {
                        self.push(b);
                    }
                    open = Some(Batch { first: i as u32, lanes: 1, cell, ..Batch::default() });
                }
            }
        }
        if let Some(b) = open {
            self.push(b);
        }
        self.cells = cells;
    }

    fn push(&mut self, batch: Batch) {
        if self.used == 0 || self.chunks[self.used - 1].batches.len() == BATCHES_PER_CHUNK {
            if self.used == self.chunks.len() {
                self.chunks.push(ListChunk::default());
            }
            self.used += 1;
        }
        self.chunks[self.used - 1].batches.push(batch);
    }
}

/// Working arrays of [`lane_lists`], kept from batch to batch so that listing allocates nothing
/// once they have reached their size.
#[derive(Clone, Debug, Default)]
pub struct LaneScratch {
    found: Candidates,
}

impl LaneScratch {
    pub fn bytes(&self) -> u64 {
        (self.found.index.capacity() * 4 + self.found.lanes.capacity()) as u64
    }
}

/// The neighbours in `others` closer than h (`h2` = h^2) of the first `lane_count` lanes at
/// `xi`, whose particles lie in `cell`: the rows of their lists are appended to `rows` (row t
/// holds the t-th neighbour of every lane, in the scalar loops' visiting order; entries past a
/// lane's list are index 0), and each lane's count is returned. The same two-pass build as the
/// density stage's lists, for callers that keep their own layout (DFSPH's lists).
#[inline(always)]
pub fn lane_lists<R: Real>(rows: &mut Vec<[u32; LANES]>, scratch: &mut LaneScratch, xi: PackV3<R>, lane_count: usize, others: Neighbours<R>, grid: &Grid<R>, cell: [u32; 3], h2: R) -> [u32; LANES] {
    let runs = Runs::of(grid, cell);
    list(rows, &mut scratch.found, xi, Mask::first(lane_count), lane_count, others, &runs, h2).counts
}

/// The 9 runs of cells of a stencil (`Grid::stencil_runs`), as an array.
struct Runs {
    runs: [(u32, u32); 9],
    len: usize,
}

impl Runs {
    #[inline(always)]
    fn of<R: Real>(grid: &Grid<R>, cell: [u32; 3]) -> Runs {
        let mut out = Runs { runs: [(0, 0); 9], len: 0 };
        for run in grid.stencil_runs(cell) {
            out.runs[out.len] = run;
            out.len += 1;
        }
        out
    }
}

/// A chunk's working arrays for [`list`]: the stencil's particles that are near some lane of
/// a batch, and those lanes (bit k for lane k).
#[derive(Clone, Debug, Default)]
struct Candidates {
    index: Vec<u32>,
    lanes: Vec<u8>,
}

/// Appends the lists of the lanes `live` at `xi` among `others` over the stencil's runs to
/// `rows`, in the visiting order, and says where they are.
///
/// Two passes: every particle of the stencil is tested against the eight lanes at once, and
/// those near at least one lane are kept with their lanes' bits; then each lane's list is read
/// off those bits, 32 candidates at a time, and written down its column of the rows. This keeps
/// each lane's count in a register and its loop short, where writing every candidate to its
/// lanes at once would step through eight counts in memory.
#[inline(always)]
fn list<R: Real>(rows: &mut Vec<[u32; LANES]>, found: &mut Candidates, xi: PackV3<R>, live: Mask<R>, lane_count: usize, others: Neighbours<R>, runs: &Runs, h2: R) -> Lists {
    let mut stencil = 0;
    for &(k0, k1) in &runs.runs[..runs.len] {
        stencil += others.span(k0, k1).len();
    }
    // Room for every particle of the stencil, and zero bits up to a whole block of 32.
    let room = stencil.div_ceil(32) * 32 + 32;
    found.index.clear();
    found.index.resize(room, 0);
    found.lanes.clear();
    found.lanes.resize(room, 0);
    let positions = as_arrays(others.positions);
    let h2 = Pack::splat(h2);
    // Plain slices, so that the stores of lane bits (bytes, which may alias anything) do not
    // make the compiler load the vectors' pointers again for every candidate.
    let (index, lane_bytes) = (&mut found.index[..], &mut found.lanes[..]);
    let mut kept = 0;
    for &(k0, k1) in &runs.runs[..runs.len] {
        for j in others.span(k0, k1) {
            let d = xi - PackV3::splat(positions[j]);
            let near = d.dot(d).ge(h2).and_not(live).bits();
            // Written always, kept (the slot advanced) only where some lane is near.
            index[kept] = j as u32;
            lane_bytes[kept] = near as u8;
            kept += (near != 0) as usize;
        }
    }
    lane_bytes[kept..].fill(0);
    // No list is longer than the candidates kept; the rows past the longest list are cut off
    // below, and the entries past a shorter list keep index 0, a valid index that the row's
    // mask leaves out.
    let offset = rows.len();
    rows.resize(offset + kept, [0; LANES]);
    let block = &mut rows[offset..];
    let (index, lane_bytes) = (&found.index[..], &found.lanes[..]);
    let mut counts = [0u32; LANES];
    for (k, count) in counts.iter_mut().enumerate().take(lane_count) {
        let mut n = 0usize;
        for first in (0..kept).step_by(32) {
            let lanes: &[u8; 32] = lane_bytes[first..first + 32].try_into().expect("32 candidates");
            let mut bits = lane_bits(lanes, k);
            while bits != 0 {
                let c = first + bits.trailing_zeros() as usize;
                block[n][k] = index[c];
                n += 1;
                bits &= bits - 1;
            }
        }
        *count = n as u32;
    }
    let longest = counts.iter().copied().max().unwrap_or(0) as usize;
    rows.truncate(offset + longest);
    Lists { offset: offset as u32, rows: longest as u32, counts }
}

/// Bit c set where candidate c of the 32 has lane `k`'s bit.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn lane_bits(lanes: &[u8; 32], k: usize) -> u32 {
    use std::arch::x86_64::*;
    // SAFETY: AVX2 integer instructions, run only inside `wide` (the processor has AVX2); the
    // load reads the 32 bytes of the array.
    unsafe {
        let v = _mm256_loadu_si256(lanes.as_ptr().cast());
        let bit = _mm256_set1_epi8(1i8 << k);
        _mm256_movemask_epi8(_mm256_cmpeq_epi8(_mm256_and_si256(v, bit), bit)) as u32
    }
}

/// Bit c set where candidate c of the 32 has lane `k`'s bit.
#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn lane_bits(lanes: &[u8; 32], k: usize) -> u32 {
    (0..32).fold(0, |bits, c| bits | ((((lanes[c] >> k) & 1) as u32) << c))
}

/// Runs `task` compiled for AVX2 (the packs' instructions); the callers check
/// [`lanes_available`] first. The values are those of the scalar loops (the same IEEE
/// operations in the same order, no fused multiply-add).
#[inline]
pub fn wide<T>(task: impl FnOnce() -> T) -> T {
    #[cfg(target_arch = "x86_64")]
    {
        assert!(lanes_available(), "the lane path runs only where the processor has AVX2");
        // SAFETY: `with_avx2` requires AVX2, which the processor was just found to have.
        unsafe { with_avx2(task) }
    }
    #[cfg(not(target_arch = "x86_64"))]
    task()
}

/// `out[i]` = (x, y, z, 0) of `positions[i]`: what the density's neighbour loads read (the
/// forces then put p / rho^2 in the fourth place).
pub fn points<R: Real>(positions: &[crate::model::real::V3<R>], out: &mut Vec<[R; 4]>) {
    out.resize(positions.len(), [R::zero(); 4]);
    out.par_iter_mut().zip(positions.par_iter()).for_each(|(p, x)| *p = [x.0[0], x.0[1], x.0[2], R::zero()]);
}

/// Whether the processor runs the packs' instructions (AVX2 on x86-64; elsewhere the packs are
/// arrays, which run anywhere).
pub fn lanes_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    return std::arch::is_x86_feature_detected!("avx2");
    #[cfg(not(target_arch = "x86_64"))]
    true
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn with_avx2<T>(task: impl FnOnce() -> T) -> T {
    task()
}
