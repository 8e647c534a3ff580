//! Numerical tolerances, named in one place so that every check in the crate
//! agrees on what "equal" and "sums to one" mean.

/// A probability table whose mass differs from 1 by more than this is rejected;
/// a smaller deviation is renormalised and reported (the authors' cut-in table
/// sums to 1.0000006).
pub const MASS_SUM_TOLERANCE: f64 = 1e-4;

/// Two axis labels closer than this (relative to the axis step) are the same label.
pub const LABEL_TOLERANCE: f64 = 1e-9;

/// Probabilities below this are treated as zero when a ratio would divide by them.
pub const PROBABILITY_FLOOR: f64 = 1e-300;
