//! Density carried by the continuity equation: each particle's density is the one its
//! integration carries (advanced by the rate the forces stage computes), and its pressure comes
//! from the equation of state (report Eq. 8 or 9). Twin of wgsl/sim/continuity.wgsl, which
//! runs in place of the density summation (density.wgsl) when a scene sets
//! `physics.density = "continuity"`.

use crate::model::kernels::pressure;
use crate::model::real::Real;
use crate::model::scene::EquationOfState;
use rayon::prelude::*;

pub struct ContinuityInput<'a, R> {
    /// The densities the particles carry, in the current (cell) order.
    pub carried: &'a [R],
    pub rest_density: R,
    pub stiffness: R,
    pub eos: EquationOfState,
    pub clamp_negative_pressure: bool,
}

/// densities = the carried densities; pressures from the equation of state.
pub fn continuity_density<R: Real>(input: &ContinuityInput<R>, densities: &mut [R], pressures: &mut [R]) {
    densities.par_iter_mut().zip(pressures.par_iter_mut()).zip(input.carried.par_iter()).for_each(|((rho, p), &carried)| {
        *rho = carried;
        *p = pressure(carried, input.rest_density, input.stiffness, input.eos, input.clamp_negative_pressure);
    });
}
