//! DFSPH's divergence solve: Jacobi steps that make the velocity field divergence-free, so
//! that the density stops changing (Bender & Koschier 2017, Sec. 4.2). Twin of
//! wgsl/sim/dfsph_divergence.wgsl (`divergence_warm_start`, `divergence_rate`,
//! `divergence_apply`).

use super::dfsph_shared::{apply_stiffness, density_rates, error_units, Rates, SolveInput, WarmStart, CHUNK};
use crate::model::lanes::Pack;
use crate::model::real::{Real, V3};
use rayon::prelude::*;

/// The stiffness the solve starts from: a share of the last step's (by particle id) where the
/// particle is being compressed (D_i > 0), none elsewhere: the last step's stiffness may have
/// answered a compression that has since passed.
pub fn divergence_warm_start<R: Real>(input: &SolveInput<R>, velocities: &[V3<R>], warm: &WarmStart<R>, stiffness: &mut [R]) {
    stiffness.par_chunks_mut(CHUNK).enumerate().for_each(|(c, k)| {
        let count = k.len();
        let mut warm_start = |local: usize, d: R| {
            let i = c * CHUNK + local;
            k[local] = if d > R::zero() { warm.share * warm.last[warm.ids[i] as usize] } else { R::zero() };
        };
        // Once a step: the lanes' values one by one.
        density_rates(input, c, count, velocities, #[inline(always)] |rates| rates.each_particle(&mut warm_start));
    });
}

/// Each particle's rate of compression D_i = max(Drho^_i/Dt, 0) (expansion is left alone, as
/// at a free surface; a NaN counts as 0), its stiffness K_i = D_i alpha_i, and the sum of the
/// errors dt D_i in fixed-point units.
pub fn divergence_rate<R: Real>(input: &SolveInput<R>, velocities: &[V3<R>], dt: R, stiffness: &mut [R]) -> u64 {
    stiffness
        .par_chunks_mut(CHUNK)
        .enumerate()
        .map(|(c, k)| {
            let mut units = 0u64;
            let factors = &input.factors[c * CHUNK..];
            density_rates(input, c, k.len(), velocities, #[inline(always)] |rates| match rates {
                Rates::One(local, d) => {
                    let d = if d > R::zero() { d } else { R::zero() };
                    k[local] = d * factors[local];
                    if input.counts(c * CHUNK + local) {
                        units += error_units(d * dt);
                    }
                }
                Rates::Eight(lanes, d) => {
                    let zero = Pack::zero();
                    let d = Pack::select(zero.lt(d), d, zero);
                    let local = lanes.locals(c * CHUNK);
                    lanes.store(d * Pack::gather(factors, &local), k);
                    units += input.lane_error_units(d * Pack::splat(dt), lanes);
                }
            });
            units
        })
        .sum()
}

/// One Jacobi step's velocity change of the stiffness K: v_i -= V sum_j (K_i + K_j) grad W_ij +
/// K_i g_i^w; K is added to the step's sum (the next step's warm start). Also applies the warm
/// start's stiffness.
pub fn divergence_apply<R: Real>(input: &SolveInput<R>, stiffness: &[R], velocities: &mut [V3<R>], sums: &mut [R]) {
    apply_stiffness(input, stiffness, R::one(), velocities, sums);
}
