//! Accelerations: symmetric pressure (report Eq. 6), viscosity (Eq. 7), walls and gravity:
//! twin of wgsl/sim/forces.wgsl.
//!
//! [`particle_acceleration`] is the GPU's loop, one particle over its stencil. [`forces`]
//! computes the same sums from the neighbour lists of the step's density stage, eight particles
//! of a cell at a time ([`super::cell_batches`]): each particle's neighbours in the same order,
//! the same operations, so the same bits.

use super::cell_batches::{wide, ListChunk, NeighbourLists, RowMasks};
use crate::model::kernels::{adhesion_shape, cohesion_shape, viscous_nu, KernelCoefficients, Neighbours};
use crate::model::lanes::{Pack, PackV3, LANES};
use crate::model::params::{Grid, Params};
use crate::model::real::{as_arrays, Real, V3};
use crate::model::scene::BoundaryPressure;
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
    /// The neighbour lists of the density stage, for the current positions ([`forces`] only).
    pub lists: &'a NeighbourLists,
    /// Each particle's position and p / rho^2 ([`pressure_terms`]; [`forces`] only).
    pub fluid_points: &'a [[R; 4]],
    /// Each wall particle's position and mass ([`forces`] only).
    pub wall_points: &'a [[R; 4]],
    /// Akinci et al.'s surface tension (gamma 0: off) and beta 0.007 / h^3 of their adhesion
    /// (`Params::adhesion_factor`; 0: off).
    pub tension: SurfaceTension<R>,
    pub adhesion_factor: R,
    /// With surface tension, each fluid particle's normal of this step (surface_normals.rs);
    /// empty otherwise.
    pub normals: &'a [V3<R>],
}

/// a_i = -sum_k m_k (p_i/rho_i^2 + p_k/rho_k^2) grad W_ik + viscosity + walls + g.
///
/// Viscosity is Eq. 7 with the volumes m_k/rho_k of Eq. 4 and the dynamic viscosity
/// mu = rho0 nu, divided by rho_i (Mueller et al. 2003, Eq. 14): nu rho0 sum_k m_k/(rho_i rho_k)
/// lap W_ik (u_k - u_i), symmetric in i and k so that it conserves momentum exactly; for the
/// cubic spline and Wendland's kernel, whose Laplacians change sign, 2 (d + 2) nu rho0 sum_k m_k/(rho_i rho_k)
/// (u_ik . x_ik) / (|x_ik|^2 + 0.01 h^2) grad W_ik (Monaghan 2005, Eq. 6.3).
/// A wall particle pushes with `boundary_pressure`: `Mirror` mirrors the fluid particle's
/// pressure (p_w = max(p_i, 0), rho_w = rho_i, giving 2 max(p_i, 0)/rho_i^2), so walls only push;
/// `Consistent` uses p_i/rho_i^2 (Akinci et al. 2012, Eq. 10 with volumes m_w/rho0), the
/// gradient of sum_i m_i e(rho_i) through the wall particles' share of rho_i, so that the walls
/// do no net work over a cycle of compression and release; `Adami` uses the wall particle's own
/// pressure and density, p_i/rho_i^2 + p_w/rho_w^2, extrapolated from the fluid
/// (wall_pressure.rs; Adami, Hu & Adams 2012). A wall particle takes part in viscosity at rest
/// with the volume m_w/rho_i, scaled by the boundary friction.
///
/// Surface tension (Akinci, Akinci & Teschner 2013: cohesion and curvature) adds
/// -sum_j K_ij (gamma m_j C(r) x_ij / r + gamma (n_i - n_j)), K_ij = 2 rho0 / (rho_i + rho_j):
/// cohesion along the pair with the spline C of [`cohesion_shape`] and the curvature term with
/// the normals of surface_normals.rs; their adhesion adds -beta sum_w m_w A(r) x_iw / r with
/// the spline A of [`adhesion_shape`], m_w = rho0 V_w the wall particle's mass.
pub fn forces<R: Real>(input: &ForcesInput<R>, accelerations: &mut [V3<R>]) {
    let lists = input.lists;
    if lists.chunks().is_empty() {
        accelerations.par_iter_mut().enumerate().for_each(|(i, acc)| *acc = particle_acceleration(input, i));
        return;
    }
    lists.chunks().par_iter().zip(lists.split(accelerations)).for_each(|(chunk, acc)| {
        wide(
            #[inline(always)]
            || chunk_accelerations(input, chunk, acc),
        );
    });
}

