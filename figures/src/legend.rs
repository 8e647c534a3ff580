//! Where a plot's legend goes: the corner of the plotting area its data
//! cover least. A legend fixed in the upper right covered the interval band
//! of every campaign whose estimate settles high (the band is widest where
//! the tests are most, on the right of a log axis).

use plotters::chart::SeriesLabelPosition;

/// A vertical stretch of data at `x`, from `low` to `high`, in the plotting
/// area's own coordinates: each in `[0, 1]`, 0 at the left and bottom. A
/// line's point is a stretch of no height; an interval band's column a
/// stretch from its lower to its upper end.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stretch {
    pub x: f64,
    pub low: f64,
    pub high: f64,
}

/// The share of the plotting area's width a legend takes (its text beside
/// the keys), and of its height per entry and for its padding.
const LEGEND_WIDTH: f64 = 0.5;
const LEGEND_LINE: f64 = 0.06;
const LEGEND_PADDING: f64 = 0.06;

/// The corner whose box for a legend of `entries` lines the fewest
/// stretches enter; ties go in the order upper right, upper left, lower
/// right, lower left (the upper right is where readers look for a legend).
pub fn corner(data: &[Stretch], entries: usize) -> SeriesLabelPosition {
    let (w, h) = (LEGEND_WIDTH, LEGEND_PADDING + LEGEND_LINE * entries as f64);
    let corners = [
        (
            SeriesLabelPosition::UpperRight,
            (1.0 - w, 1.0),
            (1.0 - h, 1.0),
        ),
        (SeriesLabelPosition::UpperLeft, (0.0, w), (1.0 - h, 1.0)),
        (SeriesLabelPosition::LowerRight, (1.0 - w, 1.0), (0.0, h)),
        (SeriesLabelPosition::LowerLeft, (0.0, w), (0.0, h)),
    ];
    let covered = |(x0, x1): (f64, f64), (y0, y1): (f64, f64)| {
        data.iter()
            .filter(|s| s.x.is_finite() && (x0..=x1).contains(&s.x))
            .filter(|s| s.low <= y1 && s.high >= y0)
            .count()
    };
    corners
        .into_iter()
        .min_by_key(|&(_, xs, ys)| covered(xs, ys))
        .map(|(position, _, _)| position)
        .unwrap_or(SeriesLabelPosition::UpperRight)
}

/// `v` on an axis from `a` to `b` as a share of it, on a log axis when
/// `log`; clamped to `[0, 1]`, NaN for a value with no place on it.
pub fn share(v: f64, (a, b): (f64, f64), log: bool) -> f64 {
    let t = if log {
        if v <= 0.0 {
            return f64::NAN;
        }
        (v.ln() - a.ln()) / (b.ln() - a.ln())
    } else {
        (v - a) / (b - a)
    };
    t.clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn band(x: f64, low: f64, high: f64) -> Stretch {
        Stretch { x, low, high }
    }

    #[test]
    fn the_legend_goes_where_the_data_are_not() {
        // A band filling the right half from 0.1 to 1 (the campaign of the
        // dashboard screenshot): the upper right is taken.
        let right: Vec<Stretch> = (50..=100)
            .map(|k| band(k as f64 / 100.0, 0.1, 1.0))
            .collect();
        assert_eq!(corner(&right, 4), SeriesLabelPosition::UpperLeft);
        // A relative half-width falling from the upper left to the lower
        // right leaves the upper right free.
        let falling: Vec<Stretch> = (0..=100)
            .map(|k| {
                let t = k as f64 / 100.0;
                band(t, 1.0 - t, 1.0 - t)
            })
            .collect();
        assert_eq!(corner(&falling, 2), SeriesLabelPosition::UpperRight);
        // Nothing drawn: the upper right.
        assert_eq!(corner(&[], 2), SeriesLabelPosition::UpperRight);
        // Data everywhere but the lower left.
        let mut most = right.clone();
        most.extend((0..50).map(|k| band(k as f64 / 100.0, 0.5, 1.0)));
        assert_eq!(corner(&most, 4), SeriesLabelPosition::LowerLeft);
    }

    #[test]
    fn shares_of_an_axis_are_clamped_and_log_where_asked() {
        assert_eq!(share(5.0, (0.0, 10.0), false), 0.5);
        assert_eq!(share(20.0, (0.0, 10.0), false), 1.0);
        assert!((share(10.0, (1.0, 100.0), true) - 0.5).abs() < 1e-12);
        assert!(share(0.0, (1.0, 100.0), true).is_nan());
    }
}
