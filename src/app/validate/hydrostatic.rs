//! Water at rest in a tank: after settling, the pressure against depth is compared with
//! rho0 g (H - y) and the density with the rest density.
//!
//! A 3D tank (a slab's walls in depth would stand in for part of every particle's pressure
//! gradient). The pressure and density are averaged per particle over the last third of the run (sampled
//! every 10 ms), which removes the small acoustic oscillation that remains of the settling,
//! and then per horizontal layer one support radius h thick, over the particles more than h from
//! the side walls. H is the depth the fluid's mass fills
//! at the rest density (the initial block's height).
//!
//! The pressure is also read as an instrument would, through point probes on the tank's
//! vertical centre line (sampled on the device every 10 ms, averaged over the same window), and
//! a probe at mid-depth sampled every step gives the pressure-noise figure: the standard
//! deviation of its pressure around its 20 ms moving mean over the window, over rho g H.

use super::scenes::{WALL_LAYERS, sample_steps, Tank, GRAVITY, H_OVER_SPACING};
use super::case::{noise_around_moving_mean, write_csv, Case, CaseReport, Figure, MakeBackend, Resolution, Sampler};
use crate::viz::plot::{Corner, Mark, Plot};
use crate::model::scene::BoundaryPressure;
use crate::model::scene::{DensityMethod, InitialPressure, Scene, SceneOrigin};
use crate::model::scene::Kernel;
use crate::model::scene::ProbeSpec;
use std::path::Path;

/// Water depth H and tank width (m).
pub const DEPTH: f64 = 0.4;
/// Settling time, then the averaging window (s).
pub const SETTLE: f64 = 0.8;
pub const WINDOW: f64 = 0.4;
/// Heights of the point probes on the centre line, as fractions of the depth.
pub const PROBE_HEIGHTS: [f64; 6] = [0.125, 0.25, 0.375, 0.5, 0.625, 0.75];
/// The moving mean the pressure noise is taken around (s).
pub const NOISE_WINDOW: f64 = 0.02;

pub fn layers(r: Resolution) -> f64 {
    20.0 * r.refinement()
}

/// (pressure error below the surface layer, pressure error over the whole depth, density
/// deviation below the surface layer, residual speed / sqrt(gH)).
pub fn tolerances(r: Resolution, case: Case) -> [f64; 4] {
    match r {
        // DFSPH: the layer on the floor reads about 24 % of rho g H high (see `DFSPH_ABOVE_FLOOR`);
        // a tenth of the viscosity leaves the settling less damped.
        _ if case.dfsph() => [0.3, 0.3, 0.01, 0.1],
        // Continuity density with diffusion from the hydrostatic state: the pressure read within
        // 1 % of rho g H (the pressure a sensor can read), and a tank that stays still.
        _ if case.diffusion() => [0.01, 0.01, 0.01, 0.01],
        Resolution::Coarse => [0.12, 0.12, 0.01, 0.05],
        _ => [0.04, 0.04, 0.01, 0.05],
    }
}

/// `hydrostatic_diffusion`: the still tank's pressure noise with diffusion over that without,
/// at most (measured 0.32 coarse, 0.51 default, CPU path: most of the noise the case's plain
/// tank carries is gone with the hydrostatic start and the walls' own pressure already, and
/// diffusion halves what is left).
pub const NOISE_RATIO_WITH_DIFFUSION: f64 = 0.75;

/// DFSPH: the largest mean compression in the window over the set `density_error`. The solve
/// bounds the compression it predicts; the one a step leaves differs from it to second order
/// in dt (measured 1.04 at the default resolution, 1.11 at the coarse one's 11 ms steps).
pub const DFSPH_COMPRESSION_OVER_TOLERANCE: f64 = 1.25;

/// DFSPH: the pressure error / rho g H of the layers above the one on the floor, default and
/// coarse resolution. The layer on the floor is left out: a wall particle pushes with the
/// fluid particle's stiffness K_i alone, where a fluid neighbour pushes with K_i + K_j (Bender
/// & Koschier 2017's boundary term, as SPlisHSPlasH), so the fluid next to the wall carries a
/// higher pressure to hold the column.
pub fn dfsph_above_floor_tolerance(r: Resolution) -> f64 {
    match r {
        Resolution::Coarse => 0.12,
        _ => 0.04,
    }
}

