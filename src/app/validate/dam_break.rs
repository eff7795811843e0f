//! The collapse of a water column twice as tall as wide: Martin & Moyce (1952) in dimensionless
//! form and Koshizuka & Oka (1996) in metres.
//!
//! Measurement: the surge front is the largest x of the fluid particles within one support
//! radius h of the floor that is reached from the back wall without a gap wider than h (so a
//! drop thrown ahead is not the front), plus half a particle spacing (a particle stands for a
//! cube of side s, so the water's edge lies s/2 beyond its centre; at t = 0 this gives exactly
//! the column's width). The residual height is measured the same way upwards along the back
//! wall: the particles within h of it, from the floor up to the first gap wider than h, plus s/2.
//!
//! A point probe on the far wall, a tenth of the column's width above the floor, sampled every
//! step, gives the pressure-noise figure: the standard deviation of its pressure around its
//! 20 ms moving mean over the run, over rho g H with H = 2a the column's height (reported,
//! with no bound: it measures how noisy the pressure of plain weakly compressible SPH is).

use super::data::{self, relative_errors};
use super::scenes::{WALL_LAYERS, H_OVER_SPACING, sample_steps, Tank, GRAVITY, SLAB_SPACINGS};
use super::case::{noise_around_moving_mean, write_csv, Case, CaseReport, Figure, MakeBackend, Resolution, Sampler};
use crate::viz::plot::{Corner, Plot};
use crate::model::scene::BoundaryPressure;
use crate::model::scene::Kernel;
use crate::model::scene::ProbeSpec;
use std::path::Path;

/// Artificial viscosity coefficient of the dam breaks (nu = alpha h c0 / 8): low, as for a
/// free-surface flow, still enough to keep the particles ordered.
pub const ALPHA: f64 = 0.05;

/// Column width a in particle spacings at each resolution.
pub fn column_resolution(r: Resolution) -> f64 {
    24.0 * r.refinement()
}

/// Comparison starts at T = t sqrt(2g/a) = 1: earlier, the measurements carry the gate's
/// release (data/validation README).
pub const T_FROM: f64 = 1.0;

/// Tolerances: (RMS, max) relative error of the front and of the residual height.
pub struct DamBreakTolerances {
    pub front_rms: f64,
    pub front_max: f64,
    pub height_rms: f64,
    pub height_max: f64,
}

/// The same for DFSPH's collapses (docs/validation.md): the bounds stand for the experiments'
/// scatter and the gate's release, not for the method.
pub fn tolerances(r: Resolution) -> DamBreakTolerances {
    match r {
        // At coarse resolution the last residual heights are one or two particles: their largest
        // error depends on the arithmetic's last bits (0.43 on the CPU and Mesa, 0.58 on an H100).
        Resolution::Coarse => DamBreakTolerances { front_rms: 0.15, front_max: 0.25, height_rms: 0.2, height_max: 0.7 },
        _ => DamBreakTolerances { front_rms: 0.15, front_max: 0.2, height_rms: 0.15, height_max: 0.4 },
    }
}

/// A column `a` wide and 2a tall at the back wall of a closed tank `length` x `3a`.
pub fn column_tank(name: &str, a: f64, length: f64, resolution: Resolution, end_time: f64) -> Tank {
    let s = a / column_resolution(resolution);
    // c0 = 10 sqrt(2 g H0), ten times the largest speed of the collapse (H0 = 2a).
    let c0 = 10.0 * (2.0 * GRAVITY * 2.0 * a).sqrt();
    let depth = SLAB_SPACINGS * s;
    Tank {
        name: name.into(),
        spacing: s,
        size: [length, 3.0 * a, depth],
        fluid: vec![([0.0; 3], [a, 2.0 * a, depth], [0.0; 3])],
        h_over_spacing: H_OVER_SPACING,
        speed_of_sound: c0,
        alpha: ALPHA,
        end_time,
        gravity: [0.0, -GRAVITY, 0.0],
        kernel: Kernel::CubicSpline,
        walls: true,
        planes: true,
        wall_layers: WALL_LAYERS,
        boundary_pressure: BoundaryPressure::Mirror,
        dfsph: false,
    }
}

/// One sample of a collapse: time, front x, residual height at the back wall (metres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CollapseSample {
    pub time: f64,
    pub front: f64,
    pub height: f64,
}

/// Front and back-wall height of a snapshot (see the module documentation).
pub fn measure(positions: &[[f64; 3]], h: f64, spacing: f64) -> (f64, f64) {
    let floor: Vec<f64> = positions.iter().filter(|x| x[1] < h).map(|x| x[0]).collect();
    let wall: Vec<f64> = positions.iter().filter(|x| x[0] < h).map(|x| x[1]).collect();
    (contiguous_extent(floor, h) + 0.5 * spacing, contiguous_extent(wall, h) + 0.5 * spacing)
}

