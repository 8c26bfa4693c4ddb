//! Line plots of measured series, as SVG or PNG, through the `plotters` crate.
//!
//! A plot has a title, labelled axes with ticks, one line with markers per series and a
//! legend that names each series. Colours are the Okabe-Ito palette (distinguishable with
//! every common colour-vision deficiency), and each series also gets its own marker shape,
//! so the lines stay apart in greyscale. Past the palette's seven colours the lines are
//! dashed, then dotted; colour and marker alone differ for the first 28 series. Text is drawn with DejaVu Sans, embedded in the
//! binary (`dejavu` crate), so a plot looks the same on every machine.
//!
//! This module does not know what it plots: callers (`report`) give it named series of
//! `(x, y)` points.

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

mod boxes;
pub use boxes::{BoxPlot, Quartiles, Sample};

/// The Okabe-Ito palette, without its yellow (too light on white), in order of contrast.
const PALETTE: [RGBColor; 7] = [
    RGBColor(0, 114, 178),   // blue
    RGBColor(213, 94, 0),    // vermillion
    RGBColor(0, 158, 115),   // bluish green
    RGBColor(204, 121, 167), // reddish purple
    RGBColor(230, 159, 0),   // orange
    RGBColor(86, 180, 233),  // sky blue
    RGBColor(0, 0, 0),       // black
];

/// How a series' line is drawn: solid for the first round of the palette, then dashed, then
/// dotted, so two series never share colour, marker and line together.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Dash {
    Solid,
    Dashed,
    Dotted,
}

impl Dash {
    fn of(series: usize) -> Dash {
        match series / PALETTE.len() {
            0 => Dash::Solid,
            1 => Dash::Dashed,
            _ => Dash::Dotted,
        }
    }

    /// Dash length and gap in pixels (a solid line is one dash with no gap).
    fn pattern(self) -> (u32, u32) {
        match self {
            Dash::Solid => (1000, 0),
            Dash::Dashed => (8, 5),
            Dash::Dotted => (2, 4),
        }
    }
}

/// One named line of a plot.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Series {
    /// The name shown in the legend.
    pub name: String,
    /// The points, in the order the line joins them.
    pub points: Vec<(f64, f64)>,
}

/// A line plot: what to draw and how to label it.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LinePlot {
    pub title: String,
    /// The x axis's label, with its unit (for example "azimuth (degrees)").
    pub x_label: String,
    /// The y axis's label, with its unit.
    pub y_label: String,
    pub series: Vec<Series>,
    /// The y range; `None` fits the data (from 0 when every value is non-negative).
    pub y_range: Option<(f64, f64)>,
    /// Width and height in pixels (PNG) or user units (SVG).
    pub size: (u32, u32),
}

/// Why a plot could not be drawn or written.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error("the plot \"{0}\" has no points to draw")]
    Empty(String),
    #[error("the plot \"{title}\" has a value that is not finite: {value} in series {series}")]
    NotFinite {
        title: String,
        series: String,
        value: f64,
    },
    #[error("drawing the plot \"{title}\": {message}")]
    Draw { title: String, message: String },
    #[error("writing the plot to {path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("the plot's file name {0} must end in .svg or .png")]
    Format(PathBuf),
}

impl LinePlot {
    /// A plot with the default size (900 x 500).
    pub fn new(title: &str, x_label: &str, y_label: &str, series: Vec<Series>) -> LinePlot {
        LinePlot {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            series,
            y_range: None,
            size: (900, 500),
        }
    }

    /// The plot as an SVG document.
    pub fn svg(&self) -> Result<String, PlotError> {
        svg_of(self)
    }

    /// The plot as an RGB image.
    pub fn png(&self) -> Result<image::RgbImage, PlotError> {
        png_of(self)
    }

    /// Writes the plot to `path`, as SVG or PNG by its extension, atomically (a temporary
    /// file, then a rename).
    pub fn write(&self, path: &Path) -> Result<(), PlotError> {
        write_of(self, path)
    }

