//! An adaptive campaign's figures besides its estimate: what its stages
//! did, on one axis of every test it ran (library, search and estimation
//! tests alike), so a reader sees where the tests went and what they found.
//!
//! - [`stages_svg`]: each stage a bar over its tests `[start, end)`,
//!   coloured by kind, as high as the events its tests met; outlined, the
//!   scenarios it found failing for the first time; a strip along the axis
//!   shows every stage, even one that met nothing.
//! - [`support_svg`]: the support `K` the estimation samples (failures
//!   found and library cells untested) after each stage, and the failing
//!   scenarios found so far.

use crate::axis::linear_top;
use crate::campaign::{draw_with, fail, vehicle, FigureError};
use crate::legend::{corner, share, Stretch};
use crate::style::{count, ESTIMATE, ESTIMATE_STAGE, LIBRARY_STAGE, SEARCH_STAGE};
use plotters::prelude::*;
use tslg_api::{AdaptiveStage, CampaignView};

/// The kinds of stage, their colours and their names in a legend.
const KINDS: [(&str, RGBColor, &str); 3] = [
    ("library", LIBRARY_STAGE, "library stage"),
    ("search", SEARCH_STAGE, "search"),
    ("estimate", ESTIMATE_STAGE, "estimation"),
];

/// `[0, last stage's end]`, at least one test wide.
fn test_axis(stages: &[AdaptiveStage]) -> (f64, f64) {
    let end = stages.iter().map(|s| s.end).max().unwrap_or(0);
    (0.0, end.max(1) as f64)
}

/// Tests of each kind, for a title: "100 library, 604 search, 30 estimation tests".
fn spent(stages: &[AdaptiveStage]) -> String {
    let of = |kind: &str| -> u64 {
        stages
            .iter()
            .filter(|s| s.kind == kind)
            .map(|s| s.end - s.start)
            .sum()
    };
    format!(
        "{} library, {} search, {} estimation tests",
        of("library"),
        of("search"),
        of("estimate")
    )
}

/// The stages on one axis of all tests, each as high as its events.
pub fn stages_svg(view: &CampaignView, stages: &[AdaptiveStage]) -> Result<String, FigureError> {
    let (x0, x1) = test_axis(stages);
    let top = linear_top(stages.iter().map(|s| s.events as f64), 1.45).max(1.0);
    let strip = top / 40.0;
    let data: Vec<Stretch> = stages
        .iter()
        .flat_map(|s| {
            let high = share(s.events as f64 + strip, (0.0, top), false);
            [s.start, s.end].map(|x| Stretch {
                x: share(x as f64, (x0, x1), false),
                low: 0.0,
                high,
            })
        })
        .collect();
    let title = format!(
        "Campaign {}, {}: stages ({})",
        view.id,
        vehicle(view),
        spent(stages)
    );
    draw_with(
        &title,
        (x0..x1, "tests run (every stage)"),
        0.0..top,
        (0.0, top),
        "events in the stage",
        corner(&data, KINDS.len() + 1),
        |chart| {
            for (kind, colour, name) in KINDS {
                let of_kind: Vec<&AdaptiveStage> =
                    stages.iter().filter(|s| s.kind == kind).collect();
                let bars = of_kind.iter().flat_map(|s| {
                    let (a, b) = (s.start as f64, s.end as f64);
                    let strip = Rectangle::new([(a, 0.0), (b, strip)], colour.filled());
                    let bar = (s.events > 0).then(|| {
                        Rectangle::new([(a, 0.0), (b, s.events as f64)], colour.mix(0.75).filled())
                    });
                    std::iter::once(strip).chain(bar)
                });
                let series = chart.draw_series(bars).map_err(fail)?;
                if !of_kind.is_empty() {
                    series.label(name).legend(move |(x, y)| {
                        Rectangle::new([(x, y - 5), (x + 18, y + 5)], colour.filled())
                    });
                }
            }
            chart
                .draw_series(stages.iter().filter(|s| s.new_failures > 0).map(|s| {
                    Rectangle::new(
                        [(s.start as f64, 0.0), (s.end as f64, s.new_failures as f64)],
                        BLACK.stroke_width(1),
                    )
                }))
                .map_err(fail)?
                .label("scenarios found failing")
                .legend(|(x, y)| {
                    Rectangle::new([(x, y - 5), (x + 18, y + 5)], BLACK.stroke_width(1))
                });
            Ok(())
        },
    )
}

/// The support after each stage and the failing scenarios found so far,
/// as steps against all tests.
pub fn support_svg(view: &CampaignView, stages: &[AdaptiveStage]) -> Result<String, FigureError> {
    let (x0, x1) = test_axis(stages);
    let support = steps(stages.iter().map(|s| (s.end, s.support as f64)));
    let mut found = 0.0;
    let failures = steps(stages.iter().map(|s| {
        found += s.new_failures as f64;
        (s.end, found)
    }));
    let top = linear_top(support.iter().chain(&failures).map(|p| p.1), 1.45).max(1.0);
    let data: Vec<Stretch> = support
        .iter()
        .chain(&failures)
        .map(|&(x, y)| Stretch {
            x: share(x, (x0, x1), false),
            low: share(y, (0.0, top), false),
            high: share(y, (0.0, top), false),
        })
        .collect();
    let title = format!(
        "Campaign {}, {}: support after each stage ({} cells)",
        view.id,
        vehicle(view),
        count(stages.last().map_or(0.0, |s| s.support as f64))
    );
    draw_with(
        &title,
        (x0..x1, "tests run (every stage)"),
        0.0..top,
        (0.0, top),
        "scenarios",
        corner(&data, 2),
        |chart| {
            chart
                .draw_series(LineSeries::new(support.clone(), ESTIMATE.stroke_width(2)))
                .map_err(fail)?
                .label("support K: failures found and library cells untested")
                .legend(|(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], ESTIMATE.stroke_width(2))
                });
            chart
                .draw_series(LineSeries::new(
                    failures.clone(),
                    SEARCH_STAGE.stroke_width(2),
                ))
                .map_err(fail)?
                .label("scenarios found failing")
                .legend(|(x, y)| {
                    PathElement::new(vec![(x, y), (x + 18, y)], SEARCH_STAGE.stroke_width(2))
                });
            Ok(())
        },
    )
}

/// A step line through `(end of stage, value after it)`: each value held
/// until the next stage's end.
fn steps(points: impl Iterator<Item = (u64, f64)>) -> Vec<(f64, f64)> {
    let mut line: Vec<(f64, f64)> = Vec::new();
    for (x, y) in points {
        if let Some(&(_, held)) = line.last() {
            line.push((x as f64, held));
        }
        line.push((x as f64, y));
    }
    line
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_support_is_held_until_the_next_stage_ends() {
        let line = steps([(100, 5.0), (300, 9.0), (330, 9.0)].into_iter());
        assert_eq!(
            line,
            [
                (100.0, 5.0),
                (300.0, 5.0),
                (300.0, 9.0),
                (330.0, 9.0),
                (330.0, 9.0)
            ]
        );
    }
}
