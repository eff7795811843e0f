//! Symplectic Euler (v += dt a, then x += dt v) and the analytic boundaries: twin of
//! wgsl/integrate.wgsl.

use crate::real::{Real, V3};
use rayon::prelude::*;

/// A plane n . x = offset in the solver's float type.
#[derive(Clone, Copy, Debug)]
pub struct PlaneR<R> {
    pub normal: V3<R>,
    pub offset: R,
    pub restitution: R,
}

/// What the integration found wrong this step.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StepHealth {
    /// Particles whose position or velocity is not finite.
    pub non_finite: u32,
    /// Particles outside the domain.
    pub escaped: u32,
}

pub struct IntegrateInput<'a, R> {
    pub dt: R,
    pub planes: &'a [PlaneR<R>],
    pub domain_min: V3<R>,
    pub domain_max: V3<R>,
    pub accelerations: &'a [V3<R>],
}

pub fn integrate<R: Real>(input: &IntegrateInput<R>, positions: &mut [V3<R>], velocities: &mut [V3<R>]) -> StepHealth {
    positions
        .par_iter_mut()
        .zip(velocities.par_iter_mut())
        .zip(input.accelerations.par_iter())
        .map(|((x, v), a)| {
            *v += *a * input.dt;
            *x += *v * input.dt;
            // A plane puts a particle behind it back on it and removes (or reflects, with
            // restitution) the velocity into it, so no particle is lost through it.
            for plane in input.planes {
                let d = x.dot(plane.normal) - plane.offset;
                if d < R::zero() {
                    *x -= plane.normal * d;
                    let vn = v.dot(plane.normal);
                    if vn < R::zero() {
                        *v -= plane.normal * ((R::one() + plane.restitution) * vn);
                    }
                }
            }
            let finite = x.is_finite() && v.is_finite();
            let inside = (0..3).all(|a| x.0[a] >= input.domain_min.0[a] && x.0[a] <= input.domain_max.0[a]);
            StepHealth { non_finite: (!finite) as u32, escaped: (finite && !inside) as u32 }
        })
        .reduce(StepHealth::default, |a, b| StepHealth {
            non_finite: a.non_finite + b.non_finite,
            escaped: a.escaped + b.escaped,
        })
}
