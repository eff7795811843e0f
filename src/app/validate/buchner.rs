//! The pressure on the far wall of a dam break: Buchner (2002), sensor P1.
//!
//! A water column H = 0.6 m high and 2H = 1.2 m wide at the back of a tank 3.22 m (5.366 H) long
//! collapses and hits the far wall; sensor P1 sits on that wall 0.16 m above the floor. The run
//! is a quasi-2D slab (four particle spacings deep, walls front and back) in a closed tank 2H
//! tall, with the settings that make a wall pressure readable (docs/pressure.md): continuity
//! density with delta-SPH diffusion (delta = 0.1) and a hydrostatic start, and the Adami wall
//! pressure, read by a point probe on the wall at P1 every step; the viscosity is the other dam
//! breaks' (nu = alpha h c0 / 8, alpha = 0.05, free-slip walls). Monaghan's artificial viscosity
//! instead (free-slip walls leave it to the fluid pairs) with the negative pressure kept brings
//! the arrival and the first peak onto the measured ones, but as a spike, with the plateau after
//! it still missing and four to seven times the noise (docs/validation.md), so it is not used.
//!
//! Figures, in t sqrt(g/H) and p / (rho g H), over the measured window (the first to the last
//! measured time): the arrival time (the first time the pressure exceeds 0.1 rho g H), the
//! impact peak (the largest pressure of the first impact, up to t sqrt(g/H) = 4, against the
//! measured 0.687) and the RMS difference from the measurements at the measured times (reported
//! also over the first impact and after it, apart: docs/validation.md compares both parts with
//! Marrone et al.'s 2011 delta-SPH curves). The
//! simulated pressure is compared through its 20 ms centred moving mean: the raw samples carry
//! the acoustic noise of the artificial compressibility (sound at c0 = 34 m/s crosses a kernel
//! support in about 1 ms), which real water, 40 times stiffer, does not have and the
//! experiment's sensor (a membrane of finite area, sampled and filtered) would not show. The
//! raw peak and RMS are reported beside them, and the largest measured value in the window (the
//! short spike of the overturning wave's second impact, 0.877 at 5.83) is reported, not judged.
//! So is the wall's pressure 0.2 H above the floor, where other codes' runs read P1 (jax-sph;
//! Adami, Hu & Adams 2012), against P1's measurements.

use super::case::{noise_around_moving_mean, write_csv, Case, CaseReport, Figure, MakeBackend, Resolution, Sampler};
use super::data::{self, interpolate};
use super::scenes::{sample_steps, Tank, GRAVITY, H_OVER_SPACING, SLAB_SPACINGS, WALL_LAYERS};
use crate::model::scene::{BoundaryPressure, DensityMethod, InitialPressure, Kernel, ProbeSpec};
use crate::viz::plot::{Corner, Plot};
use std::path::Path;

/// The column's height (m).
pub const HEIGHT: f64 = 0.6;
/// The tank's length, 5.366 H (m).
pub const TANK_LENGTH: f64 = 3.22;
/// Sensor P1's height above the floor (m).
pub const SENSOR_HEIGHT: f64 = 0.16;
/// Where jax-sph and Adami, Hu & Adams (2012, Fig. 15) read P1 in their runs: 0.2 H above the
/// floor (m). The case reads the wall there too and reports it beside P1 (docs/validation.md:
/// the converged pressure profile puts the measured P1 pressure at about this height).
pub const LOWER_READING_HEIGHT: f64 = 0.2 * HEIGHT;
/// The 20 ms moving mean the simulated pressure is compared through (s).
pub const MEAN_WINDOW: f64 = 0.02;
/// The first impact ends before t sqrt(g/H) = 4 (the measured pressure has settled to its
/// plateau of about 0.55 by 3.4).
pub const FIRST_IMPACT_END: f64 = 4.0;
/// The arrival: the first time the pressure exceeds this, in rho g H.
pub const ARRIVAL_LEVEL: f64 = 0.1;
/// Particles over the column's height at the default resolution.
pub const PARTICLES_OVER_HEIGHT: f64 = 30.0;
/// delta of the density diffusion.
pub const DIFFUSION: f64 = 0.1;

/// Tolerances: arrival time difference (in t sqrt(g/H)), impact peak relative error, RMS (in rho g H).
pub struct BuchnerTolerances {
    pub arrival: f64,
    pub peak: f64,
    pub rms: f64,
}