/// Akinci et al.'s surface tension as its pair term uses it (Akinci et al. 2013).
#[derive(Clone, Copy, Debug)]
pub struct SurfaceTension<R> {
    pub rest_density: R,
    pub h: R,
    /// gamma, and gamma m 32 / (pi h^3) (`Params::cohesion_factor`).
    pub gamma: R,
    pub cohesion_factor: R,
}

impl<R: Real> SurfaceTension<R> {
    /// The scene's surface tension (gamma 0 when it has none).
    pub fn of(params: &Params) -> SurfaceTension<R> {
        SurfaceTension {
            rest_density: R::of(params.rest_density),
            h: R::of(params.h),
            gamma: R::of(params.surface_tension),
            cohesion_factor: R::of(params.cohesion_factor()),
        }
    }

    pub fn on(&self) -> bool {
        self.gamma > R::zero()
    }

    /// What fluid neighbour j at r_ij = x_i - x_j (|r_ij| = r < h) pulls particle i by, with its
    /// factors: K_ij (gamma m C(r) x_ij / r + gamma (n_i - n_j)), K_ij = 2 rho0 / (rho_i + rho_j);
    /// no cohesion where the direction is undefined (wgsl `surface_tension_pair`).
    pub fn pair(&self, rij: V3<R>, r: R, rho_i: R, rho_j: R, ni: V3<R>, nj: V3<R>) -> V3<R> {
        let k = R::of(2.0) * self.rest_density / (rho_i + rho_j);
        let mut pull = (ni - nj) * self.gamma;
        if r > R::of(1e-12) * self.h {
            pull += rij * (self.cohesion_factor * cohesion_shape(r / self.h) / r);
        }
        pull * k
    }

    /// [`SurfaceTension::pair`] lane by lane, the same operations in the same order.
    #[inline(always)]
    fn pair_lanes(&self, rij: PackV3<R>, r: Pack<R>, rho_i: Pack<R>, rho_j: Pack<R>, ni: PackV3<R>, nj: PackV3<R>) -> PackV3<R> {
        let k = Pack::splat(R::of(2.0) * self.rest_density) / (rho_i + rho_j);
        let curvature = (ni - nj).scale(Pack::splat(self.gamma));
        let cohesion = curvature + rij.scale(Pack::splat(self.cohesion_factor) * cohesion_shape_lanes(r / Pack::splat(self.h)) / r);
        let defined = Pack::splat(R::of(1e-12) * self.h).lt(r);
        PackV3::select(defined, cohesion, curvature).scale(k)
    }
}

/// [`cohesion_shape`] lane by lane.
#[inline(always)]
fn cohesion_shape_lanes<R: Real>(q: Pack<R>) -> Pack<R> {
    let d = Pack::splat(R::one()) - q;
    let t = d * d * d * q * q * q;
    Pack::select(Pack::splat(R::of(0.5)).lt(q), t, Pack::splat(R::of(2.0)) * t - Pack::splat(R::of(1.0 / 64.0)))
}

/// [`adhesion_pair`] lane by lane (with [`adhesion_shape`]'s spline), the same operations in the
/// same order.
#[inline(always)]
fn adhesion_pair_lanes<R: Real>(h: R, rij: PackV3<R>, r: Pack<R>, mw: Pack<R>) -> PackV3<R> {
    let zero = Pack::zero();
    let q = r / Pack::splat(h);
    let radicand = Pack::splat(R::of(6.0)) * q - Pack::splat(R::of(4.0)) * q * q - Pack::splat(R::of(2.0));
    let spline = Pack::select(radicand.lt(zero), zero, radicand).sqrt().sqrt();
    let shape = Pack::select(Pack::splat(R::of(0.5)).lt(q).and(q.lt(Pack::splat(R::one()))), spline, zero);
    let defined = Pack::splat(R::of(1e-12) * h).lt(r);
    PackV3::select(defined, rij.scale(mw * shape / r), PackV3::zero())
}

/// Akinci et al.'s (2013) adhesion without beta 0.007 / h^3: m_w A(r) x_iw / r for a wall particle of
/// mass m_w (rho0 V_w); zero where the direction is undefined (wgsl `adhesion_pair`).
pub fn adhesion_pair<R: Real>(h: R, rij: V3<R>, r: R, mw: R) -> V3<R> {
    if r > R::of(1e-12) * h {
        rij * (mw * adhesion_shape(r / h) / r)
    } else {
        V3::zero()
    }
}

