//! What every figure shares: size, fonts and how numbers are written on axes.

use plotters::style::RGBColor;

/// Width and height of one plot in pixels.
pub const SIZE: (u32, u32) = (720, 420);
pub const FONT: &str = "sans-serif";
pub const ESTIMATE: RGBColor = RGBColor(31, 93, 166);
pub const BAND: RGBColor = RGBColor(160, 196, 232);
pub const LIMIT: RGBColor = RGBColor(200, 40, 40);

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
}