/// The default and fine resolutions are held to the targets the case exists for (peak within
/// 20 %, RMS within 0.1 rho g H, arrival within 10 % of the measured 2.49); the default run does
/// not meet them yet (docs/validation.md). The coarse run (15 particles over the column's
/// height: the sensor, 0.16 m up, is two kernel supports above the floor, and the toe of the
/// surge is one or two particles thick) only guards against a broken run (no pressure on the
/// wall, a blow-up, a front that never arrives): its bounds are about 1.3 times what it reaches
/// (arrival 0.45 late, RMS 0.25, measured 2026-11-24 on the f64 CPU path, 0.45 to 0.53 and 0.23
/// to 0.24 on the Mesa adapters); the first impact's peak depends on the last bits of the
/// arithmetic at this resolution (0.01 low on the CPU path, 0.36 low on both Mesa adapters), so
/// its bound is 0.5. At this resolution the other wall models reach about the same RMS (0.21
/// to 0.27).
pub fn tolerances(r: Resolution) -> BuchnerTolerances {
    match r {
        Resolution::Coarse => BuchnerTolerances { arrival: 0.7, peak: 0.5, rms: 0.33 },
        _ => BuchnerTolerances { arrival: 0.25, peak: 0.2, rms: 0.1 },
    }
}

/// The tank of the case at a resolution (the physics it needs is set on its scene, `scene`).
pub fn tank(resolution: Resolution, end_time: f64) -> Tank {
    let s = HEIGHT / (PARTICLES_OVER_HEIGHT * resolution.refinement());
    let depth = SLAB_SPACINGS * s;
    Tank {
        name: Case::BuchnerP1.name().into(),
        spacing: s,
        size: [TANK_LENGTH, 2.0 * HEIGHT, depth],
        fluid: vec![([0.0; 3], [2.0 * HEIGHT, HEIGHT, depth], [0.0; 3])],
        h_over_spacing: H_OVER_SPACING,
        // Ten times the largest speed of the collapse, sqrt(2 g H).
        speed_of_sound: 10.0 * (2.0 * GRAVITY * HEIGHT).sqrt(),
        alpha: super::dam_break::ALPHA,
        end_time,
        gravity: [0.0, -GRAVITY, 0.0],
        kernel: Kernel::CubicSpline,
        walls: true,
        planes: true,
        wall_layers: WALL_LAYERS,
        boundary_pressure: BoundaryPressure::Adami,
        dfsph: false,
    }
}

/// The scene: the tank with continuity density, diffusion, a hydrostatic start, the sensor's
/// point probe and one 0.2 H above the floor.
pub fn scene(tank: &Tank) -> anyhow::Result<crate::model::scene::Scene> {
    let mut scene = tank.scene()?;
    let p = &mut scene.physics;
    p.density = DensityMethod::Continuity;
    p.density_diffusion = DIFFUSION;
    p.initial_pressure = InitialPressure::Hydrostatic;
    scene.probe.push(ProbeSpec::point("P1", [TANK_LENGTH, SENSOR_HEIGHT, 0.5 * tank.size[2]], 1));
    scene.probe.push(ProbeSpec::point("at_0_2H", [TANK_LENGTH, LOWER_READING_HEIGHT, 0.5 * tank.size[2]], 1));
    scene.validate(&crate::model::scene::SceneOrigin::BuiltIn(tank.name.clone()))?;
    Ok(scene)
}

/// The measured P1 series of a digitisation, sorted by time (one of the files lists its points
/// out of order).
fn measured(text: &str, sensor_column: bool) -> Vec<(f64, f64)> {
    let mut v: Vec<(f64, f64)> = if sensor_column {
        // sensor,t_norm,p_norm: only P1's rows.
        text.lines()
            .filter(|l| l.starts_with("P1,"))
            .map(|l| {
                let f: Vec<f64> = l.split(',').skip(1).map(|v| v.trim().parse().expect("the shipped data files are numeric (tested)")).collect();
                (f[0], f[1])
            })
            .collect()
    } else {
        data::parse_xy(text)
    };
    v.sort_by(|a, b| a.0.total_cmp(&b.0));
    v
}

/// The centred moving mean over `window` of a series sorted by its first value.
pub fn moving_mean(series: &[(f64, f64)], window: f64) -> Vec<(f64, f64)> {
    let mut prefix = vec![0.0; series.len() + 1];
    for (i, &(_, p)) in series.iter().enumerate() {
        prefix[i + 1] = prefix[i] + p;
    }
    let (mut lo, mut hi) = (0, 0);
    series
        .iter()
        .map(|&(t, _)| {
            while series[lo].0 < t - 0.5 * window {
                lo += 1;
            }
            while hi < series.len() && series[hi].0 <= t + 0.5 * window {
                hi += 1;
            }
            (t, (prefix[hi] - prefix[lo]) / (hi - lo) as f64)
        })
        .collect()
}

