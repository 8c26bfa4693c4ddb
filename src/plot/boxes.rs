//! Box plots: one horizontal box per named sample (its quartiles, median and extremes),
//! coloured by the sample's group, with a legend naming the groups.
//!
//! Horizontal, so that long names read on the left without rotation; consecutive boxes of
//! one name (one per group) share a label.
//! The box spans the first to the third quartile, the thick bar is the median and the
//! whiskers reach the smallest and largest value (no outlier rule: every value is inside the
//! whiskers, which the caption of a figure can say plainly).

use plotters::coord::Shift;
use plotters::prelude::*;

use super::{register_font, tick, Drawing, PlotError, PALETTE};

/// One box: a named sample of measured values, and the group that colours it.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Sample {
    pub name: String,
    /// What the colour stands for (a policy, say); the legend lists groups in order of
    /// first appearance.
    pub group: String,
    pub values: Vec<f64>,
}

/// The five numbers a box shows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quartiles {
    pub min: f64,
    pub q1: f64,
    pub median: f64,
    pub q3: f64,
    pub max: f64,
}

impl Quartiles {
    /// The quartiles of `values` by linear interpolation between order statistics (the
    /// "type 7" rule of R and NumPy's default); `None` for an empty sample.
    pub fn of(values: &[f64]) -> Option<Quartiles> {
        if values.is_empty() {
            return None;
        }
        let mut v = values.to_vec();
        v.sort_by(f64::total_cmp);
        let at = |q: f64| {
            let pos = q * (v.len() - 1) as f64;
            let (lo, hi) = (pos.floor() as usize, pos.ceil() as usize);
            v[lo] + (v[hi] - v[lo]) * (pos - lo as f64)
        };
        Some(Quartiles {
            min: v[0],
            q1: at(0.25),
            median: at(0.5),
            q3: at(0.75),
            max: v[v.len() - 1],
        })
    }
}

/// A box plot.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BoxPlot {
    pub title: String,
    /// What the values measure, with their unit (the horizontal axis).
    pub value_label: String,
    pub boxes: Vec<Sample>,
    /// Pixels; the height grows with the number of boxes.
    pub size: (u32, u32),
}

impl BoxPlot {
    /// A plot 900 pixels wide and tall enough for every box.
    pub fn new(title: &str, value_label: &str, boxes: Vec<Sample>) -> BoxPlot {
        let height = 140 + 22 * boxes.len() as u32;
        BoxPlot {
            title: title.into(),
            value_label: value_label.into(),
            boxes,
            size: (900, height.max(260)),
        }
    }

    /// The groups in order of first appearance.
    pub fn groups(&self) -> Vec<&str> {
        let mut out: Vec<&str> = Vec::new();
        for b in &self.boxes {
            if !out.contains(&b.group.as_str()) {
                out.push(&b.group);
            }
        }
        out
    }

    /// The plot as an SVG document.
    pub fn svg(&self) -> Result<String, PlotError> {
        super::svg_of(self)
    }

    /// The plot as an RGB image.
    pub fn png(&self) -> Result<image::RgbImage, PlotError> {
        super::png_of(self)
    }

    /// Writes the plot to `path`, as SVG or PNG by its extension.
    pub fn write(&self, path: &std::path::Path) -> Result<(), PlotError> {
        super::write_of(self, path)
    }

