//! DFSPH, stage 1 of a step (after the binning): density, the factor alpha, the wall gradient
//! and the output pressure. Twin of
//! wgsl/sim/dfsph_factors.wgsl (`density_and_factor`); the CPU also lists each particle's
//! neighbours with their kernel gradients here, for the passes that follow.

use super::dfsph_shared::{PairChunk, Pairs, CHUNK};
use crate::model::kernels::{KernelCoefficients, Neighbours};
use crate::model::params::Grid;
use crate::model::real::{Real, V3};
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
    let volume = input.volume;
    // V_b grad W = (m_b / rho0) grad W.
    let wall_gradient = wall_gradient / input.rest_density;
    let total = fluid_gradient * volume + wall_gradient;
    let denominator = total.dot(total) + volume * volume * gradient_squares;
    let factor = if denominator > input.factor_epsilon { R::one() / denominator } else { R::zero() };
    Factors { density: input.fluid_mass * fluid_sum + wall_sum, factor, wall_gradient }
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
    jobs.into_par_iter().enumerate().for_each(|(c, (((((chunk, rho), p), alpha), gw), ksum))| {
        chunk.starts.clear();
        chunk.index.clear();
        chunk.grad.clear();
        chunk.starts.push(0);
        for local in 0..rho.len() {
            let i = c * CHUNK + local;
            let f = particle_factors(input, i, chunk);
            chunk.starts.push(chunk.index.len() as u32);
            rho[local] = f.density;
            alpha[local] = f.factor;
            gw[local] = f.wall_gradient;
            let id = input.ids[i] as usize;
            p[local] = f.density * f.density * input.warm_pressure[id] * input.pressure_scale;
            ksum[local] = R::zero();
        }
    });
}