/// The farthest coordinate reached from the smallest one without a gap wider than `gap`:
/// detached drops ahead of a front (or above a column) are not part of it.
pub fn contiguous_extent(mut values: Vec<f64>, gap: f64) -> f64 {
    values.sort_by(f64::total_cmp);
    let mut end = match values.first() {
        Some(&v) => v,
        None => return f64::NAN,
    };
    for &v in &values[1..] {
        if v - end > gap {
            break;
        }
        end = v;
    }
    end
}

pub struct Collapse {
    pub samples: Vec<CollapseSample>,
    pub sampler: Sampler,
    pub failure: Option<String>,
    pub fluid_particles: usize,
    pub adapter: String,
    pub spacing: f64,
    /// The far wall's pressure-noise figure (see the module's documentation).
    pub wall_noise: f64,
}

/// The moving mean the pressure noise is taken around (s).
pub const NOISE_WINDOW: f64 = 0.02;

/// The pressure-noise figure of a collapse (none without its probe: DFSPH's).
pub fn noise_figure(run: &Collapse) -> Option<Figure> {
    run.wall_noise.is_finite().then(|| Figure::reported("pressure noise at the far wall (std around the 20 ms moving mean) / rho g H", run.wall_noise))
}

/// Runs a column collapse, sampling every `every` seconds.
pub fn collapse(tank: &Tank, every: f64, make: &mut MakeBackend) -> anyhow::Result<Collapse> {
    let mut scene = tank.scene()?;
    let column = &tank.fluid[0];
    let (width, column_height) = (column.1[0] - column.0[0], column.1[1] - column.0[1]);
    // DFSPH's collapses have no noise figure (their cases read no probe).
    if !tank.dfsph {
        scene.probe.push(ProbeSpec::point("far_wall", [tank.size[0], 0.1 * width, 0.5 * tank.size[2]], 1));
    }
    let params = scene.params();
    let mut backend = make(&scene, None)?;
    let mut sampler = Sampler::new(&scene);
    let mut samples = Vec::new();
    let (h, s) = (params.h, tank.spacing);
    let first = backend.snapshot()?;
    let (front, height) = measure(&first.positions, h, s);
    samples.push(CollapseSample { time: 0.0, front, height });
    let steps = sample_steps(every, tank.end_time, params.dt);
    let result = sampler.run(backend.as_mut(), steps, |snap| {
        let (front, height) = measure(&snap.positions, h, s);
        samples.push(CollapseSample { time: snap.time, front, height });
    })?;
    let wall: Vec<(f64, f64)> = backend.take_probe_samples()?.iter().map(|p| (p.time, p.values[0])).collect();
    let wall_noise = if tank.dfsph { f64::NAN } else { noise_around_moving_mean(&wall, NOISE_WINDOW) / (params.rest_density * GRAVITY * column_height) };
    Ok(Collapse { samples, sampler, failure: result.err(), fluid_particles: backend.fluid_count(), adapter: backend.adapter(), spacing: s, wall_noise })
}

