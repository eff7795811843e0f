//! Density carried by the continuity equation, with the delta-SPH diffusion and the hydrostatic
//! correction of Fourtakas et al. 2019: twin of wgsl/sim/continuity.wgsl, which explains the
//! terms and why the rate is taken from the velocities of the last integration.

use crate::model::kernels::{density_above_rest, pressure, KernelCoefficients, Neighbours};
use crate::model::params::Grid;
use crate::model::real::{Real, V3};
use crate::model::scene::EquationOfState;
use rayon::prelude::*;

pub struct ContinuityInput<'a, R> {
    pub kernel: &'a KernelCoefficients<R>,
    pub grid: &'a Grid<R>,
    pub dt: R,
    pub fluid_mass: R,
    pub rest_density: R,
    pub stiffness: R,
    pub eos: EquationOfState,
    pub clamp_negative_pressure: bool,
    pub gravity: V3<R>,
    /// delta h c0 ([`crate::model::params::Params::diffusion_factor`]; 0: no diffusion).
    pub diffusion_factor: R,
    pub fluid: Neighbours<'a, R>,
    pub velocities: &'a [V3<R>],
    /// The densities the particles carry from the last step, in the current (cell) order.
    pub carried: &'a [R],
    pub walls: Neighbours<'a, R>,
    pub wall_masses: &'a [R],
}

/// The density rate of fluid particle `i` (wgsl `density_rate`).
pub fn density_rate<R: Real>(input: &ContinuityInput<R>, i: usize) -> R {
    let kernel = input.kernel;
    // Terms the scene does not use are skipped, as they are compiled out on the GPU.
    let walls = !input.wall_masses.is_empty();
    let gravity = input.gravity != V3::zero();
    let diffusion = input.diffusion_factor > R::zero();
    let xi = input.fluid.positions[i];
    let ui = input.velocities[i];
    let rho_i = input.carried[i];
    let c = input.grid.cell_coords(xi);
    let mut fluid_rate = R::zero();
    let mut wall_rate = R::zero();
    let mut diffusive = R::zero();
    for (k0, k1) in input.grid.stencil_runs(c) {
        for j in input.fluid.span(k0, k1) {
            let rij = xi - input.fluid.positions[j];
            let r2 = rij.length_squared();
            if r2 >= kernel.h2 {
                continue;
            }
            let grad = kernel.grad_w(rij, r2.sqrt());
            let rho_j = input.carried[j];
            fluid_rate = fluid_rate + (ui - input.velocities[j]).dot(grad);
            // r2 = 0 only for i itself, whose gradient is zero.
            if diffusion && r2 > R::zero() {
                let mut drho = rho_j - rho_i;
                if gravity {
                    drho = drho - density_above_rest(-input.rest_density * input.gravity.dot(rij), input.rest_density, input.stiffness, input.eos);
                }
                diffusive = diffusive + rij.dot(grad) * (drho / (rho_j * r2));
            }
        }
        for j in if walls { input.walls.span(k0, k1) } else { 0..0 } {
            let rij = xi - input.walls.positions[j];
            let r2 = rij.length_squared();
            if r2 >= kernel.h2 {
                continue;
            }
            wall_rate = wall_rate + ui.dot(kernel.grad_w(rij, r2.sqrt())) * input.wall_masses[j];
        }
    }
    (fluid_rate - input.diffusion_factor * diffusive) * input.fluid_mass + wall_rate
}

/// Each particle's density advanced over dt from the one it carries, and its pressure from the
/// equation of state.
pub fn continuity_density<R: Real>(input: &ContinuityInput<R>, densities: &mut [R], pressures: &mut [R]) {
    densities.par_iter_mut().zip(pressures.par_iter_mut()).enumerate().for_each(|(i, (rho, p))| {
        *rho = input.carried[i] + input.dt * density_rate(input, i);
        *p = pressure(*rho, input.rest_density, input.stiffness, input.eos, input.clamp_negative_pressure);
    });
}
