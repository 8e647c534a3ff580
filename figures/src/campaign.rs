//! A campaign's figures: the estimate `μ̂ₙ` with its interval band and the
//! relative half-width `z·σ̂ₙ/(√n·μ̂ₙ)` with the β line, both against the
//! number of valid tests `n` on a log axis, as in the paper's result figures.
//! Points with `n = 0` have no place on a log axis and are left out.

use crate::axis::{linear_top, log_range, log_ticks, MAX_DECADES};
use crate::legend::{corner, share, Stretch};
use crate::style::{axis_format, count, number, BAND, ESTIMATE, FONT, GUARD, LIMIT, SIZE};
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::prelude::*;
use std::fmt::Write;
use tslg_api::{CampaignView, HistoryPoint};

/// Why a figure could not be drawn (it is drawn into a string, so this is
/// a bug in the figure, not an I/O error).
#[derive(Debug, thiserror::Error)]
#[error("cannot draw the figure: {0}")]
pub struct FigureError(pub String);

pub(crate) fn fail(e: impl std::fmt::Display) -> FigureError {
    FigureError(e.to_string())
}

/// The campaign's vehicle as its title names it: the coordinator's
/// `vut_label`, or (from a coordinator before it) the model or program.
pub(crate) fn vehicle(view: &CampaignView) -> String {
    if !view.vut_label.is_empty() {
        return view.vut_label.clone();
    }
    ["model", "external"]
        .iter()
        .find_map(|key| view.vut.get(key).and_then(|v| v.as_str()))
        .unwrap_or("?")
        .to_owned()
}

/// What the estimate's x axis counts: an adaptive campaign's estimate is
/// over its estimation tests alone.
fn tests_axis(view: &CampaignView) -> &'static str {
    view.method.spec().tests_axis
}

/// The points that have a place on a log axis of tests.
fn plotted(points: &[HistoryPoint]) -> impl DoubleEndedIterator<Item = &HistoryPoint> {
    points.iter().filter(|p| p.tests > 0)
}

/// `[first, last]` tests (at least a factor 2 apart, widened around a
/// single point), drawable whatever the points say.
fn test_range(points: &[HistoryPoint]) -> (f64, f64) {
    log_range(plotted(points).map(|p| p.tests as f64), 1.0, 1.0)
}

