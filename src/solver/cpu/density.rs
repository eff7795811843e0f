//! Density by kernel summation (report Eq. 5) and pressure from the equation of state
//! (Eq. 8 or 9): twin of wgsl/sim/density.wgsl.

use crate::model::kernels::{pressure, KernelCoefficients, Neighbours};
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
}

/// rho_i = sum_k m_k W(|x_i - x_k|, h) over fluid (itself included) and wall particles.
pub fn density<R: Real>(input: &DensityInput<R>, densities: &mut [R], pressures: &mut [R]) {
    // A scene without walls skips them (WALLS = false on the GPU).
    let walls = !input.wall_masses.is_empty();
    densities.par_iter_mut().zip(pressures.par_iter_mut()).enumerate().for_each(|(i, (rho, p))| {
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
        *rho = input.fluid_mass * fluid_sum + wall_sum;
        *p = pressure(*rho, input.rest_density, input.stiffness, input.eos, input.clamp_negative_pressure);
    });
}
