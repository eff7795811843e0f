//! Small x-y plots written to PNG: line series, scatter points (optionally with a text label per
//! point), a highlighted series drawn on top, axis labels, a legend and a title.
//!
//! Built on `plotters` with its bitmap backend. Text is drawn with DejaVu Sans, compiled into the
//! binary (assets/fonts, licence beside it), so plots render the same on a machine without system
//! fonts. The image is encoded with `image` and written atomically (`io::atomic::write_atomic`).
//!
//! ```no_run
//! use wgsph::viz::plot::Plot;
//! Plot::new("Surge front", "T", "Z")
//!     .line("simulation", vec![(0.0, 1.0), (1.0, 1.4), (2.0, 2.3)])
//!     .points("experiment", vec![(0.4, 1.1), (1.2, 1.4), (2.0, 2.3)])
//!     .write_png(std::path::Path::new("front.png"))
//!     .unwrap();
//! ```

use crate::io::atomic::write_atomic;
use image::ImageEncoder;
use plotters::prelude::*;
use std::path::Path;
use std::sync::Once;

/// The font every plot uses, registered under plotters' "sans-serif" family.
static FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");

fn register_font() {
    static REGISTER: Once = Once::new();
    REGISTER.call_once(|| {
        // The font is compiled in and known to be valid (the unit tests render text with it).
        plotters::style::register_font("sans-serif", FontStyle::Normal, FONT)
            .unwrap_or_else(|_| panic!("the compiled-in DejaVu Sans font does not parse"));
    });
}

/// How a series is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mark {
    /// Points joined by straight lines, in the order given.
    Line,
    /// Unjoined markers (circles).
    Points,
    /// Lines with a marker on every point.
    LineAndPoints,
}

/// One data series of a plot.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    /// Name shown in the legend (empty: not in the legend).
    pub name: String,
    pub points: Vec<(f64, f64)>,
    pub mark: Mark,
    /// Text drawn beside each point (same length as `points`), or none.
    pub labels: Option<Vec<String>>,
    /// Drawn thicker and on top of the others, in a strong colour.
    pub highlight: bool,
    /// RGB colour; `None` picks the next colour of the palette.
    pub color: Option<(u8, u8, u8)>,
}

/// A plot with a title, axis labels and any number of series.
#[derive(Clone, Debug, PartialEq)]
pub struct Plot {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series>,
    /// Axis ranges; `None` fits the data with a 5 % margin.
    pub x_range: Option<(f64, f64)>,
    pub y_range: Option<(f64, f64)>,
    /// Image size in pixels.
    pub size: (u32, u32),
    /// Where the legend sits inside the axes.
    pub legend: Corner,
}

/// A corner of the axes, for the legend.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Corner {
    UpperLeft,
    UpperRight,
    LowerLeft,
    LowerRight,
}

/// A colour-blind-safe palette (Okabe & Ito 2008), black excluded (used for the axes).
const PALETTE: [(u8, u8, u8); 7] =
    [(0, 114, 178), (213, 94, 0), (0, 158, 115), (204, 121, 167), (86, 180, 233), (230, 159, 0), (120, 120, 120)];
/// Colour of highlighted series: vermilion-red, distinct from the palette's first entries.
const HIGHLIGHT: (u8, u8, u8) = (200, 0, 0);

impl Plot {
    pub fn new(title: impl Into<String>, x_label: impl Into<String>, y_label: impl Into<String>) -> Self {
        Plot {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            series: Vec::new(),
            x_range: None,
            y_range: None,
            size: (900, 600),
            legend: Corner::UpperLeft,
        }
    }

    /// Adds a series.
    pub fn series(mut self, s: Series) -> Self {
        self.series.push(s);
        self
    }

    fn add(self, name: impl Into<String>, points: Vec<(f64, f64)>, mark: Mark, highlight: bool) -> Self {
        self.series(Series { name: name.into(), points, mark, labels: None, highlight, color: None })
    }

    /// A line through the points, in the order given.
    pub fn line(self, name: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        self.add(name, points, Mark::Line, false)
    }

    /// Scatter points.
    pub fn points(self, name: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        self.add(name, points, Mark::Points, false)
    }

    /// Scatter points, each with a text label beside it (`labels` as long as `points`).
    pub fn labelled_points(mut self, name: impl Into<String>, points: Vec<(f64, f64)>, labels: Vec<String>) -> Self {
        self.series.push(Series { name: name.into(), points, mark: Mark::Points, labels: Some(labels), highlight: false, color: None });
        self
    }

    /// A highlighted series (thicker, strong colour, drawn on top), e.g. a front through a scatter.
    pub fn highlighted(self, name: impl Into<String>, points: Vec<(f64, f64)>, mark: Mark) -> Self {
        self.add(name, points, mark, true)
    }

    pub fn x_range(mut self, lo: f64, hi: f64) -> Self {
        self.x_range = Some((lo, hi));
        self
    }

