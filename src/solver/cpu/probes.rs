//! Probes sampled on the state a step starts from: twin of wgsl/sim/probes.wgsl, with the same
//! four entry points. `probe_points` evaluates the point probes and gauges (one invocation per
//! probe on the GPU), `probe_particles` sums the force probes and finds the fronts over the
//! fluid particles in workgroups of [`PROBE_WORKGROUP`] (one partial per workgroup and slot),
//! and `probe_finish` reduces the partials into the sample; under DFSPH the last two run after
//! the solves, on the pressure `wall_push_pressure` gives the step's wall push. What each probe measures is in
//! [`crate::model::probes`] and docs/probes.md.

use super::forces::adhesion_pair;
use crate::model::kernels::{viscous_nu, KernelCoefficients, Neighbours};
use crate::model::params::Grid;
use crate::model::probes::{Probe, ProbeGeometry, GAUGE_FRACTION};
use crate::model::real::{Real, V3};
use crate::model::scene::BoundaryPressure;
use rayon::prelude::*;

/// Particles per workgroup of `probe_particles` (PROBE_WORKGROUP in probes.wgsl).
pub const PROBE_WORKGROUP: usize = 128;
/// Values per force probe in the partials: force and moment.
pub const FORCE_SLOTS: usize = 6;
/// Values per front probe in the partials: the farthest projection and the particle count.
pub const FRONT_SLOTS: usize = 2;

/// What the probes read: the state a step starts from and the fields of its density stage.
pub struct ProbeInput<'a, R> {
    pub kernel: &'a KernelCoefficients<R>,
    pub grid: &'a Grid<R>,
    pub fluid_mass: R,
    pub viscosity: R,
    pub boundary_friction: R,
    pub boundary_pressure: BoundaryPressure,
    pub fluid: Neighbours<'a, R>,
    pub velocities: &'a [V3<R>],
    pub densities: &'a [R],
    pub pressures: &'a [R],
    pub walls: Neighbours<'a, R>,
    pub wall_masses: &'a [R],
    /// Bit k: the wall particle belongs to the k-th force probe.
    pub wall_masks: &'a [u32],
    /// With `BoundaryPressure::Adami`, each wall particle's [pressure, density] (empty otherwise).
    pub wall_fields: &'a [[R; 2]],
    pub gravity: V3<R>,
    /// alpha h_s c0 of artificial viscosity (0: off).
    pub artificial_viscosity_factor: R,
    /// beta 0.007 / h^3 of adhesion (0: off).
    pub adhesion_factor: R,
}

/// Under DFSPH, the pressure whose wall force as the force probes sum it (the consistent form,
/// -m_b p_i / rho_i^2 grad W_ib) is the step's wall push: the solves change v_i by
/// -K_i g_i^w (g_i^w = sum_b V_b grad W_ib, V_b = m_b / rho0), over dt in the constant-density
/// solve (K per dt^2 after the 1 / dt of its velocity change) and once in the divergence solve,
/// and the wall feels the opposite of m_i dv_i / dt (the force SPlisHSPlasH puts on its rigid
/// bodies). So p_i = rho_i^2 (Kp_i / dt^2 + Kd_i / dt) / rho0, with the step's stiffness sums
/// (wgsl `wall_push_pressure`).
pub fn wall_push_pressure<R: Real>(densities: &[R], pressure_sum: &[R], divergence_sum: &[R], rest_density: R, dt: R, out: &mut Vec<R>) {
    out.clear();
    out.extend(densities.iter().zip(pressure_sum).zip(divergence_sum).map(|((&rho, &kp), &kd)| rho * rho * (kp / (dt * dt) + kd / dt) / rest_density));
}

/// Sums at a point over the fluid particles within h (wgsl `ShepardSums`).
struct ShepardSums<R> {
    /// sum V_j W, with V_j = m / rho_j: the fluid fraction.
    fraction: R,
    /// sum V_j W f_j for pressure, density and velocity.
    pressure: R,
    density: R,
    velocity: V3<R>,
    /// With the Adami wall pressure: sum W, sum p_j W and sum rho_j (x - x_j) W, the sums of the
    /// wall particles' extrapolation (wall_pressure.rs) taken at the point.
    weights: R,
    weighted_pressure: R,
    hydrostatic: V3<R>,
}

