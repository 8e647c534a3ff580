//! Densities shared by the synthetic exposure models.

/// The normal density `φ((x − m)/σ)/σ`.
pub fn normal(x: f64, mean: f64, sd: f64) -> f64 {
    let z = (x - mean) / sd;
    (-0.5 * z * z).exp() / (sd * (2.0 * std::f64::consts::PI).sqrt())
}
