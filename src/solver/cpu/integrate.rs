//! Symplectic Euler (v += dt a, then x += dt v), the analytic planes and the health counters;
//! with adaptive dt the reduction of the largest speed and acceleration and the choice of dt.
//! Twin of wgsl/sim/integrate.wgsl, one function per entry point: `integrate`,
//! `reduce_maxima`, `choose_dt`, `finish_step`.

use crate::model::params::{AdaptiveDt, StopLevels};
use crate::model::real::{Real, V3};
use crate::model::state::{Health, StepMeasures};
use rayon::prelude::*;

/// A plane n . x = offset in the solver's float type.
#[derive(Clone, Copy, Debug)]
pub struct PlaneR<R> {
    pub normal: V3<R>,
    pub offset: R,
    pub restitution: R,
}

/// A solid box obstacle [min, max] in the solver's float type: its analytic backstop.
#[derive(Clone, Copy, Debug)]
pub struct SolidBoxR<R> {
    pub min: V3<R>,
    pub max: V3<R>,
}

/// What keeps particles in the fluid's space besides the forces: the analytic planes and the
/// solid boxes' faces.
#[derive(Clone, Debug, Default)]
pub struct Backstops<R> {
    pub planes: Vec<PlaneR<R>>,
    pub boxes: Vec<SolidBoxR<R>>,
}

/// What the integration found this step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepHealth {
    /// Particles whose position or velocity is not finite.
    pub non_finite: u32,
    /// Particles outside the domain.
    pub escaped: u32,
    /// The largest speed the step's forces gave a particle whose position and velocity are
    /// finite (before the planes), computed in the solver's float type (the GPU reduces it per workgroup into
    /// `STATUS_STEP_MAX_SPEED`).
    pub max_speed: f64,
}

impl StepHealth {
    /// Two parts of the particles together.
    pub fn add(self, o: StepHealth) -> StepHealth {
        StepHealth { non_finite: self.non_finite + o.non_finite, escaped: self.escaped + o.escaped, max_speed: self.max_speed.max(o.max_speed) }
    }
}

pub struct IntegrateInput<'a, R> {
    pub dt: R,
    pub backstops: &'a Backstops<R>,
    pub domain_min: V3<R>,
    pub domain_max: V3<R>,
    pub accelerations: &'a [V3<R>],
    /// With continuity density, each particle's density of this step (empty otherwise).
    pub densities: &'a [R],
}

/// Advances one particle with acceleration `a` over `dt` (wgsl `advance_particle`), then its
/// [`backstop`].
pub fn advance_particle<R: Real>(x: &mut V3<R>, v: &mut V3<R>, a: V3<R>, dt: R, backstops: &Backstops<R>, domain: (V3<R>, V3<R>)) -> StepHealth {
    *v += a * dt;
    *x += *v * dt;
    // The speed the forces gave the particle, before a plane takes the velocity into it away.
    let speed = v.length().to64();
    backstop(x, v, backstops);
    let finite = x.is_finite() && v.is_finite();
    let inside = (0..3).all(|k| x.0[k] >= domain.0 .0[k] && x.0[k] <= domain.1 .0[k]);
    // As on the GPU: 0 for a non-finite particle; a finite velocity whose length overflows is
    // infinitely fast.
    StepHealth { non_finite: (!finite) as u32, escaped: (finite && !inside) as u32, max_speed: if finite { speed } else { 0.0 } }
}

/// The backstops of a particle just moved (wgsl `backstop` in shared/common.wgsl): a plane puts
/// a particle behind it back on it and removes (or reflects, with restitution) the velocity
/// into it, so that no particle is lost through it; then a solid box's nearest face does the
/// same for a particle that entered the box ([`leave_solid_boxes`]).
pub fn backstop<R: Real>(x: &mut V3<R>, v: &mut V3<R>, backstops: &Backstops<R>) {
    for plane in &backstops.planes {
        let d = x.dot(plane.normal) - plane.offset;
        if d < R::zero() {
            *x -= plane.normal * d;
            let vn = v.dot(plane.normal);
            if vn < R::zero() {
                *v -= plane.normal * ((R::one() + plane.restitution) * vn);
            }
        }
    }
    leave_solid_boxes(x, v, &backstops.boxes);
}

