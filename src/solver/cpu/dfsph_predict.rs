//! DFSPH, between the two solves: the accelerations of every force but pressure (viscosity,
//! surface tension, adhesion and gravity), the step's dt (adaptive dt) and the predicted velocities v* = v + dt a. Twin of wgsl/sim/dfsph_predict.wgsl, one function per
//! entry point (`predict_velocities` with a fixed dt; `non_pressure_accelerations`,
//! `choose_dt` and `predict_from_accelerations` with adaptive dt).

use super::forces::{adhesion_pair, SurfaceTension};
use crate::model::kernels::{viscous_nu, KernelCoefficients, Neighbours};
use crate::model::params::{AdaptiveDt, Grid};
use crate::model::real::{Real, V3};
use rayon::prelude::*;

pub struct PredictInput<'a, R> {
    pub kernel: &'a KernelCoefficients<R>,
    pub grid: &'a Grid<R>,
    pub fluid_mass: R,
    pub rest_density: R,
    pub viscosity: R,
    pub boundary_friction: R,
    pub gravity: V3<R>,
    pub fluid: Neighbours<'a, R>,
    pub velocities: &'a [V3<R>],
    pub densities: &'a [R],
    pub walls: Neighbours<'a, R>,
    pub wall_masses: &'a [R],
    /// Surface tension and adhesion as in [`super::forces::ForcesInput`] (0: off); the normals
    /// of the step's densities, empty without surface tension.
    pub tension: SurfaceTension<R>,
    pub adhesion_factor: R,
    pub normals: &'a [V3<R>],
}

/// Viscosity, surface tension, adhesion and gravity on fluid particle i (wgsl
/// `non_pressure_acceleration`): the terms of the weakly compressible forces
/// (src/solver/cpu/forces.rs explains them), without pressure.
pub fn non_pressure_acceleration<R: Real>(input: &PredictInput<R>, i: usize) -> V3<R> {
    let gravity = input.gravity != V3::zero();
    let g = if gravity { input.gravity } else { V3::zero() };
    let viscous = input.viscosity > R::zero();
    let tension = input.tension.on();
    let adhesion = input.adhesion_factor > R::zero();
    if !(viscous || tension || adhesion) {
        return g;
    }
    let kernel = input.kernel;
    let gradient_viscosity = kernel.kind.gradient_viscosity();
    let walls = !input.wall_masses.is_empty();
    let eps = R::of(0.01) * kernel.h2;
    let xi = input.fluid.positions[i];
    let ui = input.velocities[i];
    let c = input.grid.cell_coords(xi);
    let mut fluid_visc = V3::zero();
    let mut wall_visc = V3::zero();
    let rho_i = input.densities[i];
    let ni = if tension { input.normals[i] } else { V3::zero() };
    let mut tension_sum = V3::zero();
    let mut adhesion_sum = V3::zero();
    for (k0, k1) in input.grid.stencil_runs(c) {
        for j in input.fluid.span(k0, k1) {
            let rij = xi - input.fluid.positions[j];
            let r2 = rij.length_squared();
            if r2 >= kernel.h2 {
                continue;
            }
            let r = r2.sqrt();
            if viscous {
                let inv_rho = R::one() / input.densities[j];
                let uij = ui - input.velocities[j];
                if gradient_viscosity {
                    fluid_visc += kernel.grad_w(rij, r) * (inv_rho * uij.dot(rij) / (r2 + eps));
                } else {
                    fluid_visc -= uij * (inv_rho * kernel.lap_w(r));
                }
            }
            if tension {
                tension_sum += input.tension.pair(rij, r, rho_i, input.densities[j], ni, input.normals[j]);
            }
        }
        for j in if walls { input.walls.span(k0, k1) } else { 0..0 } {
            let rij = xi - input.walls.positions[j];
            let r2 = rij.length_squared();
            if r2 >= kernel.h2 {
                continue;
            }
            let r = r2.sqrt();
            let mw = input.wall_masses[j];
            if viscous {
                if gradient_viscosity {
                    wall_visc += kernel.grad_w(rij, r) * (mw * ui.dot(rij) / (r2 + eps));
                } else {
                    wall_visc -= ui * (mw * kernel.lap_w(r));
                }
            }
            if adhesion {
                adhesion_sum += adhesion_pair(kernel.h, rij, r, mw);
            }
        }
    }
    let nu = viscous_nu(kernel.kind, input.viscosity);
    let mut a = fluid_visc * (nu * input.rest_density * input.fluid_mass / rho_i) + wall_visc * (nu * input.boundary_friction / rho_i);
    if tension {
        a -= tension_sum;
    }
    if adhesion {
        a -= adhesion_sum * input.adhesion_factor;
    }
    a + g
}

/// Fixed dt: v*_i = v_i + dt a_i into `velocities_out`; the constant-density solve's stiffness
/// sum starts at 0.
pub fn predict_velocities<R: Real>(input: &PredictInput<R>, dt: R, velocities_out: &mut [V3<R>], pressure_sum: &mut [R]) {
    velocities_out.par_iter_mut().zip(pressure_sum.par_iter_mut()).enumerate().for_each(|(i, (v, sum))| {
        *v = input.velocities[i] + non_pressure_acceleration(input, i) * dt;
        *sum = R::zero();
    });
}

/// Adaptive dt, 1 of 3: every particle's acceleration, and the largest |v| and |a| (each in `R`;
/// a non-finite one left out, as the health check reports it).
pub fn non_pressure_accelerations<R: Real>(input: &PredictInput<R>, accelerations: &mut [V3<R>]) -> (f64, f64) {
    accelerations.par_iter_mut().enumerate().for_each(|(i, a)| *a = non_pressure_acceleration(input, i));
    let finite_max = |values: &mut dyn Iterator<Item = f64>| values.filter(|v| v.is_finite()).fold(0.0, f64::max);
    let speed = finite_max(&mut input.velocities.iter().map(|v| v.length().to64()));
    let accel = finite_max(&mut accelerations.iter().map(|a| a.length().to64()));
    (speed, accel)
}

/// Adaptive dt, 2 of 3: dt = clamp(min(C_cfl h / |v|max, C_f sqrt(h / |a|max), C_visc h^2 / nu),
/// dt_min, dt_max): the CFL condition on the flow speed alone, as an incompressible fluid has no
/// speed of sound (a condition whose quantity is zero is left out).
pub fn choose_dt(adaptive: &AdaptiveDt, h: f64, maxima: (f64, f64), viscosity: f64) -> f64 {
    adaptive.dt(h, 0.0, maxima.0, maxima.1, viscosity)
}

/// Adaptive dt, 3 of 3: v*_i = v_i + dt a_i; the stiffness sum starts at 0.
pub fn predict_from_accelerations<R: Real>(velocities: &[V3<R>], accelerations: &[V3<R>], dt: R, velocities_out: &mut [V3<R>], pressure_sum: &mut [R]) {
    velocities_out.par_iter_mut().zip(pressure_sum.par_iter_mut()).enumerate().for_each(|(i, (v, sum))| {
        *v = velocities[i] + accelerations[i] * dt;
        *sum = R::zero();
    });
}