/// The sums of a particle's neighbour loops, without their constant factors.
#[derive(Clone, Copy, Debug)]
pub struct ForceSums<R> {
    pub fluid_pressure: V3<R>,
    pub fluid_visc: V3<R>,
    pub wall_pressure: V3<R>,
    pub wall_visc: V3<R>,
    pub fluid_artificial: V3<R>,
    pub wall_artificial: V3<R>,
    /// Surface tension with its factors (subtracted as it is) and adhesion without its factor.
    pub tension: V3<R>,
    pub adhesion: V3<R>,
}

/// What the pair terms of a batch's particles need of them.
#[derive(Clone, Copy)]
struct Lanes<R: Real> {
    x: PackV3<R>,
    u: PackV3<R>,
    rho: Pack<R>,
    /// p_i / rho_i^2.
    p_over: Pack<R>,
    /// The surface normal (zero without surface tension).
    n: PackV3<R>,
}

/// The terms a scene uses; the others are skipped, as they are compiled out on the GPU.
#[derive(Clone, Copy)]
struct Terms {
    gradient_viscosity: bool,
    viscous: bool,
    artificial: bool,
    /// Adami's wall pressure: each wall particle's own pressure inside the sum.
    adami: bool,
    tension: bool,
    adhesion: bool,
}

impl Terms {
    fn of<R: Real>(input: &ForcesInput<R>) -> Terms {
        Terms {
            gradient_viscosity: input.kernel.kind.gradient_viscosity(),
            viscous: input.viscosity > R::zero(),
            artificial: input.artificial_viscosity_factor > R::zero(),
            adami: input.boundary_pressure == BoundaryPressure::Adami,
            tension: input.tension.on(),
            adhesion: input.adhesion_factor > R::zero(),
        }
    }
}

