//! The forces and the integration in one pass, for fixed dt: each particle's acceleration goes
//! straight into its update instead of through an array. Twin of wgsl/sim/forces_integrate.wgsl
//! (entry point `forces_and_integrate`); the same values as [`super::forces::forces`] followed
//! by [`super::integrate::integrate`]. The new state goes to other arrays, as on the GPU, since
//! other particles still read the old one.

use super::forces::{particle_acceleration, ForcesInput};
use super::integrate::{advance_particle, carry_density, Backstops, StepHealth};
use crate::model::real::{Real, V3};
use rayon::prelude::*;

/// The next positions and velocities of every particle into `positions_out`, `velocities_out`,
/// and with continuity density each particle's density of this step into `carried_out`.
#[allow(clippy::too_many_arguments)]
pub fn forces_and_integrate<R: Real>(
    input: &ForcesInput<R>,
    dt: R,
    backstops: &Backstops<R>,
    domain: (V3<R>, V3<R>),
    positions_out: &mut [V3<R>],
    velocities_out: &mut [V3<R>],
    carried_out: &mut [R],
) -> StepHealth {
    let advance = |i: usize, x: &mut V3<R>, v: &mut V3<R>| {
        let a = particle_acceleration(input, i);
        *x = input.fluid.positions[i];
        *v = input.velocities[i];
        advance_particle(x, v, a, dt, backstops, domain)
    };
    if !carried_out.is_empty() {
        return positions_out
            .par_iter_mut()
            .zip(velocities_out.par_iter_mut())
            .zip(carried_out.par_iter_mut())
            .enumerate()
            .map(|(i, ((x, v), rho))| {
                let found = advance(i, x, v);
                carry_density(rho, input.densities[i], found)
            })
            .reduce(StepHealth::default, StepHealth::add);
    }
    positions_out
        .par_iter_mut()
        .zip(velocities_out.par_iter_mut())
        .enumerate()
        .map(|(i, (x, v))| advance(i, x, v))
        .reduce(StepHealth::default, StepHealth::add)
}