pub fn tank(resolution: Resolution) -> Tank {
    let s = DEPTH / layers(resolution);
    Tank {
        name: "hydrostatic_validation".into(),
        spacing: s,
        size: [DEPTH, 1.25 * DEPTH, DEPTH],
        fluid: vec![([0.0; 3], [DEPTH, DEPTH, DEPTH], [0.0; 3])],
        // Ten times sqrt(2 g H), the speed a particle falling from the surface would reach.
        h_over_spacing: H_OVER_SPACING,
        speed_of_sound: 10.0 * (2.0 * GRAVITY * DEPTH).sqrt(),
        // Strong: it is there to damp the settling, and leaves the state at rest unchanged.
        alpha: 0.3,
        end_time: SETTLE + WINDOW,
        gravity: [0.0, -GRAVITY, 0.0],
        kernel: Kernel::CubicSpline,
        walls: true,
        planes: true,
        wall_layers: WALL_LAYERS,
        boundary_pressure: BoundaryPressure::Mirror,
        dfsph: false,
    }
}

/// The probe of the noise figure: mid-depth on the centre line, sampled every step.
fn noise_probe() -> ProbeSpec {
    ProbeSpec::point("noise", [0.5 * DEPTH; 3], 1)
}

/// The still tank's density carried by the continuity equation with delta-SPH diffusion
/// `delta` (0: none), from the hydrostatic state: what a readable pressure needs
/// (docs/pressure.md).
fn with_diffusion(scene: &mut Scene, tank: &Tank, delta: f64) -> anyhow::Result<()> {
    let p = &mut scene.physics;
    p.density = DensityMethod::Continuity;
    p.density_diffusion = delta;
    p.initial_pressure = InitialPressure::Hydrostatic;
    scene.validate(&SceneOrigin::BuiltIn(tank.name.clone()))?;
    Ok(())
}

/// The noise figure of the same tank without diffusion (delta = 0, all else the case's): its
/// mid-depth probe alone, stepped to the window's end. NaN where that run goes bad.
fn noise_without_diffusion(tank: &Tank, make: &mut MakeBackend) -> anyhow::Result<f64> {
    let mut scene = tank.scene()?;
    with_diffusion(&mut scene, tank, 0.0)?;
    scene.probe.push(noise_probe());
    let params = scene.params();
    let mut backend = make(&scene, None)?;
    backend.step(super::scenes::steps_to(SETTLE + WINDOW, params.dt))?;
    if !backend.health()?.is_ok() {
        return Ok(f64::NAN);
    }
    let series: Vec<(f64, f64)> = backend.take_probe_samples()?.iter().filter(|s| s.time > SETTLE).map(|s| (s.time, s.values[0])).collect();
    Ok(noise_around_moving_mean(&series, NOISE_WINDOW) / (params.rest_density * GRAVITY * DEPTH))
}