fn shepard_sums<R: Real>(input: &ProbeInput<R>, x: V3<R>) -> ShepardSums<R> {
    let adami = input.boundary_pressure == BoundaryPressure::Adami;
    let mut s = ShepardSums {
        fraction: R::zero(),
        pressure: R::zero(),
        density: R::zero(),
        velocity: V3::zero(),
        weights: R::zero(),
        weighted_pressure: R::zero(),
        hydrostatic: V3::zero(),
    };
    for (k0, k1) in input.grid.stencil_runs(input.grid.cell_coords(x)) {
        for j in input.fluid.span(k0, k1) {
            let d = x - input.fluid.positions[j];
            let w = input.kernel.w(d.length_squared());
            let vw = input.fluid_mass / input.densities[j] * w;
            s.fraction = s.fraction + vw;
            s.pressure = s.pressure + vw * input.pressures[j];
            s.density = s.density + vw * input.densities[j];
            s.velocity += input.velocities[j] * vw;
            if adami {
                s.weights = s.weights + w;
                s.weighted_pressure = s.weighted_pressure + w * input.pressures[j];
                s.hydrostatic += d * (input.densities[j] * w);
            }
        }
    }
    s
}

/// The fluid fraction sum_j V_j W at a point.
fn fluid_fraction<R: Real>(input: &ProbeInput<R>, x: V3<R>) -> R {
    shepard_sums(input, x).fraction
}

/// The pressure a point probe reads from its sums: the Shepard average, or with the Adami wall
/// pressure the wall's own extrapolation evaluated at the point, (sum p_j W + g . sum rho_j
/// (x - x_j) W) / sum W (Adami et al. 2012, Eq. 27), so that a point on a wall reads what a wall
/// particle there would carry (see docs/probes.md). Both are 0 with no fluid within h.
/// `r` is 1 / fraction (0 without fluid).
fn point_pressure<R: Real>(input: &ProbeInput<R>, s: &ShepardSums<R>, r: R) -> R {
    if input.boundary_pressure != BoundaryPressure::Adami {
        return s.pressure * r;
    }
    if s.weights <= R::zero() {
        return R::zero();
    }
    let mut p = s.weighted_pressure;
    if input.gravity != V3::zero() {
        p = p + input.gravity.dot(s.hydrostatic);
    }
    p / s.weights
}

/// Point probes and gauges: each writes its columns at its offset of `values`.
pub fn probe_points<R: Real>(input: &ProbeInput<R>, probes: &[Probe], offsets: &[usize], values: &mut [R]) {
    let results: Vec<(usize, Vec<R>)> = probes
        .par_iter()
        .zip(offsets)
        .filter_map(|(probe, &at)| match &probe.geometry {
            ProbeGeometry::Point { position } => {
                let s = shepard_sums(input, V3::from64(*position));
                // No fluid within h: zeros (the fraction column says so).
                let r = if s.fraction > R::zero() { R::one() / s.fraction } else { R::zero() };
                let v = s.velocity;
                Some((at, vec![point_pressure(input, &s, r), s.density * r, v.x() * r, v.y() * r, v.z() * r, s.fraction]))
            }
            ProbeGeometry::Gauge { x, z, bottom, top, step } => {
                let surface = gauge_surface(input, R::of(*x), R::of(*z), R::of(*bottom), R::of(*top), R::of(*step));
                Some((at, vec![surface, surface - R::of(*bottom)]))
            }
            _ => None,
        })
        .collect();
    for (at, v) in results {
        values[at..at + v.len()].copy_from_slice(&v);
    }
}

/// The highest point of the line where the fluid fraction reaches [`GAUGE_FRACTION`]: levels
/// from the top down, `step` apart (the last one at the bottom), interpolated linearly between
/// the first level that reaches it and the one above; the bottom when none does.
pub fn gauge_surface<R: Real>(input: &ProbeInput<R>, x: R, z: R, bottom: R, top: R, step: R) -> R {
    surface_from_fractions(bottom, top, step, |_, y| fluid_fraction(input, V3::new(x, y, z)))
}

/// The heights of a gauge's levels, from the top down, as [`gauge_surface`] visits them.
pub fn gauge_levels<R: Real>(bottom: R, top: R, step: R) -> Vec<R> {
    let mut levels = Vec::new();
    surface_from_fractions(bottom, top, step, |_, y| {
        levels.push(y);
        R::zero()
    });
    levels
}

/// The fluid fraction at each of a gauge's levels that `evaluates` (0 at the others): across
/// ranks, each rank evaluates the levels in its slab, and the ranks' sums give the whole line.
pub fn gauge_fractions<R: Real>(input: &ProbeInput<R>, x: R, z: R, bottom: R, top: R, step: R, evaluates: impl Fn(V3<R>) -> bool) -> Vec<R> {
    gauge_levels(bottom, top, step)
        .into_iter()
        .map(|y| {
            let at = V3::new(x, y, z);
            if evaluates(at) { fluid_fraction(input, at) } else { R::zero() }
        })
        .collect()
}

