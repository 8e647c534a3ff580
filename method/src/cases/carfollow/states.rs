//! The state grid `s = (v_BV, R, Ṙ)`: v ∈ [20, 40] step 1 m/s (21), R ∈ (0,
//! 115] step 1 m (115), Ṙ ∈ [−10, 8] step 1 m/s (19): 45,885 states. A
//! continuous state is looked up at its nearest grid state; speeds and range
//! rates beyond the grid are clamped to its edge, a range beyond 115 m is
//! "free" (no state: the VUT is not following).

use super::world::FollowState;

/// The state grid's axes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StateGrid {
    /// BV speed axis: `(lowest value, number of values)` (m/s).
    pub speed: (f64, usize),
    /// Range axis: `(lowest value, number of values)` (m).
    pub range: (f64, usize),
    /// Range-rate axis: `(lowest value, number of values)` (m/s).
    pub range_rate: (f64, usize),
    /// Step of every axis (1 m/s, 1 m).
    pub step: f64,
}

impl StateGrid {
    /// The paper's grid: v 20…40, R 1…115, Ṙ −10…8, step 1 (45,885 states).
    pub fn paper() -> Self {
        Self {
            speed: (20.0, 21),
            range: (1.0, 115),
            range_rate: (-10.0, 19),
            step: 1.0,
        }
    }

    /// Number of grid states.
    pub fn len(&self) -> usize {
        self.speed.1 * self.range.1 * self.range_rate.1
    }

    /// Whether the grid has no states.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The index of grid coordinates `(i_v, i_R, i_Ṙ)`.
    pub fn index(&self, iv: usize, ir: usize, irr: usize) -> usize {
        (iv * self.range.1 + ir) * self.range_rate.1 + irr
    }

    /// The state at index `s`.
    pub fn state(&self, s: usize) -> FollowState {
        let irr = s % self.range_rate.1;
        let ir = (s / self.range_rate.1) % self.range.1;
        let iv = s / (self.range_rate.1 * self.range.1);
        FollowState {
            bv_speed: self.speed.0 + iv as f64 * self.step,
            range: self.range.0 + ir as f64 * self.step,
            range_rate: self.range_rate.0 + irr as f64 * self.step,
        }
    }

    /// The index of the grid speed nearest to `speed` (clamped to the grid).
    pub fn speed_index(&self, speed: f64) -> usize {
        (((speed - self.speed.0) / self.step).round().max(0.0) as usize).min(self.speed.1 - 1)
    }

    /// The nearest grid state, or `None` when the range is beyond the grid.
    pub fn nearest(&self, x: &FollowState) -> Option<usize> {
        let axis = |value: f64, (low, n): (f64, usize)| -> Option<usize> {
            let k = ((value - low) / self.step).round();
            if k > (n - 1) as f64 {
                None
            } else {
                Some(k.max(0.0) as usize)
            }
        };
        let ir = axis(x.range, self.range)?;
        let clamp = |value: f64, (low, n): (f64, usize)| {
            (((value - low) / self.step).round().max(0.0) as usize).min(n - 1)
        };
        Some(self.index(
            clamp(x.bv_speed, self.speed),
            ir,
            clamp(x.range_rate, self.range_rate),
        ))
    }
}