    pub fn y_range(mut self, lo: f64, hi: f64) -> Self {
        self.y_range = Some((lo, hi));
        self
    }

    pub fn legend(mut self, corner: Corner) -> Self {
        self.legend = corner;
        self
    }

    pub fn size(mut self, width: u32, height: u32) -> Self {
        self.size = (width, height);
        self
    }

    /// Checks what would make a meaningless picture: non-finite values, label counts, sizes.
    fn check(&self) -> anyhow::Result<()> {
        anyhow::ensure!(self.size.0 >= 200 && self.size.1 >= 150, "plot '{}': size {:?} is below 200 x 150 pixels", self.title, self.size);
        for s in &self.series {
            if let Some(p) = s.points.iter().find(|p| !(p.0.is_finite() && p.1.is_finite())) {
                anyhow::bail!("plot '{}': series '{}' has a non-finite point {p:?}", self.title, s.name);
            }
            if let Some(l) = &s.labels {
                anyhow::ensure!(
                    l.len() == s.points.len(),
                    "plot '{}': series '{}' has {} labels for {} points",
                    self.title,
                    s.name,
                    l.len(),
                    s.points.len()
                );
            }
        }
        for (axis, r) in [("x", self.x_range), ("y", self.y_range)] {
            if let Some((lo, hi)) = r {
                anyhow::ensure!(lo.is_finite() && hi.is_finite() && hi > lo, "plot '{}': {axis} range {lo}..{hi} must be finite and increasing", self.title);
            }
        }
        Ok(())
    }

    /// The range of the data on one axis, widened by 5 % (and to a unit width when flat).
    fn fitted(&self, axis: usize) -> (f64, f64) {
        let values = self.series.iter().flat_map(|s| s.points.iter().map(move |p| if axis == 0 { p.0 } else { p.1 }));
        let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
        if !lo.is_finite() {
            return (0.0, 1.0);
        }
        let pad = if hi > lo { 0.05 * (hi - lo) } else { 0.5 * lo.abs().max(1.0) };
        (lo - pad, hi + pad)
    }

    /// Renders to an RGB buffer (row-major, 3 bytes per pixel).
    pub fn render_rgb(&self) -> anyhow::Result<Vec<u8>> {
        self.check()?;
        register_font();
        let (w, h) = self.size;
        let mut buf = vec![255u8; w as usize * h as usize * 3];
        let x = self.x_range.unwrap_or_else(|| self.fitted(0));
        let y = self.y_range.unwrap_or_else(|| self.fitted(1));
        self.draw(&mut buf, x, y).map_err(|e| anyhow::anyhow!("plot '{}': drawing failed: {e}", self.title))?;
        Ok(buf)
    }