/// A gauge's surface from the fluid fraction at its levels (`fraction(k, y)` for the k-th level
/// from the top, at height y), visited from the top down until one reaches the level of the
/// surface.
pub fn surface_from_fractions<R: Real>(bottom: R, top: R, step: R, mut fraction: impl FnMut(usize, R) -> R) -> R {
    let half = R::of(GAUGE_FRACTION);
    let levels = ((top - bottom) / step).to64().floor() as u32 + 1;
    let (mut above, mut above_y) = (R::zero(), top);
    for k in 0..=levels {
        let y = (top - step * R::of(k as f64)).max(bottom);
        let f = fraction(k as usize, y);
        if f >= half {
            if k == 0 {
                return y;
            }
            return y + (above_y - y) * (f - half) / (f - above);
        }
        (above, above_y) = (f, y);
        if y <= bottom {
            break;
        }
    }
    bottom
}

/// The force and moment on the force probes' walls and the fronts, per particle, reduced per
/// workgroup of [`PROBE_WORKGROUP`] particles into `partials` (slot-major: slot s of workgroup
/// g at s * groups + g; force probe k holds slots 6k..6k+6, front probe q slots 6F + 2q and
/// 6F + 2q + 1). `counted`: the particles that count (across ranks, a rank's own particles,
/// not its ghosts); all of them when `None`.
pub fn probe_particles<R: Real>(input: &ProbeInput<R>, probes: &[Probe], counted: Option<&[bool]>, partials: &mut Vec<R>) {
    let forces: Vec<[f64; 3]> = probes
        .iter()
        .filter_map(|p| match &p.geometry {
            ProbeGeometry::Force { centre, .. } => Some(*centre),
            _ => None,
        })
        .collect();
    let fronts: Vec<([f64; 3], f64, f64)> = probes
        .iter()
        .filter_map(|p| match &p.geometry {
            ProbeGeometry::Front { direction, floor, height } => Some((*direction, *floor, *height)),
            _ => None,
        })
        .collect();
    let slots = FORCE_SLOTS * forces.len() + FRONT_SLOTS * fronts.len();
    let n = input.fluid.positions.len();
    let groups = n.div_ceil(PROBE_WORKGROUP).max(1);
    let centres: Vec<V3<R>> = forces.iter().map(|&c| V3::from64(c)).collect();
    let per_group: Vec<Vec<R>> = (0..groups)
        .into_par_iter()
        .map(|g| {
            let mut sums = vec![R::zero(); slots];
            for i in g * PROBE_WORKGROUP..((g + 1) * PROBE_WORKGROUP).min(n) {
                if counted.is_some_and(|c| !c[i]) {
                    continue;
                }
                let xi = input.fluid.positions[i];
                if !centres.is_empty() {
                    let f = particle_wall_forces(input, i, &centres);
                    for (s, v) in f.iter().enumerate() {
                        sums[s] = sums[s] + *v;
                    }
                }
                for (q, (direction, floor, height)) in fronts.iter().enumerate() {
                    let s = FORCE_SLOTS * forces.len() + FRONT_SLOTS * q;
                    if xi.y() < R::of(floor + height) {
                        let along = xi.dot(V3::from64(*direction));
                        sums[s] = if sums[s + 1] == R::zero() { along } else { sums[s].max(along) };
                        sums[s + 1] = sums[s + 1] + R::one();
                    }
                }
            }
            sums
        })
        .collect();
    partials.clear();
    partials.resize(slots * groups, R::zero());
    for (g, sums) in per_group.iter().enumerate() {
        for (s, v) in sums.iter().enumerate() {
            partials[s * groups + g] = *v;
        }
    }
}

