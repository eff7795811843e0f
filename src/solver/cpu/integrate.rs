//! Symplectic Euler (v += dt a, then x += dt v), the analytic planes and the health counters;
//! with adaptive dt the reduction of the largest speed and acceleration and the choice of dt.
//! Twin of wgsl/sim/integrate.wgsl, one function per entry point: `integrate`,
//! `reduce_maxima`, `choose_dt`, `finish_step`.

use crate::model::params::AdaptiveDt;
use crate::model::real::{Real, V3};
use crate::model::state::Health;
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

impl StepHealth {
    fn add(self, o: StepHealth) -> StepHealth {
        StepHealth { non_finite: self.non_finite + o.non_finite, escaped: self.escaped + o.escaped }
    }
}

pub struct IntegrateInput<'a, R> {
    pub dt: R,
    pub planes: &'a [PlaneR<R>],
    pub domain_min: V3<R>,
    pub domain_max: V3<R>,
    pub accelerations: &'a [V3<R>],
}

/// Advances one particle with acceleration `a` over `dt` (wgsl `advance_particle`): a plane puts
/// a particle behind it back on it and removes (or reflects, with restitution) the velocity
/// into it, so that no particle is lost through it.
pub fn advance_particle<R: Real>(x: &mut V3<R>, v: &mut V3<R>, a: V3<R>, dt: R, planes: &[PlaneR<R>], domain: (V3<R>, V3<R>)) -> StepHealth {
    *v += a * dt;
    *x += *v * dt;
    for plane in planes {
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
    let inside = (0..3).all(|k| x.0[k] >= domain.0 .0[k] && x.0[k] <= domain.1 .0[k]);
    StepHealth { non_finite: (!finite) as u32, escaped: (finite && !inside) as u32 }
}

/// Every particle advanced in place; returns what went wrong in this step.
pub fn integrate<R: Real>(input: &IntegrateInput<R>, positions: &mut [V3<R>], velocities: &mut [V3<R>]) -> StepHealth {
    let domain = (input.domain_min, input.domain_max);
    positions
        .par_iter_mut()
        .zip(velocities.par_iter_mut())
        .zip(input.accelerations.par_iter())
        .map(|((x, v), a)| advance_particle(x, v, *a, input.dt, input.planes, domain))
        .reduce(StepHealth::default, StepHealth::add)
}

/// Adaptive dt, 1 of 2: the largest |v| (at the start of the step) and |a| (of this step), each
/// computed in `R`; a non-finite value is left out (the health check reports it).
pub fn reduce_maxima<R: Real>(velocities: &[V3<R>], accelerations: &[V3<R>]) -> (f64, f64) {
    let finite_max = |values: &mut dyn Iterator<Item = f64>| values.filter(|v| v.is_finite()).fold(0.0, f64::max);
    let speed = finite_max(&mut velocities.iter().map(|v| v.length().to64()));
    let accel = finite_max(&mut accelerations.iter().map(|a| a.length().to64()));
    (speed, accel)
}

/// Adaptive dt, 2 of 2: the step for the largest speed and acceleration (the formula of
/// [`AdaptiveDt::dt`]: the CFL, force and viscous conditions, clamped to dt_min..dt_max).
pub fn choose_dt(adaptive: &AdaptiveDt, h: f64, speed_of_sound: f64, maxima: (f64, f64), viscosity: f64) -> f64 {
    adaptive.dt(h, speed_of_sound, maxima.0, maxima.1, viscosity)
}

/// After every step: counts it and remembers the first one that went wrong.
pub fn finish_step(steps: &mut u64, health: &mut Health, found: StepHealth) {
    *steps += 1;
    health.record(*steps, found.non_finite, found.escaped);
}
