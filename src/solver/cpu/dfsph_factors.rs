//! DFSPH, stage 1 of a step (after the binning): density, the factor alpha, the wall gradient
//! and the output pressure. Twin of
//! wgsl/sim/dfsph_factors.wgsl (`density_and_factor`); the CPU also lists each particle's
//! neighbours with their kernel gradients here, for the passes that follow.

use super::cell_batches::{lane_lists, lanes_available, wide, RowMasks};
use super::dfsph_shared::{BatchLanes, LaneWork, PairChunk, Pairs, RowBatch, WallSums, CHUNK};
use crate::model::kernels::{KernelCoefficients, Neighbours};
use crate::model::lanes::{Pack, PackV3, LANES};
use crate::model::params::Grid;
use crate::model::real::{as_arrays, Real, V3};
use rayon::prelude::*;

pub struct FactorsInput<'a, R> {
    pub kernel: &'a KernelCoefficients<R>,
    pub grid: &'a Grid<R>,
    pub fluid_mass: R,
    pub rest_density: R,
    /// The fluid particle's volume m / rho0.
    pub volume: R,
    pub fluid: Neighbours<'a, R>,
    pub walls: Neighbours<'a, R>,
    pub wall_masses: &'a [R],
    /// Each slot's particle id, and the last step's constant-density stiffness sums by id.
    pub ids: &'a [u32],
    pub warm_pressure: &'a [R],
    /// 1 / (rho0 dt^2) of the last step (0 before the first): the output pressure is
    /// p = rho^2 K / (rho0 dt^2), the pressure whose force -m sum (p_i / rho_i^2 + p_j / rho_j^2)
    /// grad W is the constant-density solve's velocity change over dt.
    pub pressure_scale: R,
    /// Below this, alpha's denominator counts as zero (too few neighbours to push).
    pub factor_epsilon: R,
    /// Whether to list and sum eight particles at a time where the processor can (the same
    /// bits as the scalar loop).
    pub lanes: bool,
}

/// The arrays the stage writes, each one value per fluid particle in slot order.
pub struct FactorsOutput<'a, R> {
    pub densities: &'a mut [R],
    pub pressures: &'a mut [R],
    pub factors: &'a mut [R],
    pub wall_gradients: &'a mut [V3<R>],
    /// The sum of the divergence solve's stiffness, started at 0.
    pub divergence_sum: &'a mut [R],
}

/// One particle's values (wgsl `particle_factors`), its neighbours appended to `chunk`.
struct Factors<R> {
    density: R,
    factor: R,
    wall_gradient: V3<R>,
}

fn particle_factors<R: Real>(input: &FactorsInput<R>, i: usize, chunk: &mut PairChunk<R>) -> Factors<R> {
    let kernel = input.kernel;
    let walls = !input.wall_masses.is_empty();
    let xi = input.fluid.positions[i];
    let c = input.grid.cell_coords(xi);
    let mut fluid_sum = R::zero();
    let mut wall_sum = R::zero();
    let mut fluid_gradient = V3::zero();
    let mut gradient_squares = R::zero();
    let mut wall_gradient = V3::zero();
    for (k0, k1) in input.grid.stencil_runs(c) {
        for j in input.fluid.span(k0, k1) {
            let rij = xi - input.fluid.positions[j];
            let r2 = rij.length_squared();
            if r2 >= kernel.h2 {
                continue;
            }
            fluid_sum = fluid_sum + kernel.w(r2);
            let grad = kernel.grad_w(rij, r2.sqrt());
            fluid_gradient += grad;
            gradient_squares = gradient_squares + grad.dot(grad);
            // The particle itself (and one at the same spot) has no gradient: not listed.
            if grad != V3::zero() {
                chunk.index.push(j as u32);
                chunk.grad.push(grad);
            }
        }
        for j in if walls { input.walls.span(k0, k1) } else { 0..0 } {
            let rij = xi - input.walls.positions[j];
            let r2 = rij.length_squared();
            if r2 >= kernel.h2 {
                continue;
            }
            let mw = input.wall_masses[j];
            wall_sum = wall_sum + mw * kernel.w(r2);
            wall_gradient += kernel.grad_w(rij, r2.sqrt()) * mw;
        }
    }
    finish(input, Sums { fluid_sum, wall_sum, fluid_gradient, gradient_squares, wall_gradient })
}

/// One particle's sums over its neighbours: sum_j W_ij, sum_b m_b W_ib, sum_j grad W_ij,
/// sum_j |grad W_ij|^2 and sum_b m_b grad W_ib.
struct Sums<R> {
    fluid_sum: R,
    wall_sum: R,
    fluid_gradient: V3<R>,
    gradient_squares: R,
    wall_gradient: V3<R>,
}