/// A particle strictly inside a solid box is put back on the box's nearest face and the
/// velocity into the box removed (restitution 0), as a plane does, box after box (wgsl
/// `leave_solid_boxes`). The wall particles inside the box push the fluid away before it gets
/// there; this backstop only catches what a hard impact drives through them. Ties between faces
/// go to the first in the order -x, +x, -y, +y, -z, +z.
pub fn leave_solid_boxes<R: Real>(x: &mut V3<R>, v: &mut V3<R>, boxes: &[SolidBoxR<R>]) {
    for b in boxes {
        if !(0..3).all(|k| x.0[k] > b.min.0[k] && x.0[k] < b.max.0[k]) {
            continue;
        }
        let (mut axis, mut upper, mut nearest) = (0, false, x.0[0] - b.min.0[0]);
        for k in 0..3 {
            let below = x.0[k] - b.min.0[k];
            if below < nearest {
                (axis, upper, nearest) = (k, false, below);
            }
            let above = b.max.0[k] - x.0[k];
            if above < nearest {
                (axis, upper, nearest) = (k, true, above);
            }
        }
        if upper {
            x.0[axis] = b.max.0[axis];
            v.0[axis] = v.0[axis].max(R::zero());
        } else {
            x.0[axis] = b.min.0[axis];
            v.0[axis] = v.0[axis].min(R::zero());
        }
    }
}

/// Carries the density of this step to the next, with continuity density (the part of wgsl
/// `advance_particle` under CONTINUITY): a particle whose density is not finite counts as
/// non-finite, with no speed, as on the GPU.
pub fn carry_density<R: Real>(carried: &mut R, rho: R, found: StepHealth) -> StepHealth {
    *carried = rho;
    if rho.is_finite() || found.non_finite > 0 {
        found
    } else {
        StepHealth { non_finite: 1, escaped: 0, max_speed: 0.0 }
    }
}

/// Every particle advanced in place, and with continuity density (`carried` not empty) its
/// density carried to the next step; returns what went wrong in this step.
pub fn integrate<R: Real>(input: &IntegrateInput<R>, positions: &mut [V3<R>], velocities: &mut [V3<R>], carried: &mut [R]) -> StepHealth {
    let domain = (input.domain_min, input.domain_max);
    if !carried.is_empty() {
        return positions
            .par_iter_mut()
            .zip(velocities.par_iter_mut())
            .zip(carried.par_iter_mut())
            .enumerate()
            .map(|(i, ((x, v), rho))| {
                let found = advance_particle(x, v, input.accelerations[i], input.dt, input.backstops, domain);
                carry_density(rho, input.densities[i], found)
            })
            .reduce(StepHealth::default, StepHealth::add);
    }
    positions
        .par_iter_mut()
        .zip(velocities.par_iter_mut())
        .zip(input.accelerations.par_iter())
        .map(|((x, v), a)| advance_particle(x, v, *a, input.dt, input.backstops, domain))
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

/// After every step: counts it, keeps the largest speed so far, and remembers the first step
/// that went wrong (a particle non-finite or outside the domain, or the largest density or
/// speed past its stop level) with what it measured. `max_density` is the largest density the
/// step's density stage computed, `time` the time at the end of the step.
pub fn finish_step(steps: &mut u64, health: &mut Health, found: StepHealth, max_density: f64, dt: f64, time: f64, stop: StopLevels) {
    *steps += 1;
    let measured = StepMeasures {
        non_finite: found.non_finite as u64,
        escaped: found.escaped as u64,
        max_density,
        max_speed: found.max_speed,
        dt,
        time,
    };
    health.record(*steps, measured, stop);
}
