//! One drawn test.

/// One drawn test: the scenario and its importance weight `P(x)/q(x)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Draw {
    /// The scenario's grid cell.
    pub cell: usize,
    /// Importance weight `P(x)/q(x)`.
    pub weight: f64,
}
