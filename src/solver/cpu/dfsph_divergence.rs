//! DFSPH's divergence solve: Jacobi steps that make the velocity field divergence-free, so
//! that the density stops changing (Bender & Koschier 2017, Sec. 4.2). Twin of
//! wgsl/sim/dfsph_divergence.wgsl (`divergence_warm_start`, `divergence_rate`,
//! `divergence_apply`).

use super::dfsph_shared::{apply_stiffness, density_rate, error_units, SolveInput, WarmStart, CHUNK};
use crate::model::real::{Real, V3};
use rayon::prelude::*;

/// The stiffness the solve starts from: a share of the last step's (by particle id) where the
/// particle is being compressed (D_i > 0), none elsewhere: the last step's stiffness may have
/// answered a compression that has since passed.
pub fn divergence_warm_start<R: Real>(input: &SolveInput<R>, velocities: &[V3<R>], warm: &WarmStart<R>, stiffness: &mut [R]) {
    input.pairs.chunks.par_iter().zip(stiffness.par_chunks_mut(CHUNK)).enumerate().for_each(|(c, (chunk, k))| {
        for (local, k) in k.iter_mut().enumerate() {
            let i = c * CHUNK + local;
            let d = density_rate(chunk, local, input.volume, velocities, velocities[i], input.wall_gradients[i]);
            *k = if d > R::zero() { warm.share * warm.last[warm.ids[i] as usize] } else { R::zero() };
        }
    });
}

/// Each particle's rate of compression D_i = max(Drho^_i/Dt, 0) (expansion is left alone, as
/// at a free surface), its stiffness K_i = D_i alpha_i, and the sum of the errors dt D_i in
/// fixed-point units.
pub fn divergence_rate<R: Real>(input: &SolveInput<R>, velocities: &[V3<R>], dt: R, stiffness: &mut [R]) -> u64 {
    input
        .pairs
        .chunks
        .par_iter()
        .zip(stiffness.par_chunks_mut(CHUNK))
        .enumerate()
        .map(|(c, (chunk, k))| {
            let mut units = 0u64;
            for (local, k) in k.iter_mut().enumerate() {
                let i = c * CHUNK + local;
                let d = density_rate(chunk, local, input.volume, velocities, velocities[i], input.wall_gradients[i]).max(R::zero());
                *k = d * input.factors[i];
                units += error_units(d * dt);
            }
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
