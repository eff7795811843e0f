//! Conservation: mass, momentum and energy.
//!
//! - Mass: every particle present, finite and inside the domain at every sample; the total mass
//!   (particle count x particle mass) exactly unchanged.
//! - Momentum: two blocks of water collide in a closed box without gravity; the run ends before
//!   any particle comes within h of the box's faces, so only the fluid's own (pairwise
//!   antisymmetric) forces act, and the total momentum must stay constant to float precision.
//!   Their kinetic + elastic energy is checked too (it may only decay, and only with viscosity).
//! - Energy of a sloshing tank (`sloshing`): kinetic + potential + elastic energy of water
//!   sloshing between wall particles must never rise, must stay nearly constant without
//!   viscosity and decay faster with more viscosity. The walls use the consistent wall pressure
//!   p_i / rho_i^2 (`BoundaryPressure::Consistent`); with the mirrored 2 p_i / rho_i^2 the energy
//!   rises (shown in the plot, see docs/validation.md). Both use the cubic spline, whose density and
//!   pressure force come from one kernel, so that the inviscid equations conserve energy
//!   (Monaghan 2005, Sec. 3).

use super::scenes::{WALL_LAYERS, sample_steps, Tank, H_OVER_SPACING};
use super::sloshing::{settled_positions, slosh, sloshing_tank, Sloshing, SETTLE_TIME};
use super::case::{energy, write_csv, Case, CaseReport, Figure, MakeBackend, Resolution, Sampler};
use crate::model::params::Params;
use crate::model::scene::{BoundaryPressure, Kernel};
use crate::model::state::Snapshot;
use crate::viz::plot::{Corner, Plot};
use std::path::Path;

/// Tolerances: momentum drift / sum m|v|, energy gain with viscosity, energy change without
/// viscosity (both over the initial energy), and the inviscid change over the viscous loss.
/// Mass has none: it must be exact.
pub fn tolerances(r: Resolution) -> [f64; 4] {
    match r {
        Resolution::Coarse => [1e-6, 0.005, 0.02, 0.1],
        _ => [1e-6, 0.005, 0.01, 0.05],
    }
}

/// Tolerances of the sloshing tank, over its initial kinetic energy K(0): the largest rise of E
/// above E(0) in any run, the largest change without viscosity, that change over the loss with
/// the smaller viscosity, and the mean loss with the smaller viscosity over that with the larger.
pub fn sloshing_tolerances(r: Resolution) -> [f64; 4] {
    match r {
        Resolution::Coarse => [0.02, 0.1, 0.1, 0.9],
        _ => [0.01, 0.05, 0.05, 0.9],
    }
}

/// Artificial viscosities of the sloshing runs: none, small, five times larger.
pub const SLOSHING_ALPHAS: [f64; 3] = [0.0, 0.01, 0.1];

/// Artificial viscosity of the collision's first run (the second has a quarter of it).
pub const ALPHA: f64 = 0.1;

/// The two colliding blocks, `10 x refinement` particles along each edge.
pub fn collision_tank(resolution: Resolution) -> Tank {
    let s = 0.2 / (10.0 * resolution.refinement());
    Tank {
        name: "momentum_box".into(),
        spacing: s,
        size: [1.4, 1.4, 1.4],
        fluid: vec![([0.3, 0.6, 0.6], [0.7, 0.8, 0.8], [1.0, 0.5, 0.0]), ([0.7, 0.6, 0.6], [1.1, 0.8, 0.8], [-1.0, 0.0, 0.25])],
        h_over_spacing: H_OVER_SPACING,
        speed_of_sound: 20.0,
        alpha: ALPHA,
        end_time: 0.1,
        gravity: [0.0; 3],
        kernel: Kernel::CubicSpline,
        walls: false,
        planes: true,
        wall_layers: WALL_LAYERS,
        boundary_pressure: BoundaryPressure::Mirror,
        dfsph: false,
    }
}

fn momentum(s: &Snapshot, m: f64) -> [f64; 3] {
    let mut p = [0.0; 3];
    for v in &s.velocities {
        for k in 0..3 {
            p[k] += m * v[k];
        }
    }
    p
}

/// Particles present, finite and inside the domain.
fn valid_particles(s: &Snapshot, p: &Params) -> usize {
    (0..s.len())
        .filter(|&i| {
            let x = s.positions[i];
            let v = s.velocities[i];
            x.iter().chain(&v).all(|c| c.is_finite()) && (0..3).all(|a| x[a] >= p.domain_min[a] && x[a] <= p.domain_max[a])
        })
        .count()
}

/// One run of the colliding blocks: momentum drift, energy curve, mass and wall checks.
struct Collision {
    drift: f64,
    near_faces: usize,
    mass_change: f64,
    /// (t, E(t) / E(0)).
    energy: Vec<(f64, f64)>,
    momentum_rows: Vec<Vec<f64>>,
    sampler: Sampler,
    failure: Option<String>,
    fluid_particles: usize,
    adapter: String,
}