    /// The x and y ranges of the data, padded so no marker sits on the frame.
    fn ranges(&self) -> Result<(std::ops::Range<f64>, std::ops::Range<f64>), PlotError> {
        let mut pts = self
            .series
            .iter()
            .flat_map(|s| s.points.iter().flat_map(move |&(x, y)| [(s, x), (s, y)]));
        if let Some((s, v)) = pts.find(|(_, v)| !v.is_finite()) {
            return Err(PlotError::NotFinite {
                title: self.title.clone(),
                series: s.name.clone(),
                value: v,
            });
        }
        let all = || self.series.iter().flat_map(|s| s.points.iter().copied());
        if all().next().is_none() {
            return Err(PlotError::Empty(self.title.clone()));
        }
        let (xmin, xmax) = all().fold((f64::MAX, f64::MIN), |(a, b), (x, _)| (a.min(x), b.max(x)));
        let (ymin, ymax) = all().fold((f64::MAX, f64::MIN), |(a, b), (_, y)| (a.min(y), b.max(y)));
        let pad = |lo: f64, hi: f64| {
            let span = if hi > lo { hi - lo } else { lo.abs().max(1.0) };
            span * 0.04
        };
        let xp = pad(xmin, xmax);
        let x = (xmin - xp)..(xmax + xp);
        let y = match self.y_range {
            Some((lo, hi)) => lo..hi,
            None => {
                let yp = pad(ymin, ymax);
                let lo = if ymin >= 0.0 { 0.0 } else { ymin - yp };
                lo..(ymax + yp)
            }
        };
        Ok((x, y))
    }

    fn draw_lines<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), PlotError>
    where
        DB::ErrorType: 'static,
    {
        register_font();
        let (xr, yr) = self.ranges()?;
        let err = |e: DrawingAreaErrorKind<DB::ErrorType>| draw_error(self, e);
        root.fill(&WHITE).map_err(err)?;
        // The legend goes to the right of the plotting area, where no line can run under it.
        let legend_width =
            40 + 8 * self.series.iter().map(|s| s.name.len()).max().unwrap_or(0) as u32;
        let mut chart = ChartBuilder::on(root)
            .caption(&self.title, ("sans-serif", 22))
            .margin(12)
            .margin_right(12 + legend_width)
            .x_label_area_size(44)
            .y_label_area_size(64)
            .build_cartesian_2d(xr, yr)
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc(&self.x_label)
            .y_desc(&self.y_label)
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 16))
            .light_line_style(RGBColor(235, 235, 235))
            .x_label_formatter(&|x| tick(*x))
            .y_label_formatter(&|y| tick(*y))
            .draw()
            .map_err(err)?;
        for (i, s) in self.series.iter().enumerate() {
            let color = PALETTE[i % PALETTE.len()];
            let line = ShapeStyle::from(&color).stroke_width(2);
            let shape = i % 4;
            match Dash::of(i) {
                Dash::Solid => chart.draw_series(LineSeries::new(s.points.iter().copied(), line)),
                d => {
                    let (size, gap) = d.pattern();
                    chart.draw_series(DashedLineSeries::new(
                        s.points.iter().copied(),
                        size,
                        gap,
                        line,
                    ))
                }
            }
            .map_err(err)?;
            // Markers: at most about 60 per line, so dense sweeps stay readable.
            let step = (s.points.len() / 60).max(1);
            let marks = s.points.iter().copied().step_by(step);
            let fill = ShapeStyle::from(&color).filled();
            match shape {
                0 => chart.draw_series(marks.map(|p| Circle::new(p, 3, fill))),
                1 => chart.draw_series(marks.map(|p| TriangleMarker::new(p, 4, fill))),
                2 => chart.draw_series(marks.map(|p| Cross::new(p, 4, line))),
                _ => chart.draw_series(
                    marks.map(|p| EmptyElement::at(p) + Rectangle::new([(-3, -3), (3, 3)], fill)),
                ),
            }
            .map_err(err)?;
        }
        // The legend, in the right margin: each series' line, marker and name.
        let (right, top) = {
            let (range_x, range_y) = chart.plotting_area().get_pixel_range();
            (range_x.end + 14, range_y.start + 4)
        };
        for (i, s) in self.series.iter().enumerate() {
            let color = PALETTE[i % PALETTE.len()];
            let line = ShapeStyle::from(&color).stroke_width(2);
            let fill = ShapeStyle::from(&color).filled();
            let y = top + 22 * i as i32;
            let mid = (right + 12, y);
            // The legend's sample shows the line's dash: segments of its pattern.
            let (size, gap) = Dash::of(i).pattern();
            let mut x = right;
            while x < right + 24 {
                let end = (x + size as i32).min(right + 24);
                root.draw(&PathElement::new(vec![(x, y), (end, y)], line))
                    .map_err(err)?;
                x = end + gap as i32;
            }
            match i % 4 {
                0 => root.draw(&Circle::new(mid, 3, fill)),
                1 => root.draw(&TriangleMarker::new(mid, 4, fill)),
                2 => root.draw(&Cross::new(mid, 4, line)),
                _ => root.draw(&Rectangle::new(
                    [(mid.0 - 3, y - 3), (mid.0 + 3, y + 3)],
                    fill,
                )),
            }
            .map_err(err)?;
            root.draw(&Text::new(
                s.name.clone(),
                (right + 32, y - 8),
                ("sans-serif", 14).into_font(),
            ))
            .map_err(err)?;
        }
        Ok(())
    }
}