/// The force (and its moment about `centres[k]`) fluid particle `i` exerts on the wall
/// particles of each force probe k: the reaction to the wall terms of its acceleration in
/// forces.rs (pressure, viscosity, artificial viscosity and adhesion), m_i times minus what wall
/// particle w adds to a_i.
pub fn particle_wall_forces<R: Real>(input: &ProbeInput<R>, i: usize, centres: &[V3<R>]) -> Vec<R> {
    let kernel = input.kernel;
    let gradient_viscosity = kernel.kind.gradient_viscosity();
    let viscous = input.viscosity > R::zero();
    let eps = R::of(0.01) * kernel.h2;
    let xi = input.fluid.positions[i];
    let ui = input.velocities[i];
    let rho_i = input.densities[i];
    let p_i = input.pressures[i];
    let pi_over = p_i / (rho_i * rho_i);
    let wall_p_over = match input.boundary_pressure {
        BoundaryPressure::Mirror => R::of(2.0) * p_i.max(R::zero()) / (rho_i * rho_i),
        BoundaryPressure::Consistent => pi_over,
        // Per wall particle, below.
        BoundaryPressure::Adami => R::zero(),
    };
    let adami = input.boundary_pressure == BoundaryPressure::Adami;
    let nu = viscous_nu(kernel.kind, input.viscosity);
    let visc_factor = nu * input.boundary_friction / rho_i;
    let artificial = input.artificial_viscosity_factor > R::zero();
    let artificial_factor = input.artificial_viscosity_factor * input.boundary_friction / rho_i;
    let adhesion = input.adhesion_factor > R::zero();
    let mut out = vec![R::zero(); FORCE_SLOTS * centres.len()];
    if input.wall_masses.is_empty() {
        return out;
    }
    for (k0, k1) in input.grid.stencil_runs(input.grid.cell_coords(xi)) {
        for j in input.walls.span(k0, k1) {
            let mask = input.wall_masks[j];
            if mask == 0 {
                continue;
            }
            let xw = input.walls.positions[j];
            let rij = xi - xw;
            let r2 = rij.length_squared();
            if r2 >= kernel.h2 {
                continue;
            }
            let r = r2.sqrt();
            let grad = kernel.grad_w(rij, r);
            let mw = input.wall_masses[j];
            // What wall particle w adds to a_i, and the opposite force on the wall.
            let mut a = if adami {
                let [p_w, rho_w] = input.wall_fields[j];
                grad * (-mw * (pi_over + p_w / (rho_w * rho_w)))
            } else {
                grad * (-mw * wall_p_over)
            };
            if viscous {
                a += if gradient_viscosity { grad * (visc_factor * mw * ui.dot(rij) / (r2 + eps)) } else { ui * (-visc_factor * mw * kernel.lap_w(r)) };
            }
            if artificial {
                let approach = ui.dot(rij);
                if approach < R::zero() {
                    a += grad * (artificial_factor * mw * approach / (r2 + eps));
                }
            }
            if adhesion {
                a -= adhesion_pair(kernel.h, rij, r, mw) * input.adhesion_factor;
            }
            let f = a * (-input.fluid_mass);
            for (k, c) in centres.iter().enumerate() {
                if mask & (1 << k) == 0 {
                    continue;
                }
                let arm = xw - *c;
                let m = [arm.y() * f.z() - arm.z() * f.y(), arm.z() * f.x() - arm.x() * f.z(), arm.x() * f.y() - arm.y() * f.x()];
                let s = FORCE_SLOTS * k;
                for (a, v) in [f.x(), f.y(), f.z(), m[0], m[1], m[2]].into_iter().enumerate() {
                    out[s + a] = out[s + a] + v;
                }
            }
        }
    }
    out
}

/// Reduces the workgroups' partials into the force and front probes' columns of `values`: sums
/// in workgroup order, the front's farthest projection over the workgroups that saw fluid in
/// its band (0 when none did).
pub fn probe_finish<R: Real>(probes: &[Probe], offsets: &[usize], partials: &[R], values: &mut [R]) {
    let forces = probes.iter().filter(|p| matches!(p.geometry, ProbeGeometry::Force { .. })).count();
    let slots = FORCE_SLOTS * forces + FRONT_SLOTS * probes.iter().filter(|p| matches!(p.geometry, ProbeGeometry::Front { .. })).count();
    let groups = if slots == 0 { 1 } else { partials.len() / slots };
    let slot = |s: usize| &partials[s * groups..(s + 1) * groups];
    let (mut force, mut front) = (0, 0);
    for (probe, &at) in probes.iter().zip(offsets) {
        match probe.geometry {
            ProbeGeometry::Force { .. } => {
                for a in 0..FORCE_SLOTS {
                    values[at + a] = slot(FORCE_SLOTS * force + a).iter().fold(R::zero(), |s, &v| s + v);
                }
                force += 1;
            }
            ProbeGeometry::Front { .. } => {
                let s = FORCE_SLOTS * forces + FRONT_SLOTS * front;
                let mut count = R::zero();
                let mut far = R::zero();
                for (&x, &c) in slot(s).iter().zip(slot(s + 1)) {
                    if c > R::zero() {
                        far = if count == R::zero() { x } else { far.max(x) };
                        count = count + c;
                    }
                }
                values[at] = far;
                values[at + 1] = count;
                front += 1;
            }
            _ => {}
        }
    }
}