fn collide(resolution: Resolution, alpha: f64, make: &mut MakeBackend) -> anyhow::Result<Collision> {
    let mut tank = collision_tank(resolution);
    tank.alpha = alpha;
    let scene = tank.scene()?;
    let params = scene.params();
    let mut backend = make(&scene, None)?;
    let n0 = backend.fluid_count();
    let first = backend.snapshot()?;
    let p0 = momentum(&first, params.fluid_mass);
    let e0 = energy(&first, &params);
    let scale: f64 = first.velocities.iter().map(|v| params.fluid_mass * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()).sum();
    let mut c = Collision {
        drift: 0.0,
        near_faces: 0,
        mass_change: 0.0,
        energy: vec![(0.0, 1.0)],
        momentum_rows: Vec::new(),
        sampler: Sampler::new(&scene),
        failure: None,
        fluid_particles: n0,
        adapter: backend.adapter(),
    };
    let h = params.h;
    let mut sampler = Sampler::new(&scene);
    let r = sampler.run(backend.as_mut(), sample_steps(0.002, tank.end_time, params.dt), |snap| {
        let p = momentum(snap, params.fluid_mass);
        let d = ((p[0] - p0[0]).powi(2) + (p[1] - p0[1]).powi(2) + (p[2] - p0[2]).powi(2)).sqrt() / scale;
        c.drift = c.drift.max(d);
        c.near_faces += snap.positions.iter().filter(|x| (0..3).any(|a| x[a] < h || x[a] > tank.size[a] - h)).count();
        let valid = valid_particles(snap, &params);
        c.mass_change = c.mass_change.max((valid as f64 - n0 as f64).abs() / n0 as f64);
        c.energy.push((snap.time, energy(snap, &params) / e0));
        c.momentum_rows.push(vec![snap.time, p[0], p[1], p[2], d]);
    })?;
    c.failure = r.err();
    c.sampler = sampler;
    Ok(c)
}