impl Drawing for LinePlot {
    fn title(&self) -> &str {
        &self.title
    }

    fn size(&self) -> (u32, u32) {
        self.size
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), PlotError>
    where
        DB::ErrorType: 'static,
    {
        self.draw_lines(root)
    }
}

/// What every kind of plot does: a title, a size, and drawing itself on a backend. The
/// files (SVG, PNG) are made the same way for all of them.
trait Drawing {
    fn title(&self) -> &str;
    fn size(&self) -> (u32, u32);
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), PlotError>
    where
        DB::ErrorType: 'static;
}

fn draw_error<P: Drawing, E: std::fmt::Display>(p: &P, e: E) -> PlotError {
    PlotError::Draw {
        title: p.title().to_string(),
        message: e.to_string(),
    }
}

fn svg_of<P: Drawing>(p: &P) -> Result<String, PlotError> {
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, p.size()).into_drawing_area();
        p.draw(&root)?;
        root.present().map_err(|e| draw_error(p, e))?;
    }
    Ok(out)
}

fn png_of<P: Drawing>(p: &P) -> Result<image::RgbImage, PlotError> {
    let (w, h) = p.size();
    let mut buf = vec![0u8; w as usize * h as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        p.draw(&root)?;
        root.present().map_err(|e| draw_error(p, e))?;
    }
    image::RgbImage::from_raw(w, h, buf).ok_or_else(|| PlotError::Draw {
        title: p.title().to_string(),
        message: "the bitmap has the wrong size".into(),
    })
}

fn write_of<P: Drawing>(p: &P, path: &Path) -> Result<(), PlotError> {
    let io = |source| PlotError::Io {
        path: path.to_path_buf(),
        source,
    };
    match path.extension().and_then(|e| e.to_str()) {
        Some("svg") => crate::output::write_atomic(path, svg_of(p)?.as_bytes()).map_err(io),
        Some("png") => {
            let mut bytes = Vec::new();
            png_of(p)?
                .write_to(
                    &mut std::io::Cursor::new(&mut bytes),
                    image::ImageFormat::Png,
                )
                .map_err(|e| io(std::io::Error::other(e)))?;
            crate::output::write_atomic(path, &bytes).map_err(io)
        }
        _ => Err(PlotError::Format(path.to_path_buf())),
    }
}