#[inline(always)]
fn finish<R: Real>(input: &FactorsInput<R>, sums: Sums<R>) -> Factors<R> {
    let volume = input.volume;
    // V_b grad W = (m_b / rho0) grad W.
    let wall_gradient = sums.wall_gradient / input.rest_density;
    let total = sums.fluid_gradient * volume + wall_gradient;
    let denominator = total.dot(total) + volume * volume * sums.gradient_squares;
    let factor = if denominator > input.factor_epsilon { R::one() / denominator } else { R::zero() };
    Factors { density: input.fluid_mass * sums.fluid_sum + sums.wall_sum, factor, wall_gradient }
}

/// One cell's particles `local..local + lanes` of a chunk (`lanes` <= 8; the chunk's first
/// slot is `chunk_first`, it has `count` particles) eight at a time: their fluid neighbours
/// listed by the two-pass lane build and appended to the chunk's groups ([`keep_lists`]), and
/// their sums over the walls (kept in `chunk.work.walls`), each lane's in the scalar loop's
/// order (the same bits).
#[inline(always)]
fn cell_lists<R: Real>(input: &FactorsInput<R>, chunk_first: usize, local: usize, lanes: usize, count: usize, cell: [u32; 3], chunk: &mut PairChunk<R>) {
    let kernel = input.kernel;
    let first = chunk_first + local;
    let index: [u32; LANES] = std::array::from_fn(|k| (first + if k < lanes { k } else { 0 }) as u32);
    let xi = PackV3::gather(as_arrays(input.fluid.positions), &index);
    let LaneWork { rows, wall_rows, scratch, walls } = &mut chunk.work;
    rows.clear();
    let counts = lane_lists(rows, scratch, xi, lanes, input.fluid, input.grid, cell, kernel.h2);

    let (mut wall_sum, mut wall_gradient) = (Pack::zero(), PackV3::zero());
    if !input.wall_masses.is_empty() {
        let wall_positions = as_arrays(input.walls.positions);
        wall_rows.clear();
        let counts = lane_lists(wall_rows, scratch, xi, lanes, input.walls, input.grid, cell, kernel.h2);
        let mut live = RowMasks::new(&counts);
        for row in wall_rows.iter() {
            let d = xi - PackV3::gather(wall_positions, row);
            let r2 = d.dot(d);
            let mw = Pack::gather(input.wall_masses, row);
            let m = live.next_row();
            wall_sum = Pack::select(m, wall_sum + mw * kernel.w_lanes(r2), wall_sum);
            wall_gradient = PackV3::select(m, wall_gradient + kernel.grad_w_lanes(d, r2.sqrt()).scale(mw), wall_gradient);
        }
    }
    let (wall_sum, wall_gradient) = (wall_sum.to_array(), wall_gradient.to_arrays());
    walls.resize(CHUNK, WallSums::default());
    for k in 0..lanes {
        walls[local + k] = WallSums { sum: wall_sum[k], gradient: V3(wall_gradient[k]) };
    }
    keep_lists(chunk, chunk_first, local, lanes, count, &counts);
}

/// Appends the lists of one cell's particles (the chunk's `local..local + lanes`, in
/// `chunk.work.rows`, `counts` long) to the chunk's groups of eight consecutive particles,
/// whatever their cells, which the factors and the solves then read: a cell's batch is often
/// short of eight and its rows as long as its longest list, so the groups' rows hold fewer
/// empty entries (the groups fill 90-95 % of their entries on the block workload, the cells'
/// batches 64-81 %). The entries past a lane's list are its own particle, whose gradient is
/// zero. `chunk_first`: the chunk's first slot; `count`: its particles.
#[inline(always)]
fn keep_lists<R: Real>(chunk: &mut PairChunk<R>, chunk_first: usize, local: usize, lanes: usize, count: usize, counts: &[u32; LANES]) {
    let PairChunk { batches, rows, max_index, work, .. } = chunk;
    let mut largest = *max_index;
    for (k, &n) in counts.iter().enumerate().take(lanes) {
        let p = local + k;
        let lane = p % LANES;
        if lane == 0 {
            let group = (count - p).min(LANES);
            batches.push(RowBatch { local: p as u32, lanes: group as u32, first_row: rows.len() as u32, rows: 0, counts: [0; LANES] });
            // The padding entries: each lane's own particle, the group's first past the chunk's
            // particles (as `BatchLanes` has them).
            largest = largest.max((chunk_first + p + group - 1) as u32);
        }
        let batch = batches.last_mut().expect("a group is opened at its first lane");
        let n = n as usize;
        if n > batch.rows as usize {
            let own = BatchLanes::of(chunk_first, batch).slots;
            rows.resize(batch.first_row as usize + n, own);
            batch.rows = n as u32;
        }
        batch.counts[lane] = n as u32;
        let first_row = batch.first_row as usize;
        for (out, row) in rows[first_row..first_row + n].iter_mut().zip(&work.rows[..n]) {
            out[lane] = row[k];
            largest = largest.max(row[k]);
        }
    }
    *max_index = largest;
}

