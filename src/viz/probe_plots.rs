//! A PNG plot of each probe's time series, beside its CSV (`probes/NAME.png`): the quantity a
//! probe is read for against time (pressure for a point, the surface height for a gauge, the
//! force components for a force probe, the front's position for a front).

use crate::io::probes::ProbeWriter;
use crate::model::probes::ProbeGeometry;
use crate::viz::plot::{Corner, Plot};
use std::path::PathBuf;

/// Writes `probes/NAME.png` for every probe with at least two samples; returns the files written.
pub fn plot_probes(writer: &ProbeWriter) -> anyhow::Result<Vec<PathBuf>> {
    let mut written = Vec::new();
    for (probe, csv, series) in writer.series() {
        if series.len() < 2 {
            continue;
        }
        // The columns plotted, by index, and the axis label.
        let (columns, y_label): (&[usize], &str) = match probe.geometry {
            ProbeGeometry::Point { .. } => (&[0], "pressure (Pa)"),
            ProbeGeometry::Gauge { .. } => (&[1], "water height (m)"),
            ProbeGeometry::Force { .. } => (&[0, 1, 2], "force (N)"),
            ProbeGeometry::Front { .. } => (&[0], "front (m)"),
        };
        let names = probe.geometry.columns();
        let mut plot = Plot::new(format!("probe '{}' ({})", probe.name, probe.geometry.type_name()), "time (s)", y_label).legend(Corner::UpperRight);
        for &c in columns {
            // A value that is not finite (a state gone bad) is left out of the picture.
            let points: Vec<(f64, f64)> = series.iter().map(|(t, v)| (*t, v[c])).filter(|p| p.0.is_finite() && p.1.is_finite()).collect();
            plot = plot.line(names[c], points);
        }
        let png = csv.with_extension("png");
        plot.write_png(&png)?;
        written.push(png);
    }
    Ok(written)
}
