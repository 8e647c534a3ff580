//! Numbers in messages: as written, or in scientific notation when tiny or
//! huge. Rust's `{}` writes `1e-310` as a decimal with 310 digits, which
//! buries an error's point; users wrote it as `1e-310`.

use std::fmt;

/// `x` written as `{}` in `[10⁻⁴, 10⁶)` (and for 0), else as `{:e}`:
/// `0.2`, `86400`, `1e-310`, `1e300`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Num(pub f64);

impl fmt::Display for Num {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let magnitude = self.0.abs();
        if self.0 == 0.0 || !self.0.is_finite() || (1e-4..1e6).contains(&magnitude) {
            write!(f, "{}", self.0)
        } else {
            write!(f, "{:e}", self.0)
        }
    }
}

/// A grid label `start + k · step` as a table writes it: rounded to 10⁻⁹
/// (every grid step is a multiple of 10⁻³), then as `{}`, the shortest
/// text that reads back to it: `-14.4` where the sum gives
/// `-14.399999999999999`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Label(pub f64);

impl fmt::Display for Label {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let rounded = (self.0 * 1e9).round() / 1e9;
        // -0 reads as 0.
        write!(f, "{}", if rounded == 0.0 { 0.0 } else { rounded })
    }
}

/// `n` and a noun, singular for 1: `1 event`, `0 events`, `2 events`.
/// The noun's plural adds `s`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Count<'a>(pub u64, pub &'a str);

impl fmt::Display for Count<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let Count(n, noun) = *self;
        write!(f, "{n} {noun}{}", if n == 1 { "" } else { "s" })
    }
}

#[cfg(test)]
mod tests {
    use super::{Count, Label, Num};

    #[test]
    fn grid_labels_are_the_shortest_text_of_the_step_they_lie_on() {
        let step = 0.4;
        let shown: Vec<String> = [14usize, 19, 23, 50]
            .map(|k| Label(-20.0 + k as f64 * step).to_string())
            .into();
        assert_eq!(-20.0 + 14.0 * step, -14.399999999999999);
        assert_eq!(shown, ["-14.4", "-12.4", "-10.8", "0"]);
        assert_eq!(Label(0.05 * 3.0).to_string(), "0.15");
    }

    #[test]
    fn one_event_is_singular() {
        let shown: Vec<String> = [0, 1, 2].map(|n| Count(n, "event").to_string()).into();
        assert_eq!(shown, ["0 events", "1 event", "2 events"]);
    }

    #[test]
    fn tiny_and_huge_numbers_are_scientific() {
        let shown: Vec<String> = [0.2, 2.0, 86400.0, 1e-310, 1e300, -3e-7, 0.0, f64::NAN, 1e-4]
            .iter()
            .map(|&x| Num(x).to_string())
            .collect();
        assert_eq!(
            shown,
            ["0.2", "2", "86400", "1e-310", "1e300", "-3e-7", "0", "NaN", "0.0001"]
        );
    }
}
