//! Axis ranges every plot can draw, whatever numbers it is given.
//!
//! plotters computes a log axis's ticks by walking its decades, so a range
//! that reaches zero, a subnormal, an infinity or a NaN (a campaign stored
//! with β = 10⁻³¹⁰ gave a lower end of 0) makes it walk forever. Every range
//! handed to plotters comes from here: finite, positive where it must be,
//! of non-zero width, and at most [`MAX_DECADES`] decades wide on a log axis.

/// The widest log axis, in decades: twelve orders of magnitude show any
/// campaign's relative half-width (it falls as 1/√n) with room to spare.
pub const MAX_DECADES: f64 = 12.0;
/// The smallest and largest values a log axis shows.
const LOG_FLOOR: f64 = 1e-300;
const LOG_CEILING: f64 = 1e300;
/// The top of a linear axis from 0 when nothing positive is given.
const LINEAR_FALLBACK: f64 = 1e-6;

/// A log axis `[low, high]` covering the usable `values` (finite, > 0),
/// widened by `margin` (≥ 1) at both ends; `[fallback/10, fallback·10]`
/// when there is none. The result is always normal, positive, of non-zero
/// width, and at most [`MAX_DECADES`] decades wide, keeping the high end.
pub fn log_range(values: impl IntoIterator<Item = f64>, margin: f64, fallback: f64) -> (f64, f64) {
    let usable = |v: &f64| v.is_finite() && *v >= LOG_FLOOR && *v <= LOG_CEILING;
    let (mut low, mut high) = values
        .into_iter()
        .filter(usable)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if low > high {
        let center = if usable(&fallback) { fallback } else { 1.0 };
        (low, high) = (center, center);
    }
    let margin = if margin.is_finite() && margin >= 1.0 {
        margin
    } else {
        1.0
    };
    low = (low / margin).max(LOG_FLOOR);
    high = (high * margin).min(LOG_CEILING);
    if high / low < 2.0 {
        // One point, or a range too narrow for a tick: a decade around it.
        let center = (low * high).sqrt();
        (low, high) = (
            (center / 10.0).max(LOG_FLOOR),
            (center * 10.0).min(LOG_CEILING),
        );
    }
    let widest = 10f64.powf(MAX_DECADES);
    if high / low > widest {
        low = high / widest;
    }
    (low, high)
}

/// The labelled ticks of a log axis `[low, high]`: the powers of ten in it
/// when there are at least three, else 1, 2 and 5 times them, else every
/// multiple 1…9 of them. plotters labels powers of ten only, so a relative
/// half-width falling from 0.3 to β = 0.05 had the single tick 0.1.
pub fn log_ticks(low: f64, high: f64) -> Vec<f64> {
    let within = |v: &f64| *v >= low * (1.0 - 1e-9) && *v <= high * (1.0 + 1e-9);
    if !(low > 0.0 && high >= low && low.is_finite() && high.is_finite()) {
        return Vec::new();
    }
    let first = low.log10().floor() as i32;
    let last = high.log10().ceil() as i32;
    let multiples = |steps: &[f64]| -> Vec<f64> {
        (first..=last)
            .flat_map(|e| {
                // Divide for negative exponents: 3 / 10 is 0.3, 3 · 0.1 is not.
                let scale = 10f64.powi(e.abs());
                steps
                    .iter()
                    .map(move |s| if e >= 0 { s * scale } else { s / scale })
            })
            .filter(within)
            .collect()
    };
    for steps in [
        &[1.0][..],
        &[1.0, 2.0, 5.0],
        &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0],
    ] {
        let ticks = multiples(steps);
        if ticks.len() >= 3 {
            return ticks;
        }
    }
    multiples(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0])
}

/// The top of a linear axis from 0 that shows every usable (finite, ≥ 0)
/// value with `headroom` (e.g. 1.15) above the largest.
pub fn linear_top(values: impl IntoIterator<Item = f64>, headroom: f64) -> f64 {
    let top = values
        .into_iter()
        .filter(|v| v.is_finite() && *v >= 0.0)
        .fold(0.0f64, f64::max);
    let top = top
        * if headroom.is_finite() && headroom >= 1.0 {
            headroom
        } else {
            1.0
        };
    if top.is_finite() && top >= f64::MIN_POSITIVE * 1e10 {
        top
    } else {
        LINEAR_FALLBACK
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_axes_get_at_least_three_ticks() {
        assert_eq!(log_ticks(1e-3, 2.0), [1e-3, 1e-2, 1e-1, 1.0]);
        assert_eq!(log_ticks(0.033, 0.45), [0.05, 0.1, 0.2]);
        assert_eq!(log_ticks(0.12, 0.35), [0.2, 0.3]);
        assert_eq!(log_ticks(0.0, 1.0), Vec::<f64>::new());
        // Every log range the figures draw (at least a factor 2 wide).
        for (low, high) in [(0.1, 0.2), (0.33, 0.99), (7e-5, 1.4e-4), (1e-300, 1e-298)] {
            let ticks = log_ticks(low, high);
            assert!(ticks.len() >= 2, "{low}..{high}: {ticks:?}");
            assert!(ticks
                .iter()
                .all(|t| (low * 0.999..=high * 1.001).contains(t)));
        }
    }

    fn drawable(range: (f64, f64)) -> bool {
        let (lo, hi) = range;
        lo.is_normal()
            && hi.is_normal()
            && lo > 0.0
            && hi / lo >= 2.0
            && hi / lo <= 10f64.powf(MAX_DECADES) * (1.0 + 1e-9)
    }

    #[test]
    fn degenerate_inputs_give_drawable_log_axes() {
        let nasty = [
            vec![],
            vec![1e-310],
            vec![0.0, -1.0, f64::NAN, f64::INFINITY],
            vec![1e-310, 0.2],
            vec![5.0],
            vec![f64::MIN_POSITIVE, f64::MAX],
            vec![0.2, 0.2, 0.2],
        ];
        for values in nasty {
            for fallback in [0.2, 1e-310, f64::NAN, 0.0] {
                let r = log_range(values.iter().copied(), 1.5, fallback);
                assert!(drawable(r), "{values:?} {fallback} → {r:?}");
            }
        }
        // Ordinary values are kept, with the margin.
        let (lo, hi) = log_range([0.05, 0.2, 1.3], 1.5, 0.2);
        assert!((lo - 0.05 / 1.5).abs() < 1e-15 && (hi - 1.95).abs() < 1e-12);
        // A span of 30 decades keeps the top 12.
        let (lo, hi) = log_range([1e-20, 1e10], 1.0, 1.0);
        assert_eq!(hi, 1e10);
        assert!((lo / 1e-2 - 1.0).abs() < 1e-9);
    }

    #[test]
    fn linear_tops_are_positive_and_finite() {
        assert_eq!(linear_top([], 1.15), LINEAR_FALLBACK);
        assert_eq!(
            linear_top([f64::NAN, f64::INFINITY, -3.0, 1e-320], 1.15),
            LINEAR_FALLBACK
        );
        assert!((linear_top([1e-3, 2e-3], 1.15) - 2.3e-3).abs() < 1e-15);
        assert_eq!(linear_top([f64::MAX], 1.15), LINEAR_FALLBACK);
    }
}