/// The density, factor and wall gradient of the chunk's group `g` of eight particles, whose lists
/// [`keep_lists`] has appended and whose wall sums [`cell_lists`] has kept: the kernel and its
/// gradient on eight pairs at once, each lane's sums in the scalar loop's order (the same bits),
/// the gradients kept beside the group's rows for the solves (zero at the entries past a
/// lane's list, its own particle).
#[inline(always)]
fn group_factors<R: Real>(input: &FactorsInput<R>, chunk_first: usize, g: usize, chunk: &mut PairChunk<R>) -> [Factors<R>; LANES] {
    let kernel = input.kernel;
    let PairChunk { batches, rows, row_grads, work, .. } = chunk;
    let batch = batches[g];
    let fluid_positions = as_arrays(input.fluid.positions);
    let xi = PackV3::gather(fluid_positions, &BatchLanes::of(chunk_first, &batch).slots);
    let (mut fluid_sum, mut gradient_squares, mut fluid_gradient) = (Pack::zero(), Pack::zero(), PackV3::zero());
    let mut live = RowMasks::new(&batch.counts);
    let first_row = batch.first_row as usize;
    for row in &rows[first_row..first_row + batch.rows as usize] {
        let d = xi - PackV3::gather(fluid_positions, row);
        let r2 = d.dot(d);
        let grad = kernel.grad_w_lanes(d, r2.sqrt());
        let m = live.next_row();
        fluid_sum = Pack::select(m, fluid_sum + kernel.w_lanes(r2), fluid_sum);
        fluid_gradient = PackV3::select(m, fluid_gradient + grad, fluid_gradient);
        gradient_squares = Pack::select(m, gradient_squares + grad.dot(grad), gradient_squares);
        row_grads.push([grad.x.to_array(), grad.y.to_array(), grad.z.to_array()]);
    }
    let (fluid_sum, gradient_squares, fluid_gradient) = (fluid_sum.to_array(), gradient_squares.to_array(), fluid_gradient.to_arrays());
    let local = batch.local as usize;
    std::array::from_fn(|k| {
        let wall = if k < batch.lanes as usize { work.walls[local + k] } else { WallSums::default() };
        finish(
            input,
            Sums { fluid_sum: fluid_sum[k], wall_sum: wall.sum, fluid_gradient: V3(fluid_gradient[k]), gradient_squares: gradient_squares[k], wall_gradient: wall.gradient },
        )
    })
}

/// Density, factor, wall gradient and output pressure of every particle, and its neighbour
/// list into `pairs`.
pub fn density_and_factor<R: Real>(input: &FactorsInput<R>, out: FactorsOutput<R>, pairs: &mut Pairs<R>) {
    let n = input.fluid.positions.len();
    pairs.chunks.resize_with(n.div_ceil(CHUNK), PairChunk::default);
    let jobs: Vec<_> = pairs
        .chunks
        .iter_mut()
        .zip(out.densities.chunks_mut(CHUNK))
        .zip(out.pressures.chunks_mut(CHUNK))
        .zip(out.factors.chunks_mut(CHUNK))
        .zip(out.wall_gradients.chunks_mut(CHUNK))
        .zip(out.divergence_sum.chunks_mut(CHUNK))
        .collect();
    let lanes = input.lanes && lanes_available();
    jobs.into_par_iter().enumerate().for_each(|(c, (((((chunk, rho), p), alpha), gw), ksum))| {
        chunk.clear();
        let count = rho.len();
        let mut store = |local: usize, f: &Factors<R>| {
            let i = c * CHUNK + local;
            rho[local] = f.density;
            alpha[local] = f.factor;
            gw[local] = f.wall_gradient;
            let id = input.ids[i] as usize;
            p[local] = f.density * f.density * input.warm_pressure[id] * input.pressure_scale;
            ksum[local] = R::zero();
        };
        if lanes {
            wide(
                #[inline(always)]
                || {
                    // Lists by cells: up to eight consecutive particles in one cell (by their
                    // current positions, as the scalar loop finds each particle's stencil);
                    // sums by groups of eight consecutive particles, each once its lists are in.
                    let (mut local, mut group) = (0, 0);
                    while local < count {
                        let cell = input.grid.cell_coords(input.fluid.positions[c * CHUNK + local]);
                        let mut lanes = 1;
                        while lanes < LANES && local + lanes < count && input.grid.cell_coords(input.fluid.positions[c * CHUNK + local + lanes]) == cell {
                            lanes += 1;
                        }
                        cell_lists(input, c * CHUNK, local, lanes, count, cell, chunk);
                        local += lanes;
                        while group * LANES < count && local >= ((group + 1) * LANES).min(count) {
                            let factors = group_factors(input, c * CHUNK, group, chunk);
                            for (k, f) in factors.iter().enumerate().take(chunk.batches[group].lanes as usize) {
                                store(group * LANES + k, f);
                            }
                            group += 1;
                        }
                    }
                },
            );
        } else {
            chunk.starts.push(0);
            for local in 0..count {
                let f = particle_factors(input, c * CHUNK + local, chunk);
                chunk.starts.push(chunk.index.len() as u32);
                store(local, &f);
            }
        }
    });
}
