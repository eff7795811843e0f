//! Density by kernel summation (report Eq. 5) and pressure from the equation of state
//! (Eq. 8 or 9): twin of wgsl/sim/density.wgsl.
//!
//! [`particle_density`] is the GPU's loop, one particle over its stencil. [`density`] computes
//! the same sums from the step's neighbour lists, eight particles of a cell at a time
//! ([`super::cell_batches`]): each particle's neighbours in the same order, so the same bits.

use super::cell_batches::{lanes_available, wide, ListChunk, NeighbourLists, RowMasks};
use crate::model::kernels::{pressure, KernelCoefficients, Neighbours};
use crate::model::lanes::{Pack, PackV3};
use crate::model::params::Grid;
use crate::model::real::Real;
use crate::model::scene::EquationOfState;
use rayon::prelude::*;

pub struct DensityInput<'a, R> {
    pub kernel: &'a KernelCoefficients<R>,
    pub grid: &'a Grid<R>,
    pub fluid_mass: R,
    pub rest_density: R,
    pub stiffness: R,
    pub eos: EquationOfState,
    pub clamp_negative_pressure: bool,
    pub fluid: Neighbours<'a, R>,
    pub walls: Neighbours<'a, R>,
    pub wall_masses: &'a [R],
    /// Each particle's position in the first three places ([`super::cell_batches::points`];
    /// the lane path only).
    pub fluid_points: &'a [[R; 4]],
    /// Each wall particle's position and mass (the lane path only).
    pub wall_points: &'a [[R; 4]],
}

/// rho_i = sum_k m_k W(|x_i - x_k|, h) over fluid (itself included) and wall particles, and
/// p_i, for every particle. With `lanes` (where the processor has AVX2) the sums run eight
/// particles at a time from neighbour lists built here for the current positions (the forces
/// read them too); otherwise each particle walks its stencil ([`particle_density`]). The values
/// are the same.
pub fn density<R: Real>(input: &DensityInput<R>, lanes: bool, lists: &mut NeighbourLists, densities: &mut [R], pressures: &mut [R]) {
    if !(lanes && lanes_available()) {
        lists.clear();
        densities.par_iter_mut().zip(pressures.par_iter_mut()).enumerate().for_each(|(i, (rho, p))| (*rho, *p) = particle_density(input, i));
        return;
    }
    lists.build(input.grid, input.fluid, input.walls, input.kernel.h2);
    let lists = &*lists;
    lists.chunks().par_iter().zip(lists.split(densities)).zip(lists.split(pressures)).for_each(|((chunk, rho), p)| {
        wide(
            #[inline(always)]
            || chunk_density(input, chunk, rho, p),
        );
    });
}

/// The density and pressure of a chunk's particles, eight at a time.
#[inline(always)]
fn chunk_density<R: Real>(input: &DensityInput<R>, chunk: &ListChunk, densities: &mut [R], pressures: &mut [R]) {
    let first = chunk.particles().start;
    for batch in &chunk.batches {
        let (xi, _) = PackV3::gather_with_w(input.fluid_points, &batch.indices());
        let mut fluid_sum = Pack::zero();
        let (rows, counts) = chunk.fluid_rows(batch);
        let mut live = RowMasks::new(&counts);
        for index in rows {
            let d = xi - PackV3::gather_with_w(input.fluid_points, index).0;
            fluid_sum = Pack::select(live.next_row(), fluid_sum + input.kernel.w_lanes(d.dot(d)), fluid_sum);
        }
        let mut wall_sum = Pack::zero();
        let (rows, counts) = chunk.wall_rows(batch);
        let mut live = RowMasks::new(&counts);
        for index in rows {
            let (xw, mw) = PackV3::gather_with_w(input.wall_points, index);
            let d = xi - xw;
            let term = mw * input.kernel.w_lanes(d.dot(d));
            wall_sum = Pack::select(live.next_row(), wall_sum + term, wall_sum);
        }
        let (fluid_sum, wall_sum) = (fluid_sum.to_array(), wall_sum.to_array());
        for k in 0..batch.lanes as usize {
            let i = batch.first as usize + k - first;
            (densities[i], pressures[i]) = finish(input, fluid_sum[k], wall_sum[k]);
        }
    }
}

/// Density and pressure from a particle's fluid and wall sums.
#[inline(always)]
fn finish<R: Real>(input: &DensityInput<R>, fluid_sum: R, wall_sum: R) -> (R, R) {
    let rho = input.fluid_mass * fluid_sum + wall_sum;
    (rho, pressure(rho, input.rest_density, input.stiffness, input.eos, input.clamp_negative_pressure))
}

/// Density and pressure of particle `i` by the GPU's loop (wgsl/sim/density.wgsl): every
/// particle of the stencil, in its order.
pub fn particle_density<R: Real>(input: &DensityInput<R>, i: usize) -> (R, R) {
    // A scene without walls skips them (WALLS = false on the GPU).
    let walls = !input.wall_masses.is_empty();
    let xi = input.fluid.positions[i];
    let c = input.grid.cell_coords(xi);
    let mut fluid_sum = R::zero();
    let mut wall_sum = R::zero();
    for (k0, k1) in input.grid.stencil_runs(c) {
        for j in input.fluid.span(k0, k1) {
            fluid_sum = fluid_sum + input.kernel.w((xi - input.fluid.positions[j]).length_squared());
        }
        for j in if walls { input.walls.span(k0, k1) } else { 0..0 } {
            wall_sum = wall_sum + input.wall_masses[j] * input.kernel.w((xi - input.walls.positions[j]).length_squared());
        }
    }
    finish(input, fluid_sum, wall_sum)
}
