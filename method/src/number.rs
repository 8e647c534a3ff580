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

#[cfg(test)]
mod tests {
    use super::Num;

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
