//! DFSPH's constant-density solve: Jacobi steps on the predicted density, so that the density
//! the velocities would give after dt is the rest density (Bender & Koschier 2017, Sec. 4.3).
//! Twin of wgsl/sim/dfsph_pressure.wgsl (`pressure_warm_start`, `predict_density`,
//! `pressure_apply`).

use super::dfsph_shared::{apply_stiffness, density_rates, error_units, Rates, SolveInput, WarmStart, CHUNK};
use crate::model::lanes::Pack;
use crate::model::real::{Real, V3};
use rayon::prelude::*;

/// The stiffness the solve starts from: a share of the last step's (by particle id) where the
/// predicted density is above rest density, none elsewhere.
pub fn pressure_warm_start<R: Real>(input: &SolveInput<R>, velocities: &[V3<R>], densities: &[R], rest_density: R, dt: R, warm: &WarmStart<R>, stiffness: &mut [R]) {
    stiffness.par_chunks_mut(CHUNK).enumerate().for_each(|(c, k)| {
        let count = k.len();
        let mut warm_start = |local: usize, d: R| {
            let i = c * CHUNK + local;
            let predicted = densities[i] / rest_density + dt * d;
            k[local] = if predicted > R::one() { warm.share * warm.last[warm.ids[i] as usize] } else { R::zero() };
        };
        // Once a step: the lanes' values one by one.
        density_rates(input, c, count, velocities, #[inline(always)] |rates| rates.each_particle(&mut warm_start));
    });
}

/// Each particle's predicted density rho*_i = max(rho_i / rho0 + dt D_i, 1) (a particle below
/// rest density, as at a free surface, is not pulled; a NaN counts as 1), its stiffness K_i = (rho*_i - 1) alpha_i,
/// and the sum of the errors rho*_i - 1 in fixed-point units.
pub fn predict_density<R: Real>(input: &SolveInput<R>, velocities: &[V3<R>], densities: &[R], rest_density: R, dt: R, stiffness: &mut [R]) -> u64 {
    stiffness
        .par_chunks_mut(CHUNK)
        .enumerate()
        .map(|(c, k)| {
            let mut units = 0u64;
            let (factors, densities) = (&input.factors[c * CHUNK..], &densities[c * CHUNK..]);
            density_rates(input, c, k.len(), velocities, #[inline(always)] |rates| match rates {
                Rates::One(local, d) => {
                    let predicted = densities[local] / rest_density + dt * d;
                    let error = if predicted > R::one() { predicted } else { R::one() } - R::one();
                    k[local] = error * factors[local];
                    if input.counts(c * CHUNK + local) {
                        units += error_units(error);
                    }
                }
                Rates::Eight(lanes, d) => {
                    let one = Pack::splat(R::one());
                    let local = lanes.locals(c * CHUNK);
                    let predicted = Pack::gather(densities, &local) / Pack::splat(rest_density) + Pack::splat(dt) * d;
                    let error = Pack::select(one.lt(predicted), predicted, one) - one;
                    lanes.store(error * Pack::gather(factors, &local), k);
                    units += input.lane_error_units(error, lanes);
                }
            });
            units
        })
        .sum()
}

/// One Jacobi step's velocity change: v_i -= (V sum_j (K_i + K_j) grad W_ij + K_i g_i^w) / dt;
/// K is added to the step's sum. Also applies the warm start's stiffness.
pub fn pressure_apply<R: Real>(input: &SolveInput<R>, stiffness: &[R], inv_dt: R, velocities: &mut [V3<R>], sums: &mut [R]) {
    apply_stiffness(input, stiffness, inv_dt, velocities, sums);
}
