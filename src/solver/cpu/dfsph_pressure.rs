//! DFSPH's constant-density solve: Jacobi steps on the predicted density, so that the density
//! the velocities would give after dt is the rest density (Bender & Koschier 2017, Sec. 4.3).
//! Twin of wgsl/sim/dfsph_pressure.wgsl (`pressure_warm_start`, `predict_density`,
//! `pressure_apply`).

use super::dfsph_shared::{apply_stiffness, density_rate, error_units, SolveInput, WarmStart, CHUNK};
use crate::model::real::{Real, V3};
use rayon::prelude::*;

/// The stiffness the solve starts from: a share of the last step's (by particle id) where the
/// predicted density is above rest density, none elsewhere.
pub fn pressure_warm_start<R: Real>(input: &SolveInput<R>, velocities: &[V3<R>], densities: &[R], rest_density: R, dt: R, warm: &WarmStart<R>, stiffness: &mut [R]) {
    input.pairs.chunks.par_iter().zip(stiffness.par_chunks_mut(CHUNK)).enumerate().for_each(|(c, (chunk, k))| {
        for (local, k) in k.iter_mut().enumerate() {
            let i = c * CHUNK + local;
            let d = density_rate(chunk, local, input.volume, velocities, velocities[i], input.wall_gradients[i]);
            let predicted = densities[i] / rest_density + dt * d;
            *k = if predicted > R::one() { warm.share * warm.last[warm.ids[i] as usize] } else { R::zero() };
        }
    });
}

/// Each particle's predicted density rho*_i = max(rho_i / rho0 + dt D_i, 1) (a particle below
/// rest density, as at a free surface, is not pulled), its stiffness K_i = (rho*_i - 1) alpha_i,
/// and the sum of the errors rho*_i - 1 in fixed-point units.
pub fn predict_density<R: Real>(input: &SolveInput<R>, velocities: &[V3<R>], densities: &[R], rest_density: R, dt: R, stiffness: &mut [R]) -> u64 {
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
                let d = density_rate(chunk, local, input.volume, velocities, velocities[i], input.wall_gradients[i]);
                let predicted = (densities[i] / rest_density + dt * d).max(R::one());
                let error = predicted - R::one();
                *k = error * input.factors[i];
                units += error_units(error);
            }
            units
        })
        .sum()
}

/// One Jacobi step's velocity change: v_i -= (V sum_j (K_i + K_j) grad W_ij + K_i g_i^w) / dt;
/// K is added to the step's sum. Also applies the warm start's stiffness.
pub fn pressure_apply<R: Real>(input: &SolveInput<R>, stiffness: &[R], inv_dt: R, velocities: &mut [V3<R>], sums: &mut [R]) {
    apply_stiffness(input, stiffness, inv_dt, velocities, sums);
}
