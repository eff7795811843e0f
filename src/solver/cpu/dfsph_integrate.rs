//! DFSPH, the end of a step: positions advanced with the final velocities (x += dt v), the
//! analytic planes, the health counters, and the stiffness sums kept by particle id for the
//! next step's warm start. Twin of wgsl/sim/dfsph_integrate.wgsl (`integrate`,
//! `step_accelerations`; the step's bookkeeping is wgsl/sim/integrate.wgsl `finish_step`).

use super::integrate::{advance_particle, Backstops, StepHealth};
use crate::model::real::{Real, V3};
use rayon::prelude::*;

/// Every particle advanced in place with its velocity (planes and solid boxes may change both); returns what
/// went wrong, across ranks with the slots `ghosts` marks left out (their owners count them;
/// empty alone).
pub fn integrate<R: Real>(positions: &mut [V3<R>], velocities: &mut [V3<R>], dt: R, backstops: &Backstops<R>, domain: (V3<R>, V3<R>), ghosts: &[bool]) -> StepHealth {
    positions
        .par_iter_mut()
        .zip(velocities.par_iter_mut())
        .enumerate()
        .map(|(i, (x, v))| {
            let found = advance_particle(x, v, V3::zero(), dt, backstops, domain);
            if ghosts.get(i).copied().unwrap_or(false) {
                StepHealth::default()
            } else {
                found
            }
        })
        .reduce(StepHealth::default, StepHealth::add)
}

/// The stiffness sums of the step into the warm-start arrays, by particle id.
pub fn keep_warm_start<R: Real>(ids: &[u32], pressure_sum: &[R], divergence_sum: &[R], warm_pressure: &mut [R], warm_divergence: &mut [R]) {
    for (slot, &id) in ids.iter().enumerate() {
        warm_pressure[id as usize] = pressure_sum[slot];
        warm_divergence[id as usize] = divergence_sum[slot];
    }
}

/// The acceleration the step applied after its divergence solve: (v_end - v_start) / dt (the
/// pressure and every other force, the planes included), for `Backend::step_fields`.
pub fn step_accelerations<R: Real>(start: &[V3<R>], end: &[V3<R>], dt: R, accelerations: &mut [V3<R>]) {
    for ((a, &v0), &v1) in accelerations.iter_mut().zip(start).zip(end) {
        *a = (v1 - v0) / dt;
    }
}