/// The first time a series exceeds `level` (NaN if never).
pub fn arrival(series: &[(f64, f64)], level: f64) -> f64 {
    series.iter().find(|p| p.1 > level).map_or(f64::NAN, |p| p.0)
}

/// The largest value of a series with `from <= t <= to`, and its time.
pub fn peak(series: &[(f64, f64)], from: f64, to: f64) -> (f64, f64) {
    series.iter().filter(|p| p.0 >= from && p.0 <= to).fold((f64::NAN, f64::NEG_INFINITY), |best, p| if p.1 > best.1 { *p } else { best })
}

/// RMS of sim - exp at the measured times the simulated series covers.
pub fn rms_difference(sim: &[(f64, f64)], measured: &[(f64, f64)]) -> f64 {
    rms_difference_over(sim, measured, f64::NEG_INFINITY, f64::INFINITY)
}

/// RMS of sim - exp at the measured times in [from, to) that the simulated series covers.
pub fn rms_difference_over(sim: &[(f64, f64)], measured: &[(f64, f64)], from: f64, to: f64) -> f64 {
    let d: Vec<f64> = measured.iter().filter(|m| m.0 >= from && m.0 < to).filter_map(|&(t, e)| interpolate(sim, t).map(|s| s - e)).collect();
    if d.is_empty() {
        return f64::NAN;
    }
    (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt()
}

pub fn run(resolution: Resolution, out: &Path, make: &mut MakeBackend) -> anyhow::Result<CaseReport> {
    let exp = measured(data::BUCHNER_P1_TRIXI, true);
    let other = measured(data::BUCHNER_P1_JAXSPH, false);
    let t_scale = (GRAVITY / HEIGHT).sqrt();
    let rho_g_h = 1000.0 * GRAVITY * HEIGHT;
    let (window_start, window_end) = (exp[0].0, exp[exp.len() - 1].0);
    let tank = tank(resolution, (window_end + 0.05) / t_scale);
    let scene = scene(&tank)?;
    let params = scene.params();
    let mut backend = make(&scene, None)?;
    let mut sampler = Sampler::new(&scene);
    // Health and leaks every 10 ms (through the impact); the probe samples every step.
    let result = sampler.run(backend.as_mut(), sample_steps(0.01, tank.end_time, params.dt), |_| {})?;
    // Both probes sample every step: P1's pressure is the first value, the lower reading's
    // pressure the first of its columns.
    let lower_at = params.probes.offsets()[1];
    let samples = backend.take_probe_samples()?;
    let series = |at: usize| -> Vec<(f64, f64)> { samples.iter().map(|p| (p.time * t_scale, p.values[at] / rho_g_h)).collect() };
    let (raw, lower_raw) = (series(0), series(lower_at));
    let mean = moving_mean(&raw, MEAN_WINDOW * t_scale);
    let lower = moving_mean(&lower_raw, MEAN_WINDOW * t_scale);
    let in_window = |s: &[(f64, f64)]| -> Vec<(f64, f64)> { s.iter().copied().filter(|p| p.0 >= window_start && p.0 <= window_end).collect() };
    let (exp_peak, sim_peak, raw_peak) = (peak(&exp, window_start, FIRST_IMPACT_END), peak(&mean, window_start, FIRST_IMPACT_END), peak(&raw, window_start, FIRST_IMPACT_END));
    let tol = tolerances(resolution);
    let arrival_exp = arrival(&exp, ARRIVAL_LEVEL);
    let figures = vec![
        Figure::new("arrival (first p > 0.1 rho g H) difference, in t sqrt(g/H)", (arrival(&mean, ARRIVAL_LEVEL) - arrival_exp).abs(), tol.arrival),
        Figure::new("first impact peak relative error (20 ms mean)", ((sim_peak.1 - exp_peak.1) / exp_peak.1).abs(), tol.peak),
        Figure::new("RMS difference over the measured window / rho g H (20 ms mean)", rms_difference(&in_window(&mean), &exp), tol.rms),
        Figure::reported("simulated arrival, t sqrt(g/H)", arrival(&mean, ARRIVAL_LEVEL)),
        Figure::reported("simulated first impact peak / rho g H (20 ms mean)", sim_peak.1),
        Figure::reported("simulated first impact peak / rho g H (raw samples)", raw_peak.1),
        Figure::reported("RMS difference / rho g H (raw samples)", rms_difference(&in_window(&raw), &exp)),
        Figure::reported("RMS difference over the first impact (t sqrt(g/H) < 4) / rho g H (20 ms mean)", rms_difference_over(&in_window(&mean), &exp, window_start, FIRST_IMPACT_END)),
        Figure::reported("RMS difference after the first impact (t sqrt(g/H) >= 4) / rho g H (20 ms mean)", rms_difference_over(&in_window(&mean), &exp, FIRST_IMPACT_END, f64::INFINITY)),
        Figure::reported("largest simulated pressure in the window / rho g H (20 ms mean)", peak(&mean, window_start, window_end).1),
        Figure::reported("pressure noise at P1 (std around the 20 ms moving mean) / rho g H", noise_around_moving_mean(&raw, MEAN_WINDOW * t_scale)),
        Figure::reported("at 0.2 H: arrival (first p > 0.1 rho g H), t sqrt(g/H)", arrival(&lower, ARRIVAL_LEVEL)),
        Figure::reported("at 0.2 H: first impact peak / rho g H (20 ms mean)", peak(&lower, window_start, FIRST_IMPACT_END).1),
        Figure::reported("at 0.2 H: RMS difference from P1's measurements / rho g H (20 ms mean)", rms_difference(&in_window(&lower), &exp)),
    ];
    let name = Case::BuchnerP1.name();
    let plot = out.join(format!("{name}.png"));
    let csv = out.join(format!("{name}.csv"));
    let rows: Vec<Vec<f64>> = raw.iter().zip(&mean).zip(lower_raw.iter().zip(&lower)).map(|((r, m), (lr, lm))| vec![r.0 / t_scale, r.0, r.1, m.1, lr.1, lm.1]).collect();
    write_csv(&csv, &["t_s", "t_sqrt_g_over_H", "p_over_rho_g_H", "p_over_rho_g_H_20ms_mean", "p_0_2H_over_rho_g_H", "p_0_2H_over_rho_g_H_20ms_mean"], &rows)?;
    Plot::new(
        format!("Dam break, pressure at Buchner's P1 ({} particles, {})", backend.fluid_count(), resolution.name()),
        "t sqrt(g/H)",
        "p / (rho g H)",
    )
    .line("simulation, raw samples", raw.clone())
    .line("simulation, 20 ms moving mean", mean)
    .line("simulation at 0.2 H (below P1), 20 ms moving mean", lower)
    .points("Buchner 2002 (TrixiParticles' digitisation)", exp)
    .points("Buchner 2002 (JAX-SPH's digitisation)", other)
    .x_range(0.0, window_end + 0.1)
    .y_range(-0.2, 1.6)
    .legend(Corner::UpperLeft)
    .write_png(&plot)?;
    Ok(CaseReport {
        case: Case::BuchnerP1,
        resolution,
        fluid_particles: backend.fluid_count(),
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_measured_series_parse_sorted_and_the_figures_measure_what_they_say() {
        let exp = measured(data::BUCHNER_P1_TRIXI, true);
        assert_eq!(exp.len(), 98);
        assert_eq!(exp[0], (2.02512, -0.01792));
        assert!(exp.windows(2).all(|w| w[0].0 <= w[1].0));
        let other = measured(data::BUCHNER_P1_JAXSPH, false);
        assert!(other.len() > 80 && other.windows(2).all(|w| w[0].0 <= w[1].0));
        assert_eq!(arrival(&exp, ARRIVAL_LEVEL), 2.49148);
        assert_eq!(peak(&exp, exp[0].0, FIRST_IMPACT_END), (2.77411, 0.68698));
        assert_eq!(peak(&exp, 0.0, 10.0), (5.83288, 0.87672));
        // A series against itself, and shifted up by 0.1.
        assert!(rms_difference(&exp, &exp) < 1e-12);
        let up: Vec<(f64, f64)> = exp.iter().map(|p| (p.0, p.1 + 0.1)).collect();
        assert!((rms_difference(&up, &exp) - 0.1).abs() < 1e-12);
        // The two parts of the window: the first impact's points alone, then the rest.
        let early_up: Vec<(f64, f64)> = exp.iter().map(|p| (p.0, p.1 + if p.0 < FIRST_IMPACT_END { 0.3 } else { 0.0 })).collect();
        assert!((rms_difference_over(&early_up, &exp, 0.0, FIRST_IMPACT_END) - 0.3).abs() < 1e-12);
        assert!(rms_difference_over(&early_up, &exp, FIRST_IMPACT_END, f64::INFINITY) < 1e-12);
        let (n_early, n) = (exp.iter().filter(|p| p.0 < FIRST_IMPACT_END).count() as f64, exp.len() as f64);
        assert!((rms_difference(&early_up, &exp) - 0.3 * (n_early / n).sqrt()).abs() < 1e-12);
        let m = moving_mean(&[(0.0, 0.0), (1.0, 3.0), (2.0, 0.0), (3.0, 3.0)], 2.0);
        assert_eq!(m, vec![(0.0, 1.5), (1.0, 1.0), (2.0, 2.0), (3.0, 1.5)]);
    }
}
