//! The energy of a sloshing tank, for the conservation case.
//!
//! Water at rest depth H in a slab tank of length L (wall particles backed by planes, gravity)
//! is given the velocity field of the first sloshing mode of linear potential flow,
//! phi = A cos(k x) cosh(k y) with k = pi / L (standing surface waves, Lamb, Hydrodynamics, Ch. IX): u = -A k sin(k x) cosh(k y),
//! v = A k cos(k x) sinh(k y). It is divergence free and has no normal velocity at the side walls
//! and the floor, so the start is not impulsive. The total energy
//! E = kinetic + potential + elastic (`conservation::energy`) can then only decay, through
//! viscosity (and any particle stopped by a plane, whose restitution is 0).

use super::case::energy;
use super::scenes::{sample_steps, Tank, GRAVITY, H_OVER_SPACING, SLAB_SPACINGS, WALL_LAYERS};
use super::case::{MakeBackend, Resolution, Sampler};
use crate::model::scene::{BoundaryPressure, Kernel};
use std::f64::consts::PI;

/// Tank length and water depth (m).
pub const LENGTH: f64 = 0.4;
pub const DEPTH: f64 = 0.15;
/// Largest horizontal speed of the initial mode, at the free surface's centre (m/s).
pub const SURFACE_SPEED: f64 = 0.3;
/// Simulated time: about two periods of the first mode (0.8 s).
pub const END_TIME: f64 = 1.6;

/// The tank: 0.4 m x 0.3 m, water 0.15 m deep, particle spacing 0.01 m at the default resolution
/// (s = 0.01 m; coarse 0.02 m, fine 0.005 m).
pub fn sloshing_tank(resolution: Resolution, alpha: f64, boundary_pressure: BoundaryPressure) -> Tank {
    let s = 0.01 / resolution.refinement();
    let depth = SLAB_SPACINGS * s;
    Tank {
        name: "sloshing".into(),
        spacing: s,
        size: [LENGTH, 2.0 * DEPTH, depth],
        fluid: vec![([0.0; 3], [LENGTH, DEPTH, depth], [0.0; 3])],
        h_over_spacing: H_OVER_SPACING,
        // Ten times the shallow-water wave speed sqrt(g H), far above the flow's 0.3 m/s.
        speed_of_sound: 10.0 * (GRAVITY * DEPTH).sqrt(),
        alpha,
        end_time: END_TIME,
        gravity: [0.0, -GRAVITY, 0.0],
        kernel: Kernel::CubicSpline,
        walls: true,
        planes: true,
        wall_layers: WALL_LAYERS,
        boundary_pressure,
        dfsph: false,
    }
}

/// The first mode's velocity at `x` (origin at the tank's floor corner).
pub fn mode_velocity(x: [f64; 3]) -> [f64; 3] {
    let k = PI / LENGTH;
    let a = SURFACE_SPEED / (k * (k * DEPTH).cosh());
    [-a * k * (k * x[0]).sin() * (k * x[1]).cosh(), a * k * (k * x[0]).cos() * (k * x[1]).sinh(), 0.0]
}

/// One sloshing run.
pub struct Sloshing {
    /// (t, (E(t) - E(0)) / K(0)): the energy change over the initial kinetic energy.
    pub energy: Vec<(f64, f64)>,
    /// (t, K(t) / K(0)): the kinetic energy.
    pub kinetic: Vec<(f64, f64)>,
    pub sampler: Sampler,
    pub failure: Option<String>,
    pub fluid_particles: usize,
    pub adapter: String,
    pub initial_kinetic: f64,
}

impl Sloshing {
    /// Largest rise of E above E(0), over K(0).
    pub fn gain(&self) -> f64 {
        self.energy.iter().map(|e| e.1).fold(0.0, |a: f64, b| if a.is_nan() || b.is_nan() { f64::NAN } else { a.max(b) })
    }
    /// Energy lost by the end, over K(0).
    pub fn loss(&self) -> f64 {
        -self.energy.last().map(|e| e.1).unwrap_or(f64::NAN)
    }
}

/// Settling before the mode is given: the lattice, which is not in hydrostatic balance, settles
/// with alpha = 0.3 (as in the hydrostatic case) for this long, so that its settling does not
/// mix with the energy measured.
pub const SETTLE_TIME: f64 = 1.0;

/// The positions of the tank's water after settling at rest.
pub fn settled_positions(tank: &Tank, settle_time: f64, make: &mut MakeBackend) -> anyhow::Result<Vec<[f64; 3]>> {
    let settle = Tank { alpha: 0.3, ..tank.clone() };
    let scene = settle.scene()?;
    let params = scene.params();
    let mut backend = make(&scene, None)?;
    let mut sampler = Sampler::new(&scene);
    let r = sampler.run(backend.as_mut(), sample_steps(0.1, settle_time, params.dt), |_| {})?;
    if let Err(e) = r {
        anyhow::bail!("the sloshing tank's settling failed: {e}");
    }
    Ok(backend.snapshot()?.positions)
}

/// Runs the tank from `settled` positions with the first mode's velocity field.
pub fn slosh(tank: &Tank, settled: &[[f64; 3]], make: &mut MakeBackend) -> anyhow::Result<Sloshing> {
    let scene = tank.scene()?;
    let params = scene.params();
    let mut initial = scene.initial_state();
    initial.fluid_positions = settled.to_vec();
    for (v, x) in initial.fluid_velocities.iter_mut().zip(&initial.fluid_positions) {
        *v = mode_velocity(*x);
    }
    let mut backend = make(&scene, Some(initial))?;
    let first = backend.snapshot()?;
    let e0 = energy(&first, &params);
    let kinetic_energy = |vs: &[[f64; 3]]| -> f64 { vs.iter().map(|v| 0.5 * params.fluid_mass * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2])).sum() };
    let k0 = kinetic_energy(&first.velocities);
    let mut curve = vec![(0.0, 0.0)];
    let mut kinetic = vec![(0.0, 1.0)];
    let mut sampler = Sampler::new(&scene);
    let r = sampler.run(backend.as_mut(), sample_steps(0.01, tank.end_time, params.dt), |snap| {
        curve.push((snap.time, (energy(snap, &params) - e0) / k0));
        kinetic.push((snap.time, kinetic_energy(&snap.velocities) / k0));
    })?;
    Ok(Sloshing { energy: curve, kinetic, sampler, failure: r.err(), fluid_particles: backend.fluid_count(), adapter: backend.adapter(), initial_kinetic: k0 })
}