/// The estimate with its interval band against tests, the exact `P(A)` as
/// a dashed line where the campaign knows it, and for a library campaign
/// the guarded interval's upper end now (the bound that does not assume
/// the library covers the vehicle's failures) as a dotted line. The y
/// axis runs from 0 to a little above the largest estimate, the last
/// interval's upper end and the exact value; the band is clipped to it
/// (early intervals are wide). A guarded end more than three times that
/// top would flatten everything else: it is drawn at the top, its value
/// in the legend marked "above".
pub fn estimate_svg(view: &CampaignView, points: &[HistoryPoint]) -> Result<String, FigureError> {
    let (x0, x1) = test_range(points);
    let exact = view
        .exact_probability
        .filter(|p| p.is_finite() && *p >= 0.0);
    let top = linear_top(
        plotted(points)
            .map(|p| p.estimate)
            .chain(plotted(points).last().map(|p| p.ci_high))
            .chain(exact),
        // Room above the data for the legend (`legend::corner`).
        1.45,
    );
    let guarded = view
        .guarded_ci_high
        .filter(|g| g.is_finite() && *g >= 0.0 && plotted(points).next().is_some());
    let y1 = match guarded {
        Some(g) if g <= 3.0 * top => top.max(g * 1.05),
        _ => top,
    };
    let clip = |y: f64| if y.is_nan() { 0.0 } else { y.clamp(0.0, y1) };
    let mut band: Vec<(f64, f64)> = plotted(points)
        .map(|p| (p.tests as f64, clip(p.ci_high)))
        .collect();
    band.extend(
        plotted(points)
            .rev()
            .map(|p| (p.tests as f64, clip(p.ci_low))),
    );
    let line: Vec<(f64, f64)> = plotted(points)
        .map(|p| (p.tests as f64, clip(p.estimate)))
        .collect();
    // What the legend must not cover: the band's columns, the estimate,
    // and the guarded and exact lines across the whole width.
    let at = |x: f64| share(x, (x0, x1), true);
    let on_y = |y: f64| share(y, (0.0, y1), false);
    let mut data: Vec<Stretch> = plotted(points)
        .map(|p| Stretch {
            x: at(p.tests as f64),
            low: on_y(clip(p.ci_low).min(clip(p.estimate))),
            high: on_y(clip(p.ci_high).max(clip(p.estimate))),
        })
        .collect();
    for level in guarded.map(|g| g.min(y1)).into_iter().chain(exact) {
        data.extend((0..=20).map(|k| Stretch {
            x: k as f64 / 20.0,
            low: on_y(level),
            high: on_y(level),
        }));
    }
    let title = format!(
        "Campaign {}, {}: estimate of P(A), {} ({} tests)",
        view.id,
        vehicle(view),
        view.status.as_str(),
        count(view.tests as f64)
    );
    draw_with(
        &title,
        ((x0..x1).log_scale(), tests_axis(view)),
        0.0..y1,
        (0.0, y1),
        "P(A)",
        corner(
            &data,
            2 + usize::from(guarded.is_some()) + usize::from(exact.is_some()),
        ),
        |chart| {
            let interval = format!("{:.0}% interval", view.confidence * 100.0);
            chart
                .draw_series(std::iter::once(Polygon::new(band, BAND.filled())))
                .map_err(fail)?
                .label(interval)
                .legend(|(x, y)| Rectangle::new([(x, y - 5), (x + 18, y + 5)], BAND.filled()));
            chart
                .draw_series(LineSeries::new(line, ESTIMATE.stroke_width(2)))
                .map_err(fail)?
                .label("estimate")
                .legend(|(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], ESTIMATE.stroke_width(2))
                });
            if let Some(g) = guarded {
                let (height, label) = if g <= y1 {
                    (g, format!("guarded upper end = {}", number(g)))
                } else {
                    (y1, format!("guarded upper end = {} (above)", number(g)))
                };
                chart
                    .draw_series(DashedLineSeries::new(
                        [(x0, height), (x1, height)],
                        2,
                        3,
                        GUARD.stroke_width(2),
                    ))
                    .map_err(fail)?
                    .label(label)
                    .legend(|(x, y)| {
                        PathElement::new(vec![(x, y), (x + 18, y)], GUARD.stroke_width(2))
                    });
            }
            if let Some(p) = exact {
                chart
                    .draw_series(DashedLineSeries::new(
                        [(x0, p), (x1, p)],
                        6,
                        4,
                        LIMIT.stroke_width(2),
                    ))
                    .map_err(fail)?
                    .label(format!("exact P(A) = {}", number(p)))
                    .legend(|(x, y)| {
                        PathElement::new(vec![(x, y), (x + 18, y)], LIMIT.stroke_width(2))
                    });
            }
            Ok(())
        },
    )
}

