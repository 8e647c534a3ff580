//! What a car-following controller sees at one step.

/// What a car-following controller sees at one step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FollowerObservation {
    /// Own speed v (m/s).
    pub speed: f64,
    /// Leader's speed (m/s).
    pub lead_speed: f64,
    /// Range R: leader's rear bumper to own front bumper (m).
    pub gap: f64,
}
