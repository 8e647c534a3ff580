//! Pieces shared by the cases' auxiliary objectives.

/// Normalised distance to a box-shaped common set Ω:
/// `d(x, Ω) = min_{y∈Ω} √((1/m) Σᵢ (xᵢ − yᵢ)² / U_{F,i}²)`.
/// For a box the minimising `y` is `x` clamped to the box, axis by axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxDistance<const M: usize> {
    /// Lower corner of Ω, per axis.
    pub lower: [f64; M],
    /// Upper corner of Ω, per axis.
    pub upper: [f64; M],
    /// The normalisation factors U_F.
    pub scale: [f64; M],
}

impl<const M: usize> BoxDistance<M> {
    /// `d(x, Ω)`.
    pub fn distance(&self, x: &[f64; M]) -> f64 {
        let sum: f64 = (0..M)
            .map(|i| {
                let outside = (self.lower[i] - x[i]).max(x[i] - self.upper[i]).max(0.0);
                (outside / self.scale[i]).powi(2)
            })
            .sum();
        (sum / M as f64).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distance_is_zero_inside_and_normalised_outside() {
        let omega = BoxDistance {
            lower: [6.0, -2.4],
            upper: [88.0, 1.2],
            scale: [18.0, 20.0],
        };
        assert_eq!(omega.distance(&[20.0, 0.0]), 0.0);
        // 18 m short of the range bound only: √(½ · 1²).
        assert!((omega.distance(&[-12.0, 0.0]) - 0.5f64.sqrt()).abs() < 1e-12);
        // Both axes: √(½ (1² + 1²)) = 1.
        assert!((omega.distance(&[-12.0, -22.4]) - 1.0).abs() < 1e-12);
    }
}
