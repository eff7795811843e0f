//! Accelerations: symmetric pressure (report Eq. 6), viscosity (Eq. 7), walls and gravity:
//! twin of wgsl/sim/forces.wgsl.

use crate::model::kernels::{KernelCoefficients, Neighbours};
use crate::model::params::Grid;
use crate::model::real::{Real, V3};
use crate::model::scene::{BoundaryPressure, Kernel};
use rayon::prelude::*;

pub struct ForcesInput<'a, R> {
    pub kernel: &'a KernelCoefficients<R>,
    pub grid: &'a Grid<R>,
    pub fluid_mass: R,
    pub viscosity: R,
    pub rest_density: R,
    pub boundary_friction: R,
    pub boundary_pressure: BoundaryPressure,
    pub gravity: V3<R>,
    pub fluid: Neighbours<'a, R>,
    pub velocities: &'a [V3<R>],
    pub densities: &'a [R],
    pub pressures: &'a [R],
    pub walls: Neighbours<'a, R>,
    pub wall_masses: &'a [R],
    /// alpha h_s c0 of artificial viscosity (0: off).
    pub artificial_viscosity_factor: R,
    /// With `BoundaryPressure::Adami`, each wall particle's [pressure, density] of this step
    /// (wall_pressure.rs); empty otherwise.
    pub wall_fields: &'a [[R; 2]],
}

/// a_i = -sum_k m_k (p_i/rho_i^2 + p_k/rho_k^2) grad W_ik + viscosity + walls + g.
///
/// Viscosity is Eq. 7 with the volumes m_k/rho_k of Eq. 4 and the dynamic viscosity
/// mu = rho0 nu, divided by rho_i (Mueller et al. 2003, Eq. 14): nu rho0 sum_k m_k/(rho_i rho_k)
/// lap W_ik (u_k - u_i), symmetric in i and k so that it conserves momentum exactly; for the
/// cubic spline, whose Laplacian changes sign, 2 (d + 2) nu rho0 sum_k m_k/(rho_i rho_k)
/// (u_ik . x_ik) / (|x_ik|^2 + 0.01 h^2) grad W_ik (Monaghan 2005, Eq. 6.3).
/// A wall particle pushes with `boundary_pressure`: `Mirror` mirrors the fluid particle's
/// pressure (p_w = max(p_i, 0), rho_w = rho_i, giving 2 max(p_i, 0)/rho_i^2), so walls only push;
/// `Consistent` uses p_i/rho_i^2 (Akinci et al. 2012, Eq. 10 with volumes m_w/rho0), the
/// gradient of sum_i m_i e(rho_i) through the wall particles' share of rho_i, so that the walls
/// do no net work over a cycle of compression and release; `Adami` uses the wall particle's own
/// pressure and density, p_i/rho_i^2 + p_w/rho_w^2, extrapolated from the fluid
/// (wall_pressure.rs; Adami, Hu & Adams 2012). A wall particle takes part in viscosity at rest
/// with the volume m_w/rho_i, scaled by the boundary friction.
pub fn forces<R: Real>(input: &ForcesInput<R>, accelerations: &mut [V3<R>]) {
    accelerations.par_iter_mut().enumerate().for_each(|(i, acc)| *acc = particle_acceleration(input, i));
}

