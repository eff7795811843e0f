//! The published measurements (data/validation/, sources named in each file's `#` lines).

/// Martin & Moyce (1952), column 2a tall and a wide: (T = t sqrt(2g/a), Z = x_front / a).
pub const MARTIN_MOYCE_FRONT: &str = include_str!("../../../data/validation/mm1952_n2eq2_surge_front_ocellaris.csv");
/// Martin & Moyce (1952), the same column: (tau = t sqrt(g/a), H = h / (2a)).
pub const MARTIN_MOYCE_HEIGHT: &str = include_str!("../../../data/validation/mm1952_n2eq2_residual_height_ocellaris.csv");
/// Koshizuka & Oka (1996), 1 m x 2 m column: (t in s, x_front in m).
pub const KOSHIZUKA_OKA_FRONT: &str = include_str!("../../../data/validation/koshizuka_oka_1996_surge_front_dualsphysics.csv");
/// Buchner (2002), sensor P1 and P2, TrixiParticles' digitisation: (sensor, t sqrt(g/H), p / (rho g H)).
pub const BUCHNER_P1_TRIXI: &str = include_str!("../../../data/validation/dambreak2d_buchner2002_pressure_trixiparticles.csv");
/// Buchner (2002), sensor P1, JAX-SPH's digitisation: (t sqrt(g/H), p / (rho g H)), not sorted by time.
pub const BUCHNER_P1_JAXSPH: &str = include_str!("../../../data/validation/dambreak2d_buchner2002_P1_jaxsph.csv");

/// The (x, y) rows of a two-column CSV with `#` comment lines and one header line.
pub fn parse_xy(text: &str) -> Vec<(f64, f64)> {
    text.lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .skip(1)
        .map(|l| {
            let mut f = l.split(',').map(|v| v.trim().parse::<f64>().expect("the shipped data files are numeric (tested)"));
            (f.next().expect("two columns"), f.next().expect("two columns"))
        })
        .collect()
}

/// Linear interpolation of a series sorted by x; `None` outside its range.
pub fn interpolate(series: &[(f64, f64)], x: f64) -> Option<f64> {
    let i = series.partition_point(|p| p.0 < x);
    if i == 0 {
        return series.first().filter(|p| p.0 == x).map(|p| p.1);
    }
    let (a, b) = (series[i - 1], *series.get(i)?);
    Some(a.1 + (b.1 - a.1) * (x - a.0) / (b.0 - a.0))
}

/// RMS and maximum of |sim - exp| / |exp| over measured points (x, exp) that the simulated
/// series covers, with `include(x)`. Returns (rms, max, points used).
pub fn relative_errors(sim: &[(f64, f64)], measured: &[(f64, f64)], include: impl Fn(f64) -> bool) -> (f64, f64, usize) {
    let errs: Vec<f64> = measured
        .iter()
        .filter(|p| include(p.0))
        .filter_map(|&(x, e)| interpolate(sim, x).map(|s| ((s - e) / e).abs()))
        .collect();
    if errs.is_empty() {
        return (f64::NAN, f64::NAN, 0);
    }
    let rms = (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt();
    (rms, errs.iter().cloned().fold(0.0, f64::max), errs.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_measurements_parse() {
        let z = parse_xy(MARTIN_MOYCE_FRONT);
        assert_eq!(z.len(), 15);
        assert_eq!(z[0], (0.41, 1.11));
        assert_eq!(parse_xy(MARTIN_MOYCE_HEIGHT).len(), 17);
        let k = parse_xy(KOSHIZUKA_OKA_FRONT);
        assert_eq!(k.len(), 15);
        assert_eq!(k[14], (0.751331828, 4.132));
    }

    #[test]
    fn interpolation_and_relative_errors() {
        let s = [(0.0, 0.0), (1.0, 2.0), (2.0, 2.0)];
        assert_eq!(interpolate(&s, 0.5), Some(1.0));
        assert_eq!(interpolate(&s, 0.0), Some(0.0));
        assert_eq!(interpolate(&s, 2.0), Some(2.0));
        assert_eq!(interpolate(&s, 2.5), None);
        assert_eq!(interpolate(&s, -0.1), None);
        let (rms, max, n) = relative_errors(&s, &[(0.5, 0.8), (1.5, 2.0), (3.0, 1.0)], |x| x >= 0.5);
        assert_eq!(n, 2);
        assert!((max - 0.25).abs() < 1e-12);
        assert!((rms - (0.25f64 * 0.25 / 2.0).sqrt()).abs() < 1e-12);
    }
}