/// The relative half-width against tests, both on log axes, with the line
/// at β where the campaign stops.
pub fn relative_half_width_svg(
    view: &CampaignView,
    points: &[HistoryPoint],
) -> Result<String, FigureError> {
    let (x0, x1) = test_range(points);
    let line: Vec<(f64, f64)> = plotted(points)
        .filter_map(|p| p.relative_half_width.map(|r| (p.tests as f64, r)))
        .filter(|&(_, r)| r.is_finite() && r > 0.0)
        .collect();
    let (low, high) = log_range(
        line.iter().map(|&(_, r)| r).chain([view.beta]),
        1.5,
        view.beta,
    );
    // Room above the curve for the legend (`legend::corner`): the top
    // raised by a third of the axis's span.
    // The ticks are written as the data's range asks (`axis_format`).
    let data_high = high;
    let high = (high * (high / low).powf(1.0 / 3.0)).min(low * 10f64.powf(MAX_DECADES));
    let title = format!(
        "Campaign {}, {}: relative half-width, β = {}",
        view.id,
        vehicle(view),
        view.beta
    );
    let beta = view.beta;
    let on_y = |y: f64| share(y, (low, high), true);
    let mut data: Vec<Stretch> = line
        .iter()
        .map(|&(x, r)| Stretch {
            x: share(x, (x0, x1), true),
            low: on_y(r),
            high: on_y(r),
        })
        .collect();
    data.extend((0..=20).map(|k| Stretch {
        x: k as f64 / 20.0,
        low: on_y(beta),
        high: on_y(beta),
    }));
    draw_with(
        &title,
        ((x0..x1).log_scale(), tests_axis(view)),
        (low..high)
            .log_scale()
            .with_key_points(log_ticks(low, high)),
        (low, data_high),
        "relative half-width",
        corner(&data, 2),
        |chart| {
            chart
                .draw_series(DashedLineSeries::new(
                    [(x0, beta), (x1, beta)],
                    6,
                    4,
                    LIMIT.stroke_width(2),
                ))
                .map_err(fail)?
                .label(format!("β = {beta}"))
                .legend(|(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], LIMIT.stroke_width(2))
                });
            chart
                .draw_series(LineSeries::new(line, ESTIMATE.stroke_width(2)))
                .map_err(fail)?
                .label("relative half-width")
                .legend(|(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], ESTIMATE.stroke_width(2))
                });
            Ok(())
        },
    )
}

pub(crate) type Chart<'a, X, Y> = ChartContext<'a, SVGBackend<'a>, Cartesian2d<X, Y>>;

/// One plot of `title` with `x` named `x_label`, the series drawn by
/// `series`, and a legend; `y` runs from `low` to `high`, whose ticks are
/// written alike ([`axis_format`]).
pub(crate) fn draw_with<XR, YR, X, Y>(
    title: &str,
    (x, x_label): (XR, &str),
    y: YR,
    (low, high): (f64, f64),
    y_label: &str,
    legend: SeriesLabelPosition,
    series: impl for<'a> FnOnce(&mut Chart<'a, X, Y>) -> Result<(), FigureError>,
) -> Result<String, FigureError>
where
    XR: AsRangedCoord<CoordDescType = X, Value = f64>,
    YR: AsRangedCoord<CoordDescType = Y, Value = f64>,
    X: Ranged<ValueType = f64> + ValueFormatter<f64>,
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    let y_format = axis_format(low, high);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(fail)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, (FONT, 18))
            .margin(12)
            .x_label_area_size(42)
            .y_label_area_size(72)
            .build_cartesian_2d(x, y)
            .map_err(fail)?;
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .x_labels(8)
            .y_labels(8)
            .bold_line_style(BLACK.mix(0.15))
            .light_line_style(BLACK.mix(0.03))
            .x_label_formatter(&|v| count(*v))
            .y_label_formatter(&y_format)
            .label_style((FONT, 13))
            .draw()
            .map_err(fail)?;
        series(&mut chart)?;
        chart
            .configure_series_labels()
            .position(legend)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.4))
            .label_font((FONT, 13))
            .draw()
            .map_err(fail)?;
        root.present().map_err(fail)?;
    }
    Ok(svg)
}

/// The numbers behind the figures, one row per point.
pub fn history_csv(points: &[HistoryPoint]) -> String {
    let mut csv = String::from(
        "tests,indices,events,estimate,half_width,relative_half_width,ci_low,ci_high\n",
    );
    for p in points {
        let r = p
            .relative_half_width
            .map_or(String::new(), |r| r.to_string());
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{},{},{}",
            p.tests, p.indices, p.events, p.estimate, p.half_width, r, p.ci_low, p.ci_high
        );
    }
    csv
}