/// A tick's label: whole numbers without decimals, the others with as few as they need.
fn tick(v: f64) -> String {
    if (v - v.round()).abs() < 1e-9 * v.abs().max(1.0) {
        format!("{v:.0}")
    } else {
        let s = format!("{v:.4}");
        s.trim_end_matches('0').to_string()
    }
}

/// Registers the embedded font as plotters' "sans-serif", once per process.
fn register_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // The embedded font is a valid TrueType file: registering it cannot fail unless the
        // `dejavu` crate is broken, in which case the text is left out and the plot's lines
        // are still drawn (plotters reports a missing font as a drawing error, surfaced to
        // the caller).
        let _ = plotters::style::register_font(
            "sans-serif",
            FontStyle::Normal,
            dejavu::sans::regular(),
        );
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plot() -> LinePlot {
        LinePlot::new(
            "EPR over azimuth",
            "azimuth (degrees)",
            "error pixel rate",
            vec![
                Series {
                    name: "kb-rmw".into(),
                    points: vec![(0.0, 0.5), (90.0, 0.9), (180.0, 0.4)],
                },
                Series {
                    name: "bdp".into(),
                    points: vec![(0.0, 0.0), (90.0, 0.1), (180.0, 0.05)],
                },
            ],
        )
    }

    #[test]
    fn no_two_of_many_series_share_colour_marker_and_dash() {
        let style = |i: usize| (i % PALETTE.len(), i % 4, Dash::of(i));
        for a in 0..28 {
            for b in 0..a {
                assert_ne!(style(a), style(b), "series {a} and {b} look the same");
            }
        }
        // The second round of colours is dashed, the third dotted.
        assert_eq!(Dash::of(3), Dash::Solid);
        assert_eq!(Dash::of(PALETTE.len()), Dash::Dashed);
        assert_eq!(Dash::of(2 * PALETTE.len()), Dash::Dotted);
        // And a plot of 16 series draws.
        let many = LinePlot::new(
            "many",
            "x",
            "y",
            (0..16)
                .map(|i| Series {
                    name: format!("s{i}"),
                    points: vec![(0.0, i as f64), (1.0, i as f64 + 0.5)],
                })
                .collect(),
        );
        let svg = many.svg().unwrap();
        assert!(svg.contains("s15"));
    }

    #[test]
    fn the_svg_has_title_axis_labels_and_every_series_name() {
        let svg = plot().svg().unwrap();
        for text in [
            "EPR over azimuth",
            "azimuth (degrees)",
            "error pixel rate",
            "kb-rmw",
            "bdp",
        ] {
            assert!(svg.contains(text), "{text} missing from the SVG");
        }
    }

    #[test]
    fn the_png_draws_text_and_lines_in_the_palette() {
        let img = plot().png().unwrap();
        assert_eq!(img.dimensions(), (900, 500));
        let count = |c: RGBColor| img.pixels().filter(|p| p.0 == [c.0, c.1, c.2]).count();
        // Both series' colours are drawn, and dark text pixels exist beyond the axes' lines.
        assert!(count(PALETTE[0]) > 100);
        assert!(count(PALETTE[1]) > 100);
        let dark = img.pixels().filter(|p| p.0.iter().all(|&v| v < 80)).count();
        assert!(dark > 2000, "only {dark} dark pixels: no text?");
    }

    #[test]
    fn empty_and_non_finite_plots_are_refused() {
        let mut p = plot();
        p.series.clear();
        assert!(matches!(p.svg(), Err(PlotError::Empty(_))));
        let mut p = plot();
        p.series[1].points[1].1 = f64::NAN;
        let e = p.svg().unwrap_err().to_string();
        assert!(e.contains("bdp") && e.contains("NaN"), "{e}");
    }
}