/// Martin & Moyce (1952): Z = x/a against T = t sqrt(2g/a), H = h/(2a) against tau = t sqrt(g/a).
pub fn run_martin_moyce(case: Case, resolution: Resolution, out: &Path, make: &mut MakeBackend) -> anyhow::Result<CaseReport> {
    // The experiment's column: a = 2.25 in (Martin & Moyce 1952).
    let a = 0.05715;
    let t_scale = (2.0 * GRAVITY / a).sqrt();
    let tau_scale = (GRAVITY / a).sqrt();
    let front_data = data::parse_xy(data::MARTIN_MOYCE_FRONT);
    let height_data = data::parse_xy(data::MARTIN_MOYCE_HEIGHT);
    let tau_end = height_data.last().map(|p| p.0).unwrap_or(7.4) + 0.1;
    // A tank 8a long: the front (Z <= 4.1 in the data) runs free, and the bore reflected from
    // the far wall does not reach the back wall within the measured residual heights.
    let tank = Tank { dfsph: case.dfsph(), ..column_tank(case.name(), a, 8.0 * a, resolution, tau_end / tau_scale) };
    let run = collapse(&tank, 0.05 / t_scale, make)?;
    // A sample without any particle near the floor (NaN) would only come from a failed run.
    let z: Vec<(f64, f64)> = run.samples.iter().map(|s| (s.time * t_scale, s.front / a)).filter(|p| p.1.is_finite()).collect();
    let hh: Vec<(f64, f64)> = run.samples.iter().map(|s| (s.time * tau_scale, s.height / (2.0 * a))).filter(|p| p.1.is_finite()).collect();
    let tol = tolerances(resolution);
    let (zr, zm, _) = relative_errors(&z, &front_data, |t| t >= T_FROM);
    // T >= 1 is tau >= 1/sqrt(2).
    let (hr, hm, _) = relative_errors(&hh, &height_data, |tau| tau * std::f64::consts::SQRT_2 >= T_FROM);
    let mut figures = vec![
        Figure::new("front RMS relative error", zr, tol.front_rms),
        Figure::new("front max relative error", zm, tol.front_max),
        Figure::new("height RMS relative error", hr, tol.height_rms),
        Figure::new("height max relative error", hm, tol.height_max),
    ];
    figures.extend(noise_figure(&run));
    let name = case.name();
    let plot = out.join(format!("{name}.png"));
    let csv = out.join(format!("{name}.csv"));
    let rows: Vec<Vec<f64>> = run
        .samples
        .iter()
        .map(|s| vec![s.time, s.time * t_scale, s.time * tau_scale, s.front / a, s.height / (2.0 * a)])
        .collect();
    write_csv(&csv, &["t_s", "T", "tau", "Z", "H"], &rows)?;
    let z_shown: Vec<(f64, f64)> = z.iter().copied().filter(|p| p.0 <= 4.0).collect();
    Plot::new(
        format!("Dam break, Martin & Moyce 1952 ({} particles, {}{})", run.fluid_particles, resolution.name(), method(case)),
        "T = t sqrt(2g/a) for Z,   tau = t sqrt(g/a) for H",
        "Z = x_front / a,   H = h_column / 2a",
    )
    .line("Z, simulation", z_shown)
    .points("Z, Martin & Moyce", front_data)
    .line("H, simulation", hh)
    .points("H, Martin & Moyce", height_data)
    .legend(Corner::UpperRight)
    .write_png(&plot)?;
    Ok(report(case, resolution, run, figures, plot, csv))
}

/// Koshizuka & Oka (1996): a 1 m x 2 m column in a 4 m tank, the front in metres against time.
pub fn run_koshizuka_oka(case: Case, resolution: Resolution, out: &Path, make: &mut MakeBackend) -> anyhow::Result<CaseReport> {
    let a = 1.0;
    let length = 4.0;
    let measured = data::parse_xy(data::KOSHIZUKA_OKA_FRONT);
    // To t = 0.8 s: past the last measurement and the impact on the far wall.
    let tank = Tank { dfsph: case.dfsph(), ..column_tank(case.name(), a, length, resolution, 0.8) };
    let run = collapse(&tank, 0.005, make)?;
    let front: Vec<(f64, f64)> = run.samples.iter().map(|s| (s.time, s.front)).filter(|p| p.1.is_finite()).collect();
    let t_from = T_FROM / (2.0 * GRAVITY / a).sqrt();
    // Points beyond the far wall (x >= 4 m) cannot be reached in a 4 m tank.
    let (rms, max, _) = relative_errors(
        &front,
        &measured.iter().copied().filter(|p| p.1 < length).collect::<Vec<_>>(),
        |t| t >= t_from,
    );
    let tol = tolerances(resolution);
    let mut figures = vec![Figure::new("front RMS relative error", rms, tol.front_rms), Figure::new("front max relative error", max, tol.front_max)];
    figures.extend(noise_figure(&run));
    let name = case.name();
    let plot = out.join(format!("{name}.png"));
    let csv = out.join(format!("{name}.csv"));
    let rows: Vec<Vec<f64>> = run.samples.iter().map(|s| vec![s.time, s.front, s.height]).collect();
    write_csv(&csv, &["t_s", "front_m", "back_wall_height_m"], &rows)?;
    Plot::new(
        format!("Dam break, Koshizuka & Oka 1996 ({} particles, {}{})", run.fluid_particles, resolution.name(), method(case)),
        "t [s]",
        "front position x [m]",
    )
    .line("simulation", front)
    .points("Koshizuka & Oka", measured)
    .y_range(0.8, 4.3)
    .write_png(&plot)?;
    Ok(report(case, resolution, run, figures, plot, csv))
}

/// The method, for a plot's title.
pub fn method(case: Case) -> &'static str {
    if case.dfsph() {
        ", DFSPH"
    } else if case.diffusion() {
        ", delta-SPH"
    } else {
        ""
    }
}

fn report(case: Case, resolution: Resolution, run: Collapse, figures: Vec<Figure>, plot: std::path::PathBuf, csv: std::path::PathBuf) -> CaseReport {
    CaseReport {
        case,
        resolution,
        fluid_particles: run.fluid_particles,
        adapter: run.adapter,
        figures,
        wall_leaks: run.sampler.wall_leaks,
        deepest_spacings: run.sampler.deepest / run.spacing,
        regime: run.sampler.regime,
        checked_steps: run.sampler.checked_steps,
        plot,
        csv,
        wall_seconds: 0.0,
        failure: run.failure,
    }
}