/// The accelerations of a chunk's particles, eight at a time from the neighbour lists: the
/// pair terms of [`particle_acceleration`] lane by lane, in the same order.
#[inline(always)]
fn chunk_accelerations<R: Real>(input: &ForcesInput<R>, chunk: &ListChunk, accelerations: &mut [V3<R>]) {
    let first = chunk.particles().start;
    let terms = Terms::of(input);
    let kernel = input.kernel;
    let eps = Pack::splat(R::of(0.01) * kernel.h2);
    let zero = Pack::zero();
    let velocities = as_arrays(input.velocities);
    let normals = as_arrays(input.normals);
    for batch in &chunk.batches {
        let index = batch.indices();
        let (x, p_over) = PackV3::gather_with_w(input.fluid_points, &index);
        let n = if terms.tension { PackV3::gather(normals, &index) } else { PackV3::zero() };
        let pi = Lanes { x, u: PackV3::gather(velocities, &index), rho: Pack::gather(input.densities, &index), p_over, n };
        let mut fluid_pressure = PackV3::zero();
        let mut fluid_visc = PackV3::zero();
        let mut fluid_artificial = PackV3::zero();
        let mut tension = PackV3::zero();
        let (rows, counts) = chunk.fluid_rows(batch);
        let mut live = RowMasks::new(&counts);
        for index in rows {
            let valid = live.next_row();
            let (xj, pj_over) = PackV3::gather_with_w(input.fluid_points, index);
            let rij = pi.x - xj;
            let r2 = rij.dot(rij);
            let r = r2.sqrt();
            let grad = kernel.grad_w_lanes(rij, r);
            fluid_pressure = PackV3::select(valid, fluid_pressure - grad.scale(pi.p_over + pj_over), fluid_pressure);
            // The neighbours' densities, gathered once for the terms that read them.
            let rho_j = if terms.viscous || terms.artificial || terms.tension { Pack::gather(input.densities, index) } else { zero };
            if terms.viscous || terms.artificial {
                let uij = pi.u - PackV3::gather(velocities, index);
                if terms.viscous {
                    let inv_rho = Pack::splat(R::one()) / rho_j;
                    let visc = if terms.gradient_viscosity {
                        fluid_visc + grad.scale(inv_rho * uij.dot(rij) / (r2 + eps))
                    } else {
                        fluid_visc - uij.scale(inv_rho * kernel.lap_w_lanes(r))
                    };
                    fluid_visc = PackV3::select(valid, visc, fluid_visc);
                }
                if terms.artificial {
                    let approach = uij.dot(rij);
                    let term = fluid_artificial + grad.scale(approach / ((r2 + eps) * (pi.rho + rho_j)));
                    fluid_artificial = PackV3::select(valid.and(approach.lt(zero)), term, fluid_artificial);
                }
            }
            if terms.tension {
                let pull = input.tension.pair_lanes(rij, r, pi.rho, rho_j, pi.n, PackV3::gather(normals, index));
                tension = PackV3::select(valid, tension + pull, tension);
            }
        }
        let mut wall_pressure = PackV3::zero();
        let mut wall_visc = PackV3::zero();
        let mut wall_artificial = PackV3::zero();
        let mut adhesion = PackV3::zero();
        let (rows, counts) = chunk.wall_rows(batch);
        let mut live = RowMasks::new(&counts);
        for index in rows {
            let valid = live.next_row();
            let (xw, mw) = PackV3::gather_with_w(input.wall_points, index);
            let rij = pi.x - xw;
            let r2 = rij.dot(rij);
            let r = r2.sqrt();
            let grad = kernel.grad_w_lanes(rij, r);
            let term = if terms.adami {
                let (p_w, rho_w) = wall_fields(input.wall_fields, index);
                grad.scale(mw * (pi.p_over + p_w / (rho_w * rho_w)))
            } else {
                grad.scale(mw)
            };
            wall_pressure = PackV3::select(valid, wall_pressure - term, wall_pressure);
            if terms.viscous {
                let visc = if terms.gradient_viscosity {
                    wall_visc + grad.scale(mw * pi.u.dot(rij) / (r2 + eps))
                } else {
                    wall_visc - pi.u.scale(mw * kernel.lap_w_lanes(r))
                };
                wall_visc = PackV3::select(valid, visc, wall_visc);
            }
            if terms.artificial {
                let approach = pi.u.dot(rij);
                let term = wall_artificial + grad.scale(mw * approach / ((r2 + eps) * pi.rho));
                wall_artificial = PackV3::select(valid.and(approach.lt(zero)), term, wall_artificial);
            }
            if terms.adhesion {
                let pull = adhesion_pair_lanes(kernel.h, rij, r, mw);
                adhesion = PackV3::select(valid, adhesion + pull, adhesion);
            }
        }
        let (fluid_pressure, fluid_visc, wall_pressure) = (fluid_pressure.to_arrays(), fluid_visc.to_arrays(), wall_pressure.to_arrays());
        let (wall_visc, fluid_artificial, wall_artificial) = (wall_visc.to_arrays(), fluid_artificial.to_arrays(), wall_artificial.to_arrays());
        let (tension, adhesion) = (tension.to_arrays(), adhesion.to_arrays());
        for k in 0..batch.lanes as usize {
            let i = batch.first as usize + k;
            let sums = ForceSums {
                fluid_pressure: V3(fluid_pressure[k]),
                fluid_visc: V3(fluid_visc[k]),
                wall_pressure: V3(wall_pressure[k]),
                wall_visc: V3(wall_visc[k]),
                fluid_artificial: V3(fluid_artificial[k]),
                wall_artificial: V3(wall_artificial[k]),
                tension: V3(tension[k]),
                adhesion: V3(adhesion[k]),
            };
            accelerations[i - first] = finish(input, i, &sums);
        }
    }
}

/// The pressure and density of the wall particles `index` (Adami's wall pressure).
#[inline(always)]
fn wall_fields<R: Real>(fields: &[[R; 2]], index: &[u32; LANES]) -> (Pack<R>, Pack<R>) {
    let (mut p, mut rho) = ([R::zero(); LANES], [R::zero(); LANES]);
    for k in 0..LANES {
        [p[k], rho[k]] = fields[index[k] as usize];
    }
    (Pack::from_array(p), Pack::from_array(rho))
}