pub fn run(resolution: Resolution, out: &Path, make: &mut MakeBackend) -> anyhow::Result<CaseReport> {
    let tol = tolerances(resolution);
    let runs = [collide(resolution, ALPHA, make)?, collide(resolution, 0.0, make)?];
    let loss = |c: &Collision| 1.0 - c.energy.last().map(|e| e.1).unwrap_or(f64::NAN);
    let (l1, l2) = (loss(&runs[0]), loss(&runs[1]));
    let gain = runs[0].energy.iter().map(|e| e.1 - 1.0).fold(0.0, f64::max);
    // NaN (a run that produced none) must fail, so no fold with max here.
    let inviscid_change = runs[1].energy.iter().map(|e| (e.1 - 1.0).abs()).fold(0.0, |a: f64, b| if b.is_nan() || a.is_nan() { f64::NAN } else { a.max(b) });

    // The sloshing tank: settled once, then run with each viscosity; and, settled with mirrored
    // wall pressure, run with it without viscosity, to show what the consistent one fixes.
    let settle_tank = sloshing_tank(resolution, 0.0, BoundaryPressure::Consistent);
    let settled = settled_positions(&settle_tank, SETTLE_TIME, make)?;
    let mut sloshes = Vec::new();
    for alpha in SLOSHING_ALPHAS {
        sloshes.push(slosh(&sloshing_tank(resolution, alpha, BoundaryPressure::Consistent), &settled, make)?);
    }
    let mirror_tank = sloshing_tank(resolution, 0.0, BoundaryPressure::Mirror);
    let mirrored = slosh(&mirror_tank, &settled_positions(&mirror_tank, SETTLE_TIME, make)?, make)?;
    let stol = sloshing_tolerances(resolution);
    let nan_max = |a: f64, b: f64| if a.is_nan() || b.is_nan() { f64::NAN } else { a.max(b) };
    let slosh_gain = sloshes.iter().map(Sloshing::gain).fold(0.0, nan_max);
    let slosh_inviscid = sloshes[0].energy.iter().map(|e| e.1.abs()).fold(0.0, nan_max);
    let mean_loss = |s: &Sloshing| -s.energy.iter().map(|e| e.1).sum::<f64>() / s.energy.len() as f64;
    let (slow, fast) = (mean_loss(&sloshes[1]), mean_loss(&sloshes[2]));
    let [_, a_lo, a_hi] = SLOSHING_ALPHAS;

    let figures = vec![
        Figure::new("mass change (relative)", runs.iter().map(|c| c.mass_change).fold(0.0, f64::max), 0.0),
        Figure::new("momentum drift / sum m|v|", runs.iter().map(|c| c.drift).fold(0.0, f64::max), tol[0]),
        Figure::new("particles within h of the box's faces", runs.iter().map(|c| c.near_faces as f64).sum(), 0.0),
        Figure::new("collision: energy gain with viscosity / initial energy", gain, tol[1]),
        Figure::new("collision: energy change without viscosity / initial energy", inviscid_change, tol[2]),
        // Viscosity must dissipate: far more than the inviscid run's change.
        Figure::new("collision: inviscid change / viscous loss", if l1 > 0.0 { inviscid_change / l1 } else { f64::INFINITY }, tol[3]),
        Figure::new("sloshing: largest rise of E above E(0) / K(0)", slosh_gain, stol[0]),
        Figure::new("sloshing: largest change without viscosity / K(0)", slosh_inviscid, stol[1]),
        Figure::new(
            format!("sloshing: change without viscosity / loss with alpha = {a_lo}"),
            if sloshes[1].loss() > 0.0 { slosh_inviscid / sloshes[1].loss() } else { f64::INFINITY },
            stol[2],
        ),
        Figure::new(format!("sloshing: mean loss with alpha = {a_lo} / with alpha = {a_hi}"), if fast > 0.0 { slow / fast } else { f64::INFINITY }, stol[3]),
    ];
    let name = Case::Conservation.name();
    let plot = out.join(format!("{name}.png"));
    let csv = out.join(format!("{name}.csv"));
    // The mirrored run is shown, not judged: a blow-up of it ends its column (empty cells).
    let rows: Vec<Vec<f64>> = (0..sloshes.iter().map(|s| s.energy.len()).min().unwrap_or(0))
        .map(|i| {
            let mut row = vec![sloshes[0].energy[i].0];
            row.extend(sloshes.iter().chain([&mirrored]).map(|s| s.energy.get(i).map_or(f64::NAN, |e| e.1)));
            row.extend(sloshes.iter().map(|s| s.kinetic[i].1));
            row
        })
        .collect();
    write_csv(
        &csv,
        &["t_s", "dE_over_K0_alpha_0", "dE_over_K0_alpha_0.01", "dE_over_K0_alpha_0.1", "dE_over_K0_mirrored_walls_alpha_0", "K_over_K0_alpha_0", "K_over_K0_alpha_0.01", "K_over_K0_alpha_0.1"],
        &rows,
    )?;
    let mut p = Plot::new(
        format!("Sloshing tank ({} particles, {}): E loses {:.2} / {:.2} / {:.2} K(0)", sloshes[0].fluid_particles, resolution.name(), sloshes[0].loss(), sloshes[1].loss(), sloshes[2].loss()),
        "t [s]",
        "(E(t) - E(0)) / K(0), E = kinetic + potential + elastic",
    );
    for (alpha, s) in SLOSHING_ALPHAS.iter().zip(&sloshes) {
        p = p.line(format!("alpha = {alpha}"), s.energy.clone());
    }
    // The mirrored run (in the CSV) rises by far more than the scale of the others.
    p.legend(Corner::LowerLeft).write_png(&plot)?;

    // The collision's energy and momentum beside it.
    let collision_rows: Vec<Vec<f64>> = runs[0]
        .momentum_rows
        .iter()
        .zip(&runs[0].energy[1..])
        .zip(&runs[1].energy[1..])
        .map(|((m, e1), e2)| vec![m[0], m[1], m[2], m[3], m[4], e1.1, e2.1])
        .collect();
    write_csv(&out.join(format!("{name}_collision.csv")), &["t_s", "px", "py", "pz", "momentum_drift_over_total", "energy_over_initial_alpha", "energy_over_initial_inviscid"], &collision_rows)?;
    Plot::new(
        format!("Colliding blocks: energy ({} particles, {}); loss {:.1} % / {:.1} %", runs[0].fluid_particles, resolution.name(), 100.0 * l1, 100.0 * l2),
        "t [s]",
        "E(t) / E(0), kinetic + elastic",
    )
    .line(format!("alpha = {ALPHA}"), runs[0].energy.clone())
    .line("alpha = 0 (no viscosity)", runs[1].energy.clone())
    .legend(Corner::LowerLeft)
    .write_png(&out.join(format!("{name}_collision.png")))?;

    let [a, b] = runs;
    let spacing = settle_tank.spacing;
    let mut checked = a.sampler.checked_steps;
    checked.extend(b.sampler.checked_steps);
    let mut wall_leaks = a.sampler.wall_leaks + b.sampler.wall_leaks;
    let mut deepest = a.sampler.deepest.max(b.sampler.deepest) / collision_tank(resolution).spacing;
    let mut regime = a.sampler.regime.max(b.sampler.regime);
    let mut failure = a.failure.or(b.failure);
    for s in sloshes {
        checked.extend(s.sampler.checked_steps);
        wall_leaks += s.sampler.wall_leaks;
        deepest = deepest.max(s.sampler.deepest / spacing);
        regime = regime.max(s.sampler.regime);
        failure = failure.or(s.failure.map(|f| format!("sloshing: {f}")));
    }
    if let Some(f) = mirrored.failure {
        eprintln!("conservation: the sloshing run with mirrored wall pressure stopped: {f}");
    }
    Ok(CaseReport {
        case: Case::Conservation,
        resolution,
        fluid_particles: a.fluid_particles,
        adapter: a.adapter,
        figures,
        wall_leaks,
        deepest_spacings: deepest,
        regime,
        checked_steps: checked,
        plot,
        csv,
        wall_seconds: 0.0,
        failure,
    })
}