    fn range(&self) -> Result<std::ops::Range<f64>, PlotError> {
        let mut lo = f64::MAX;
        let mut hi = f64::MIN;
        for b in &self.boxes {
            for &v in &b.values {
                if !v.is_finite() {
                    return Err(PlotError::NotFinite {
                        title: self.title.clone(),
                        series: b.name.clone(),
                        value: v,
                    });
                }
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
        if lo > hi {
            return Err(PlotError::Empty(self.title.clone()));
        }
        let span = if hi > lo { hi - lo } else { lo.abs().max(1.0) };
        let lo = if lo >= 0.0 { 0.0 } else { lo - span * 0.04 };
        Ok(lo..hi + span * 0.04)
    }
}

impl Drawing for BoxPlot {
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
        register_font();
        let xr = self.range()?;
        let n = self.boxes.len();
        let err = |e: DrawingAreaErrorKind<DB::ErrorType>| super::draw_error(self, e);
        root.fill(&WHITE).map_err(err)?;
        let groups = self.groups();
        let name_width = 16 + 8 * self.boxes.iter().map(|b| b.name.len()).max().unwrap_or(0);
        let legend_width = 40 + 8 * groups.iter().map(|g| g.len()).max().unwrap_or(0) as u32;
        let mut chart = ChartBuilder::on(root)
            .caption(&self.title, ("sans-serif", 22))
            .margin(12)
            .margin_right(12 + legend_width)
            .x_label_area_size(44)
            .y_label_area_size(name_width as u32)
            .build_cartesian_2d(xr, -0.5..(n as f64 - 0.5))
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc(&self.value_label)
            .disable_y_mesh()
            .y_labels(0)
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 16))
            .light_line_style(RGBColor(235, 235, 235))
            .x_label_formatter(&|x| tick(*x))
            .draw()
            .map_err(err)?;
        // Row i from the top: y = n - 1 - i.
        for (i, b) in self.boxes.iter().enumerate() {
            let Some(q) = Quartiles::of(&b.values) else {
                continue;
            };
            let g = groups.iter().position(|&g| g == b.group).unwrap_or(0);
            let color = PALETTE[g % PALETTE.len()];
            let y = (n - 1 - i) as f64;
            let line = ShapeStyle::from(&color).stroke_width(2);
            let light = ShapeStyle::from(&color.mix(0.3)).filled();
            let h = 0.3;
            chart
                .draw_series([
                    Rectangle::new([(q.q1, y - h), (q.q3, y + h)], light),
                    Rectangle::new([(q.q1, y - h), (q.q3, y + h)], line),
                ])
                .map_err(err)?;
            chart
                .draw_series([
                    PathElement::new(vec![(q.min, y), (q.q1, y)], line),
                    PathElement::new(vec![(q.q3, y), (q.max, y)], line),
                    PathElement::new(vec![(q.min, y - h / 2.0), (q.min, y + h / 2.0)], line),
                    PathElement::new(vec![(q.max, y - h / 2.0), (q.max, y + h / 2.0)], line),
                    // The median in the group's colour, thick: a box of equal values is
                    // only this bar, and it still shows its group.
                    PathElement::new(
                        vec![(q.median, y - h), (q.median, y + h)],
                        ShapeStyle::from(&color).stroke_width(4),
                    ),
                ])
                .map_err(err)?;
            // The name, right-aligned against the plotting area, once per run of boxes of
            // one name (a name's boxes sit together, one per group); a thin rule above
            // each new name.
            if i > 0 && self.boxes[i - 1].name == b.name {
                continue;
            }
            if i > 0 {
                let (x0, x1) = (chart.x_range().start, chart.x_range().end);
                chart
                    .draw_series([PathElement::new(
                        vec![(x0, y + 0.5), (x1, y + 0.5)],
                        ShapeStyle::from(&RGBColor(190, 190, 190)).stroke_width(1),
                    )])
                    .map_err(err)?;
            }
            let (px, py) = chart.backend_coord(&(chart.x_range().start, y));
            let label = TextStyle::from(("sans-serif", 14).into_font()).pos(
                plotters::style::text_anchor::Pos::new(
                    plotters::style::text_anchor::HPos::Right,
                    plotters::style::text_anchor::VPos::Center,
                ),
            );
            root.draw(&Text::new(b.name.clone(), (px - 8, py), label))
                .map_err(err)?;
        }
        // The legend: one swatch per group.
        let (right, top) = {
            let (range_x, range_y) = chart.plotting_area().get_pixel_range();
            (range_x.end + 14, range_y.start + 4)
        };
        for (g, name) in groups.iter().enumerate() {
            let color = PALETTE[g % PALETTE.len()];
            let y = top + 22 * g as i32;
            root.draw(&Rectangle::new(
                [(right, y - 6), (right + 24, y + 6)],
                ShapeStyle::from(&color.mix(0.3)).filled(),
            ))
            .map_err(err)?;
            root.draw(&Rectangle::new(
                [(right, y - 6), (right + 24, y + 6)],
                ShapeStyle::from(&color).stroke_width(2),
            ))
            .map_err(err)?;
            root.draw(&Text::new(
                name.to_string(),
                (right + 32, y - 8),
                ("sans-serif", 14).into_font(),
            ))
            .map_err(err)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quartiles_interpolate_between_order_statistics() {
        let q = Quartiles::of(&[4.0, 1.0, 3.0, 2.0, 5.0]).unwrap();
        assert_eq!(
            (q.min, q.q1, q.median, q.q3, q.max),
            (1.0, 2.0, 3.0, 4.0, 5.0)
        );
        let q = Quartiles::of(&[0.0, 1.0]).unwrap();
        assert_eq!((q.q1, q.median, q.q3), (0.25, 0.5, 0.75));
        assert!(Quartiles::of(&[]).is_none());
    }

    #[test]
    fn the_box_plot_names_every_box_and_group() {
        let p = BoxPlot::new(
            "EPR per run",
            "error pixel rate",
            vec![
                Sample {
                    name: "kb-rmw".into(),
                    group: "random".into(),
                    values: vec![0.1, 0.2, 0.4],
                },
                Sample {
                    name: "kb-rmw ".into(),
                    group: "pct:3".into(),
                    values: vec![0.3, 0.5, 0.9],
                },
            ],
        );
        let svg = p.svg().unwrap();
        for t in [
            "EPR per run",
            "error pixel rate",
            "kb-rmw",
            "random",
            "pct:3",
        ] {
            assert!(svg.contains(t), "{t} missing");
        }
        let img = p.png().unwrap();
        let blue = PALETTE[0];
        assert!(img.pixels().any(|px| px.0 == [blue.0, blue.1, blue.2]));
        assert!(matches!(
            BoxPlot::new("e", "v", vec![]).svg(),
            Err(PlotError::Empty(_))
        ));
    }
}