/// The acceleration of fluid particle `i` (wgsl/sim/forces.wgsl `particle_acceleration`, whose
/// w carries the particle's density to the integration with continuity density).
///
/// Artificial viscosity (Monaghan 1992, Eq. 4.1) adds -sum_k m_k Pi_ik grad W_ik with
/// Pi_ik = -alpha c0 h_s mu_ik / rho_ik, mu_ik = (u_ik . x_ik) / (|x_ik|^2 + 0.01 h^2), for
/// approaching pairs (u_ik . x_ik < 0) only; rho_ik is the pair's mean density (rho_i for a wall).
pub fn particle_acceleration<R: Real>(input: &ForcesInput<R>, i: usize) -> V3<R> {
    let kernel = input.kernel;
    let cubic = kernel.kind == Kernel::CubicSpline;
    let viscous = input.viscosity > R::zero();
    // Terms the scene does not use are skipped, as they are compiled out on the GPU.
    let walls = !input.wall_masses.is_empty();
    let gravity = input.gravity != V3::zero();
    let eps = R::of(0.01) * kernel.h2;
    let ten = R::of(10.0);
    let xi = input.fluid.positions[i];
    let ui = input.velocities[i];
    let rho_i = input.densities[i];
    let p_i = input.pressures[i];
    let pi_over = p_i / (rho_i * rho_i);
    // The wall pressure term's factor outside the sum over wall particles (Adami: inside).
    let adami = input.boundary_pressure == BoundaryPressure::Adami;
    let wall_p_over = match input.boundary_pressure {
        BoundaryPressure::Mirror => R::of(2.0) * p_i.max(R::zero()) / (rho_i * rho_i),
        BoundaryPressure::Consistent => pi_over,
        BoundaryPressure::Adami => R::one(),
    };
    let c = input.grid.cell_coords(xi);
    // Sums without the constant factors, which are applied once at the end.
    let mut fluid_pressure = V3::zero();
    let mut fluid_visc = V3::zero();
    let mut wall_pressure = V3::zero();
    let mut wall_visc = V3::zero();
    let artificial = input.artificial_viscosity_factor > R::zero();
    let mut fluid_artificial = V3::zero();
    let mut wall_artificial = V3::zero();
    for (k0, k1) in input.grid.stencil_runs(c) {
        for j in input.fluid.span(k0, k1) {
            let rij = xi - input.fluid.positions[j];
            let r2 = rij.length_squared();
            if r2 >= kernel.h2 {
                continue;
            }
            let r = r2.sqrt();
            let grad = kernel.grad_w(rij, r);
            let rho_j = input.densities[j];
            let pj_over = input.pressures[j] / (rho_j * rho_j);
            fluid_pressure -= grad * (pi_over + pj_over);
            if viscous {
                let inv_rho = R::one() / rho_j;
                let uij = ui - input.velocities[j];
                if cubic {
                    fluid_visc += grad * (inv_rho * uij.dot(rij) / (r2 + eps));
                } else {
                    fluid_visc -= uij * (inv_rho * kernel.lap_w(r));
                }
            }
            if artificial {
                let uij = ui - input.velocities[j];
                let approach = uij.dot(rij);
                if approach < R::zero() {
                    fluid_artificial += grad * (approach / ((r2 + eps) * (rho_i + rho_j)));
                }
            }
        }
        for j in if walls { input.walls.span(k0, k1) } else { 0..0 } {
            let rij = xi - input.walls.positions[j];
            let r2 = rij.length_squared();
            if r2 >= kernel.h2 {
                continue;
            }
            let r = r2.sqrt();
            let grad = kernel.grad_w(rij, r);
            let mw = input.wall_masses[j];
            if adami {
                let [p_w, rho_w] = input.wall_fields[j];
                wall_pressure -= grad * (mw * (pi_over + p_w / (rho_w * rho_w)));
            } else {
                wall_pressure -= grad * mw;
            }
            if viscous {
                if cubic {
                    wall_visc += grad * (mw * ui.dot(rij) / (r2 + eps));
                } else {
                    wall_visc -= ui * (mw * kernel.lap_w(r));
                }
            }
            if artificial {
                let approach = ui.dot(rij);
                if approach < R::zero() {
                    wall_artificial += grad * (mw * approach / ((r2 + eps) * rho_i));
                }
            }
        }
    }
    let nu = if cubic { ten * input.viscosity } else { input.viscosity };
    let visc = fluid_visc * (nu * input.rest_density * input.fluid_mass / rho_i) + wall_visc * (nu * input.boundary_friction / rho_i);
    let mut a = fluid_pressure * input.fluid_mass + wall_pressure * wall_p_over + visc;
    if artificial {
        let av = input.artificial_viscosity_factor;
        a += fluid_artificial * (R::of(2.0) * av * input.fluid_mass) + wall_artificial * av;
    }
    if gravity {
        a += input.gravity;
    }
    a
}