    fn draw(&self, buf: &mut [u8], x: (f64, f64), y: (f64, f64)) -> Result<(), Box<dyn std::error::Error + '_>> {
        let root = BitMapBackend::with_buffer(buf, self.size).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(&self.title, ("sans-serif", 24))
            .margin(16)
            .x_label_area_size(50)
            .y_label_area_size(70)
            .build_cartesian_2d(x.0..x.1, y.0..y.1)?;
        chart
            .configure_mesh()
            .x_desc(&self.x_label)
            .y_desc(&self.y_label)
            .axis_desc_style(("sans-serif", 18))
            .label_style(("sans-serif", 14))
            .light_line_style(RGBColor(235, 235, 235))
            .draw()?;
        // Highlighted series last, so that they lie on top.
        let mut order: Vec<(usize, &Series)> = self.series.iter().enumerate().collect();
        order.sort_by_key(|(_, s)| s.highlight);
        let mut palette = 0usize;
        let mut colours = vec![(0u8, 0u8, 0u8); self.series.len()];
        for (i, s) in self.series.iter().enumerate() {
            colours[i] = s.color.unwrap_or_else(|| {
                if s.highlight {
                    HIGHLIGHT
                } else {
                    palette += 1;
                    PALETTE[(palette - 1) % PALETTE.len()]
                }
            });
        }
        for (i, s) in order {
            let (r, g, b) = colours[i];
            let colour = RGBColor(r, g, b);
            let width = if s.highlight { 4 } else { 2 };
            let radius = if s.highlight { 5 } else { 4 };
            let line = colour.stroke_width(width);
            let pts = s.points.clone();
            let has_line = matches!(s.mark, Mark::Line | Mark::LineAndPoints);
            let has_points = matches!(s.mark, Mark::Points | Mark::LineAndPoints);
            if has_line {
                let anno = chart.draw_series(LineSeries::new(pts.clone(), line))?;
                if !s.name.is_empty() && !has_points {
                    anno.label(s.name.clone()).legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], line));
                }
            }
            if has_points {
                let anno = chart.draw_series(pts.iter().map(|&p| Circle::new(p, radius, colour.filled())))?;
                if !s.name.is_empty() {
                    anno.label(s.name.clone()).legend(move |(x, y)| {
                        EmptyElement::at((x + 12, y)) + Circle::new((0, 0), radius, colour.filled()) + PathElement::new(
                            if has_line { vec![(-12, 0), (12, 0)] } else { vec![] },
                            line,
                        )
                    });
                }
            }
            if let Some(labels) = &s.labels {
                let font = ("sans-serif", 13).into_font().color(&colour);
                chart.draw_series(
                    pts.iter().zip(labels).map(|(&p, l)| EmptyElement::at(p) + Text::new(l.clone(), (radius + 3, -radius - 12), font.clone())),
                )?;
            }
        }
        if self.series.iter().any(|s| !s.name.is_empty()) {
            chart
                .configure_series_labels()
                .position(match self.legend {
                    Corner::UpperLeft => SeriesLabelPosition::UpperLeft,
                    Corner::UpperRight => SeriesLabelPosition::UpperRight,
                    Corner::LowerLeft => SeriesLabelPosition::LowerLeft,
                    Corner::LowerRight => SeriesLabelPosition::LowerRight,
                })
                .label_font(("sans-serif", 15))
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .draw()?;
        }
        root.present()?;
        Ok(())
    }

    /// Renders and writes a PNG atomically (a reader never sees a half-written image).
    pub fn write_png(&self, path: &Path) -> anyhow::Result<()> {
        let rgb = self.render_rgb()?;
        let (w, h) = self.size;
        write_atomic(path, |out| {
            image::codecs::png::PngEncoder::new(out)
                .write_image(&rgb, w, h, image::ExtendedColorType::Rgb8)
                .map_err(std::io::Error::other)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pixels_of(img: &image::RgbImage, colour: (u8, u8, u8)) -> usize {
        img.pixels().filter(|p| p.0 == [colour.0, colour.1, colour.2]).count()
    }

    #[test]
    fn renders_lines_points_labels_and_a_highlighted_front_to_png() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("plot.png");
        let curve: Vec<(f64, f64)> = (0..50).map(|i| (i as f64 * 0.1, (i as f64 * 0.1).sin())).collect();
        let scatter = vec![(0.5, 0.2), (2.0, -0.5), (4.0, 0.7)];
        Plot::new("Test plot", "time [s]", "value")
            .line("sine", curve)
            .labelled_points("designs", scatter.clone(), vec!["a".into(), "b".into(), "c".into()])
            .highlighted("front", vec![(0.5, 0.9), (2.0, 0.95), (4.0, 1.0)], Mark::LineAndPoints)
            .size(640, 480)
            .legend(Corner::LowerLeft)
            .write_png(&path)
            .unwrap();
        let img = image::open(&path).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (640, 480));
        let non_white = img.pixels().filter(|p| p.0 != [255, 255, 255]).count();
        // Axes, text and series cover a few percent of the picture, not nothing and not all.
        assert!(non_white > 640 * 480 / 100 && non_white < 640 * 480 / 2, "{non_white} non-white pixels");
        // Each series shows in its colour: the first palette colour, the second, the highlight.
        assert!(pixels_of(&img, PALETTE[0]) > 200, "line colour missing");
        assert!(pixels_of(&img, PALETTE[1]) > 50, "scatter colour missing");
        assert!(pixels_of(&img, HIGHLIGHT) > 100, "highlight colour missing");
        // Only the finished file is in its directory (written through a renamed temporary).
        assert_eq!(std::fs::read_dir(path.parent().unwrap()).unwrap().count(), 1);
    }

    #[test]
    fn text_is_drawn_with_the_compiled_in_font() {
        // The same empty axes with and without a title: the title adds dark pixels.
        let base = Plot::new("", "", "").x_range(0.0, 1.0).y_range(0.0, 1.0).size(400, 300);
        let dark = |rgb: &[u8]| rgb.chunks(3).filter(|p| p.iter().all(|&c| c < 128)).count();
        let without = dark(&base.render_rgb().unwrap());
        let mut titled = base.clone();
        titled.title = "A title with glyphs".into();
        let with = dark(&titled.render_rgb().unwrap());
        assert!(with > without + 100, "title drew {} dark pixels", with - without);
    }

    #[test]
    fn refuses_non_finite_points_and_mismatched_labels() {
        let e = Plot::new("t", "x", "y").line("bad", vec![(0.0, f64::NAN)]).render_rgb().unwrap_err();
        assert!(e.to_string().contains("series 'bad' has a non-finite point"), "{e}");
        let e = Plot::new("t", "x", "y").labelled_points("p", vec![(0.0, 1.0)], vec![]).render_rgb().unwrap_err();
        assert!(e.to_string().contains("0 labels for 1 points"), "{e}");
        let e = Plot::new("t", "x", "y").x_range(1.0, 0.0).render_rgb().unwrap_err();
        assert!(e.to_string().contains("x range"), "{e}");
    }
}
