//! Values over a two-dimensional grid as coloured cells on a log colour
//! scale (probabilities span many orders of magnitude), with the scale
//! beside each map (a colour bar); cells at 0 stay white. Several maps side
//! by side share nothing but the title.

use crate::campaign::{fail, FigureError};
use crate::style::{number, FONT};
use plotters::prelude::*;

/// One axis of a map: its name and the cell centres, ascending.
#[derive(Debug, Clone)]
pub struct HeatmapAxis {
    /// The axis title, with its unit.
    pub label: String,
    /// The cell centres, ascending.
    pub centres: Vec<f64>,
}

/// `values[i * y.centres.len() + j]` is the value at `(x[i], y[j])`.
#[derive(Debug, Clone)]
pub struct Heatmap {
    /// The figure's title.
    pub title: String,
    /// The horizontal axis.
    pub x: HeatmapAxis,
    /// The vertical axis.
    pub y: HeatmapAxis,
    /// The values, `x.centres.len() × y.centres.len()` of them.
    pub values: Vec<f64>,
}

impl HeatmapAxis {
    /// The extent of cell `k`: halfway to its neighbours.
    fn cell(&self, k: usize) -> (f64, f64) {
        let c = &self.centres;
        let step = |a: usize, b: usize| (c[b] - c[a]).abs();
        let below = if k > 0 {
            step(k - 1, k)
        } else if c.len() > 1 {
            step(0, 1)
        } else {
            1.0
        };
        let above = if k + 1 < c.len() {
            step(k, k + 1)
        } else {
            below
        };
        (c[k] - below / 2.0, c[k] + above / 2.0)
    }

    fn range(&self) -> std::ops::Range<f64> {
        self.cell(0).0..self.cell(self.centres.len() - 1).1
    }
}

/// Steps of a colour bar.
pub const COLOUR_STEPS: usize = 48;

/// A colour on a white → blue → dark red ramp for `t ∈ [0, 1]`.
fn ramp(t: f64) -> RGBColor {
    let stops = [
        (255.0, 255.0, 204.0),
        (65.0, 182.0, 196.0),
        (37.0, 52.0, 148.0),
        (128.0, 0.0, 38.0),
    ];
    let t = t.clamp(0.0, 1.0) * (stops.len() - 1) as f64;
    let k = (t.floor() as usize).min(stops.len() - 2);
    let f = t - k as f64;
    let mix = |a: f64, b: f64| (a + (b - a) * f).round() as u8;
    let (a, b) = (stops[k], stops[k + 1]);
    RGBColor(mix(a.0, b.0), mix(a.1, b.1), mix(a.2, b.2))
}

/// The maps side by side under `title`.
pub fn heatmaps_svg(title: &str, maps: &[Heatmap]) -> Result<String, FigureError> {
    if maps.is_empty() {
        return Err(FigureError("no map to draw".into()));
    }
    for map in maps {
        if map.x.centres.is_empty()
            || map.y.centres.is_empty()
            || map.values.len() != map.x.centres.len() * map.y.centres.len()
        {
            return Err(FigureError(format!(
                "map `{}` has {} values for a {} × {} grid",
                map.title,
                map.values.len(),
                map.x.centres.len(),
                map.y.centres.len()
            )));
        }
    }
    let mut svg = String::new();
    {
        let size = (520 * maps.len() as u32, 460);
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        root.fill(&WHITE).map_err(fail)?;
        let root = root.titled(title, (FONT, 18)).map_err(fail)?;
        for (area, map) in root.split_evenly((1, maps.len())).iter().zip(maps) {
            draw_map(area, map)?;
        }
        root.present().map_err(fail)?;
    }
    Ok(svg)
}

fn draw_map(
    area: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    map: &Heatmap,
) -> Result<(), FigureError> {
    let positive = map.values.iter().copied().filter(|v| *v > 0.0);
    let low = positive.clone().fold(f64::INFINITY, f64::min);
    let high = positive.fold(0.0f64, f64::max);
    let caption = if high > 0.0 {
        format!(
            "{} (log colour {} … {})",
            map.title,
            number(low),
            number(high)
        )
    } else {
        format!("{} (all 0)", map.title)
    };
    let width = area.dim_in_pixel().0;
    // The bar's labels (`7.31e-10`, 11 px) need about 50 px beside it: a
    // 46 px label area let the longer ones run into the bar.
    let (area, bar) = area.split_horizontally(width * 80 / 100);
    if high > 0.0 {
        colour_bar(&bar, low, high)?;
    }
    let mut chart = ChartBuilder::on(&area)
        .caption(caption, (FONT, 13))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(52)
        .build_cartesian_2d(map.x.range(), map.y.range())
        .map_err(fail)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc(map.x.label.as_str())
        .y_desc(map.y.label.as_str())
        .x_label_formatter(&|v| number(*v))
        .y_label_formatter(&|v| number(*v))
        .label_style((FONT, 12))
        .draw()
        .map_err(fail)?;
    let span = (high / low).ln();
    let ny = map.y.centres.len();
    let cells = map
        .values
        .iter()
        .enumerate()
        .filter(|(_, v)| **v > 0.0)
        .map(|(k, &v)| {
            let (x0, x1) = map.x.cell(k / ny);
            let (y0, y1) = map.y.cell(k % ny);
            let t = if span > 0.0 {
                (v / low).ln() / span
            } else {
                1.0
            };
            Rectangle::new([(x0, y0), (x1, y1)], ramp(t).filled())
        });
    chart.draw_series(cells).map_err(fail)?;
    Ok(())
}

/// The colour scale of a map whose positive values run from `low` to
/// `high`: the ramp bottom to top with the values it stands for (log
/// scale) as ticks.
fn colour_bar(
    area: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    low: f64,
    high: f64,
) -> Result<(), FigureError> {
    let span = (high / low).ln();
    let value = |t: f64| low * (t * span).exp();
    let mut chart = ChartBuilder::on(area)
        .margin_top(40)
        .margin_bottom(50)
        .margin_right(6)
        .y_label_area_size(64)
        .build_cartesian_2d(0.0..1.0, 0.0..1.0)
        .map_err(fail)?;
    let labels = if span > 0.0 { 5 } else { 1 };
    chart
        .configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_labels(labels)
        .y_label_formatter(&|t| number(value(*t)))
        .label_style((FONT, 11))
        .draw()
        .map_err(fail)?;
    let step = 1.0 / COLOUR_STEPS as f64;
    chart
        .draw_series((0..COLOUR_STEPS).map(|k| {
            let t = k as f64 * step;
            Rectangle::new([(0.0, t), (1.0, t + step)], ramp(t + step / 2.0).filled())
        }))
        .map_err(fail)?;
    Ok(())
}
