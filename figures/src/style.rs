//! What every figure shares: size, fonts and how numbers are written on axes.

use plotters::style::RGBColor;

/// Width and height of one plot in pixels.
pub const SIZE: (u32, u32) = (720, 420);
pub const FONT: &str = "sans-serif";
pub const ESTIMATE: RGBColor = RGBColor(31, 93, 166);
pub const BAND: RGBColor = RGBColor(160, 196, 232);
pub const LIMIT: RGBColor = RGBColor(200, 40, 40);
/// The guarded interval's upper end.
pub const GUARD: RGBColor = RGBColor(161, 92, 0);
/// An adaptive campaign's stages: its library stage, its searches, and its
/// estimation stages (the dashboard's colours for them too).
pub const LIBRARY_STAGE: RGBColor = RGBColor(31, 93, 166);
pub const SEARCH_STAGE: RGBColor = RGBColor(214, 130, 20);
pub const ESTIMATE_STAGE: RGBColor = RGBColor(29, 122, 58);

/// A count on a log axis: `1`, `10`, `100`, `1k`, `10k`, …, `1M`, …
pub fn count(value: f64) -> String {
    let v = value.round();
    let (scaled, suffix) = if v >= 1e9 {
        (v / 1e9, "G")
    } else if v >= 1e6 {
        (v / 1e6, "M")
    } else if v >= 1e3 {
        (v / 1e3, "k")
    } else {
        (v, "")
    };
    if (scaled - scaled.round()).abs() < 1e-9 {
        format!("{}{suffix}", scaled.round())
    } else {
        format!("{scaled:.1}{suffix}")
    }
}

/// How the ticks of an axis running from `low` to `high` are written, all
/// alike: fixed decimals enough for its scale when the axis stays within
/// `[0.01, 1000)` and within two decades of its top (0.0050, 0.0100,
/// 0.0150), else three significant digits in scientific notation
/// (5.00e-3, 1.00e-2). One format per axis:
/// `number` alone would write 5.00e-3 beside 0.015 on the same axis.
pub fn axis_format(low: f64, high: f64) -> impl Fn(&f64) -> String {
    let top = low.abs().max(high.abs());
    let bottom = low.abs().min(high.abs());
    // A log axis reaching two decades below its top needs the exponent.
    let fixed = (1e-2..1e3).contains(&top) && (bottom == 0.0 || bottom >= top / 100.0);
    let decimals = if fixed {
        (2.0 - top.log10().floor()).clamp(0.0, 6.0) as usize
    } else {
        0
    };
    move |v: &f64| {
        if *v == 0.0 {
            "0".into()
        } else if fixed {
            format!("{v:.decimals$}")
        } else {
            format!("{v:.2e}")
        }
    }
}

/// A small probability or ratio: three significant digits.
pub fn number(value: f64) -> String {
    if value == 0.0 {
        "0".into()
    } else if (1e-2..1e3).contains(&value.abs()) {
        format!("{}", (value * 1e3).round() / 1e3)
    } else {
        format!("{value:.2e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_numbers_are_short() {
        assert_eq!(count(1.0), "1");
        assert_eq!(count(1000.0), "1k");
        assert_eq!(count(2500.0), "2.5k");
        assert_eq!(count(1e7), "10M");
        assert_eq!(number(0.2), "0.2");
        assert_eq!(number(1.23e-4), "1.23e-4");
        assert_eq!(number(0.0), "0");
    }

    #[test]
    fn an_axis_writes_its_ticks_alike() {
        let ticks = |low: f64, high: f64, values: &[f64]| {
            let format = axis_format(low, high);
            values.iter().map(format).collect::<Vec<_>>()
        };
        assert_eq!(
            ticks(0.0, 0.02, &[0.0, 0.005, 0.01, 0.015]),
            ["0", "0.0050", "0.0100", "0.0150"]
        );
        assert_eq!(
            ticks(0.0, 0.008, &[0.002, 0.004, 0.008]),
            ["2.00e-3", "4.00e-3", "8.00e-3"]
        );
        assert_eq!(ticks(0.05, 5.0, &[0.1, 1.0]), ["0.10", "1.00"]);
        assert_eq!(ticks(1e-3, 1.0, &[1e-3, 0.1]), ["1.00e-3", "1.00e-1"]);
        assert_eq!(ticks(0.0, 400.0, &[100.0, 250.0]), ["100", "250"]);
    }
}