pub fn run(case: Case, resolution: Resolution, out: &Path, make: &mut MakeBackend) -> anyhow::Result<CaseReport> {
    let mut tank = Tank { dfsph: case.dfsph(), ..tank(resolution) };
    if case.diffusion() {
        // The walls a sensor reads (as in `buchner_p1`): their own pressure, extrapolated from
        // the fluid, rather than the fluid particle's mirrored.
        tank.boundary_pressure = BoundaryPressure::Adami;
    }
    let mut scene = tank.scene()?;
    if case.diffusion() {
        with_diffusion(&mut scene, &tank, super::buchner::DIFFUSION)?;
    }
    let centre = 0.5 * DEPTH;
    // DFSPH's case reads the particles alone (its checks were set on them, before DFSPH had probes).
    let probes = !tank.dfsph;
    if probes {
        for (j, f) in PROBE_HEIGHTS.iter().enumerate() {
            let mut probe = ProbeSpec::point(&format!("centre_{j}"), [centre, f * DEPTH, centre], 1);
            (probe.every_steps, probe.every_seconds) = (None, Some(0.01));
            scene.probe.push(probe);
        }
        scene.probe.push(noise_probe());
    }
    let params = scene.params();
    let mut backend = make(&scene, None)?;
    let n = backend.fluid_count();
    let mut sampler = Sampler::new(&scene);
    let scene_rest_density = params.rest_density;
    let mut p_sum = vec![0.0; n];
    let mut rho_sum = vec![0.0; n];
    let mut y_sum = vec![0.0; n];
    let mut x_sum = vec![[0.0; 3]; n];
    let mut count = 0usize;
    // DFSPH: the largest mean compression, mean of max(rho / rho0 - 1, 0), of a sample.
    let mut compression = 0.0f64;
    let mut last_speed = f64::NAN;
    let settle_steps = super::scenes::steps_to(SETTLE, params.dt);
    let mut steps: Vec<u64> = sample_steps(0.1, SETTLE, params.dt);
    steps.extend(sample_steps(0.01, WINDOW, params.dt).into_iter().map(|k| k + settle_steps));
    let result = sampler.run(backend.as_mut(), steps, |snap| {
        if snap.step > settle_steps {
            for i in 0..n {
                p_sum[i] += snap.pressures[i];
                rho_sum[i] += snap.densities[i];
                y_sum[i] += snap.positions[i][1];
                x_sum[i][0] += snap.positions[i][0];
                x_sum[i][2] += snap.positions[i][2];
            }
            count += 1;
            last_speed = snap.max_speed();
            let mean = snap.densities.iter().map(|rho| (rho / scene_rest_density - 1.0).max(0.0)).sum::<f64>() / n.max(1) as f64;
            compression = compression.max(mean);
        }
    })?;
    let samples = backend.take_probe_samples()?;
    let offsets = params.probes.offsets();
    let rho0 = params.rest_density;
    let g = GRAVITY;
    let h = params.h;
    let c = count.max(1) as f64;
    let (p, rho, y): (Vec<f64>, Vec<f64>, Vec<f64>) =
        ((0..n).map(|i| p_sum[i] / c).collect(), (0..n).map(|i| rho_sum[i] / c).collect(), (0..n).map(|i| y_sum[i] / c).collect());
    // Layers one support radius h thick, by mean height: the resolution at which SPH defines a
    // field (single particle layers alternate by a few percent of rho g H, an odd-even pattern
    // of the settled lattice).
    let nl = (DEPTH / h).ceil() as usize + 2;
    let mut layer = vec![(0.0, 0.0, 0.0, 0usize); nl];
    let mut x_mean = vec![[0.0; 3]; n];
    for i in 0..n {
        x_mean[i] = [x_sum[i][0] / c, y[i], x_sum[i][2] / c];
    }
    // The interior column: more than h from the side walls, where the walls' mirrored pressure
    // would stand in for the fluid's own pressure gradient.
    let interior = |x: [f64; 3]| x[0] > h && x[0] < DEPTH - h && x[2] > h && x[2] < DEPTH - h;
    for i in (0..n).filter(|&i| interior(x_mean[i])) {
        let k = ((y[i] / h).floor().max(0.0) as usize).min(nl - 1);
        layer[k].0 += y[i];
        layer[k].1 += p[i];
        layer[k].2 += rho[i];
        layer[k].3 += 1;
    }
    let scale = rho0 * g * DEPTH;
    let mut rows = Vec::new();
    let (mut err_interior, mut err_all, mut rho_dev, mut err_above_floor) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for l in layer.iter().filter(|l| l.3 > 0) {
        let m = l.3 as f64;
        let (ly, lp, lrho) = (l.0 / m, l.1 / m, l.2 / m);
        let expected = rho0 * g * (DEPTH - ly).max(0.0);
        let e = (lp - expected).abs() / scale;
        err_all = err_all.max(e);
        if ly < DEPTH - h {
            err_interior = err_interior.max(e);
            if ly > h {
                err_above_floor = err_above_floor.max(e);
            }
            rho_dev = rho_dev.max((lrho / rho0 - 1.0).abs());
        }
        rows.push(vec![ly, lp, expected, lrho / rho0, l.3 as f64]);
    }
    if count == 0 {
        err_interior = f64::NAN;
        err_all = f64::NAN;
        rho_dev = f64::NAN;
        err_above_floor = f64::NAN;
    }
    // The probes: their pressure averaged over the window against rho0 g (H - y), and the
    // noise of the one sampled every step.
    let in_window = |s: &&crate::model::probes::ProbeSample| s.time > SETTLE;
    let mut probe_rows = Vec::new();
    let mut err_probes = if samples.iter().any(|s| in_window(&s)) { 0.0f64 } else { f64::NAN };
    for (j, f) in PROBE_HEIGHTS.iter().enumerate().filter(|_| probes) {
        let probe = &params.probes.probes[j];
        let kept: Vec<f64> = samples.iter().filter(in_window).filter(|s| probe.due(s.step, s.time, s.previous_time)).map(|s| s.values[offsets[j]]).collect();
        let mean = kept.iter().sum::<f64>() / kept.len().max(1) as f64;
        let y = f * DEPTH;
        err_probes = err_probes.max((mean - rho0 * g * (DEPTH - y)).abs() / scale);
        probe_rows.push((mean, y));
    }
    let noise = if probes {
        let noise_at = offsets[PROBE_HEIGHTS.len()];
        let noise_series: Vec<(f64, f64)> = samples.iter().filter(in_window).map(|s| (s.time, s.values[noise_at])).collect();
        noise_around_moving_mean(&noise_series, NOISE_WINDOW) / scale
    } else {
        f64::NAN
    };
    let tol = tolerances(resolution, case);
    let mut figures = vec![
        Figure::new("pressure error / rho g H below the top h", err_interior, tol[0]),
        Figure::new("pressure error / rho g H, whole depth", err_all, tol[1]),
        Figure::new("layer density deviation from rest below the top h", rho_dev, tol[2]),
        Figure::new("residual speed / sqrt(g H)", last_speed / (g * DEPTH).sqrt(), tol[3]),
    ];
    if probes {
        figures.push(Figure::new("point-probe pressure error / rho g H", err_probes, tol[0]));
        figures.push(Figure::reported("pressure noise (std around the 20 ms moving mean) / rho g H", noise));
    }
    if case.diffusion() {
        // The same tank with delta = 0: what the diffusion itself takes off the noise.
        let without = noise_without_diffusion(&tank, make)?;
        figures.push(Figure::reported("pressure noise without diffusion (delta = 0) / rho g H", without));
        figures.push(Figure::new("pressure noise with diffusion / without", noise / without, NOISE_RATIO_WITH_DIFFUSION));
    }
    if let Some(d) = &params.dfsph {
        figures.push(Figure::new("pressure error / rho g H between the floor's h and the top h", err_above_floor, dfsph_above_floor_tolerance(resolution)));
        // What DFSPH's constant-density solve bounds, against its own tolerance: the error the
        // last solve ended with, and the compression the steps left.
        let solves = backend.health()?.iterations.unwrap_or_default();
        figures.push(Figure::new("last constant-density solve's average error / set density_error", solves.pressure.last_error / d.density_error, 1.0));
        // Reported, not bounded: the first steps' solves, from the lattice at rest density with
        // nothing to warm-start from, may stop at the iteration limit while the fluid settles.
        figures.push(Figure::reported("constant-density solves stopped unconverged (whole run)", solves.pressure.unconverged as f64));
        figures.push(Figure::new("largest mean compression over the window / set density_error", compression / d.density_error, DFSPH_COMPRESSION_OVER_TOLERANCE));
    }
    let name = case.name();
    let plot = out.join(format!("{name}.png"));
    let csv = out.join(format!("{name}.csv"));
    write_csv(&csv, &["y_m", "pressure_pa", "expected_pa", "density_over_rest", "particles"], &rows)?;
    let exact = vec![(scale, 0.0), (0.0, DEPTH)];
    Plot::new(format!("Hydrostatic pressure ({n} particles, {}{})", resolution.name(), super::dam_break::method(case)), "pressure [Pa]", "height y [m]")
        .points("interior particles (time-averaged)", (0..n).filter(|&i| interior(x_mean[i])).map(|i| (p[i], y[i])).collect())
        .series(crate::viz::plot::Series {
            name: "layer means".into(),
            points: rows.iter().map(|r| (r[1], r[0])).collect(),
            mark: Mark::Points,
            labels: None,
            highlight: true,
            color: None,
        })
        .points("point probes on the centre line", probe_rows)
        .line("rho0 g (H - y)", exact)
        .legend(Corner::UpperRight)
        .write_png(&plot)?;
    Ok(CaseReport {
        case,
        resolution,
        fluid_particles: n,
        adapter: backend.adapter(),
        figures,
        wall_leaks: sampler.wall_leaks,
        deepest_spacings: sampler.deepest / tank.spacing,
        regime: sampler.regime,
        checked_steps: sampler.checked_steps,
        plot,
        csv,
        wall_seconds: 0.0,
        failure: result.err(),
    })
}