/// The acceleration of particle i from its sums: their constant factors, and gravity.
#[inline(always)]
fn finish<R: Real>(input: &ForcesInput<R>, i: usize, sums: &ForceSums<R>) -> V3<R> {
    let terms = Terms::of(input);
    let rho_i = input.densities[i];
    let p_i = input.pressures[i];
    let pi_over = p_i / (rho_i * rho_i);
    // The wall pressure term's factor outside the sum over wall particles (Adami: inside).
    let wall_p_over = match input.boundary_pressure {
        BoundaryPressure::Mirror => R::of(2.0) * p_i.max(R::zero()) / (rho_i * rho_i),
        BoundaryPressure::Consistent => pi_over,
        BoundaryPressure::Adami => R::one(),
    };
    let nu = viscous_nu(input.kernel.kind, input.viscosity);
    let visc = sums.fluid_visc * (nu * input.rest_density * input.fluid_mass / rho_i) + sums.wall_visc * (nu * input.boundary_friction / rho_i);
    let mut a = sums.fluid_pressure * input.fluid_mass + sums.wall_pressure * wall_p_over + visc;
    if terms.artificial {
        let av = input.artificial_viscosity_factor;
        a += sums.fluid_artificial * (R::of(2.0) * av * input.fluid_mass) + sums.wall_artificial * (av * input.boundary_friction);
    }
    if input.tension.on() {
        a -= sums.tension;
    }
    if input.adhesion_factor > R::zero() {
        a -= sums.adhesion * input.adhesion_factor;
    }
    if input.gravity != V3::zero() {
        a += input.gravity;
    }
    a
}

/// p_i / rho_i^2 of every particle, the pressure term of the forces' pairs
/// in the fourth place of each of `points` ([`ForcesInput::fluid_points`]).
pub fn pressure_terms<R: Real>(densities: &[R], pressures: &[R], points: &mut [[R; 4]]) {
    points.par_iter_mut().zip(densities.par_iter().zip(pressures)).for_each(|(t, (&rho, &p))| t[3] = p / (rho * rho));
}

/// The acceleration of fluid particle `i` (wgsl/sim/forces.wgsl `particle_acceleration`, whose
/// w carries the particle's density to the integration with continuity density).
///
/// Artificial viscosity (Monaghan 1992, Eq. 4.1) adds -sum_k m_k Pi_ik grad W_ik with
/// Pi_ik = -alpha c0 h_s mu_ik / rho_ik, mu_ik = (u_ik . x_ik) / (|x_ik|^2 + 0.01 h^2), for
/// approaching pairs (u_ik . x_ik < 0) only; rho_ik is the pair's mean density (rho_i for a wall).
pub fn particle_acceleration<R: Real>(input: &ForcesInput<R>, i: usize) -> V3<R> {
    let kernel = input.kernel;
    let gradient_viscosity = kernel.kind.gradient_viscosity();
    let viscous = input.viscosity > R::zero();
    // Terms the scene does not use are skipped, as they are compiled out on the GPU.
    let walls = !input.wall_masses.is_empty();
    let eps = R::of(0.01) * kernel.h2;
    let xi = input.fluid.positions[i];
    let ui = input.velocities[i];
    let rho_i = input.densities[i];
    let p_i = input.pressures[i];
    let pi_over = p_i / (rho_i * rho_i);
    // Adami's wall pressure is inside the sum over wall particles (`finish` applies the others').
    let adami = input.boundary_pressure == BoundaryPressure::Adami;
    let c = input.grid.cell_coords(xi);
    // Sums without the constant factors, which are applied once at the end.
    let mut fluid_pressure = V3::zero();
    let mut fluid_visc = V3::zero();
    let mut wall_pressure = V3::zero();
    let mut wall_visc = V3::zero();
    let artificial = input.artificial_viscosity_factor > R::zero();
    let mut fluid_artificial = V3::zero();
    let mut wall_artificial = V3::zero();
    let tension = input.tension.on();
    let adhesion = input.adhesion_factor > R::zero();
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
            let grad = kernel.grad_w(rij, r);
            let rho_j = input.densities[j];
            let pj_over = input.pressures[j] / (rho_j * rho_j);
            fluid_pressure -= grad * (pi_over + pj_over);
            if viscous {
                let inv_rho = R::one() / rho_j;
                let uij = ui - input.velocities[j];
                if gradient_viscosity {
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
            if tension {
                tension_sum += input.tension.pair(rij, r, rho_i, rho_j, ni, input.normals[j]);
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
                if gradient_viscosity {
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
            if adhesion {
                adhesion_sum += adhesion_pair(kernel.h, rij, r, mw);
            }
        }
    }
    let sums = ForceSums {
        fluid_pressure,
        fluid_visc,
        wall_pressure,
        wall_visc,
        fluid_artificial,
        wall_artificial,
        tension: tension_sum,
        adhesion: adhesion_sum,
    };
    finish(input, i, &sums)
}
