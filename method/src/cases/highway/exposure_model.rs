//! The built-in highway-exit exposure: a synthetic car-following model in
//! the paper's form `P(x) = P(p₁) P(v₁, R, v₂)`, `R = p₁ − p₂`.
//!
//! The paper takes `P(v₁, R, v₂)` from car-following events of the IVBSS
//! naturalistic data at speeds ≥ 20 m/s, which are not public. This model has
//! the same structure with magnitudes one can check against highway driving:
//!
//! - `p₁` (the leading BV's position) uniform over the road section;
//! - `v₁ ~ N(29.5, 3.5²)` m/s: highway traffic at about 66 mph with most
//!   speeds between 58 and 74 mph (US interstate speed studies report mean
//!   speeds near 65–70 mph and standard deviations of 7–8 mph);
//! - `v₂ | v₁ ~ N(v₁, 1.5²)`: in car following the range rate is small, its
//!   standard deviation 1–2 m/s;
//! - `R | v₂`: the time headway `h = R/v₂` is log-normal with median 1.6 s
//!   and log-standard deviation 0.5 (highway headways of following drivers
//!   cluster at 1–2 s; about 10% are below 0.85 s). `R` is front to front,
//!   so the bumper gap is `R − 5 m`.
//! - BV 1 leads (`R > 0`); cells with `p₂ ≥ p₁` are not car following and
//!   have exposure 0.
//!
//! The density is evaluated at each cell's values and normalised over the
//! grid, so near the ends of the road section, where not every range fits,
//! the leader position is slightly less than uniform.

use crate::density::normal;
use crate::grid::{Axis, Grid};
use crate::mass::GridMass;

/// Parameters of the synthetic car-following exposure.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExitExposureModel {
    /// Leader speed mean and standard deviation (m/s).
    pub speed_mean: f64,
    /// Leader speed standard deviation (m/s).
    pub speed_sd: f64,
    /// Standard deviation of the follower's speed about the leader's (m/s).
    pub relative_speed_sd: f64,
    /// Median (s) and log-standard deviation of the time headway.
    pub headway_median: f64,
    /// Log-standard deviation of the time headway.
    pub headway_log_sd: f64,
}

impl Default for ExitExposureModel {
    fn default() -> Self {
        Self {
            speed_mean: 29.5,
            speed_sd: 3.5,
            relative_speed_sd: 1.5,
            headway_median: 1.6,
            headway_log_sd: 0.5,
        }
    }
}

impl ExitExposureModel {
    /// Unnormalised density of `(v₁, R, v₂)`; zero unless `R > 0`.
    pub fn density(&self, v1: f64, range: f64, v2: f64) -> f64 {
        if range <= 0.0 || v2 <= 0.0 {
            return 0.0;
        }
        let h = range / v2;
        let log_ratio = (h / self.headway_median).ln();
        // Log-normal density of h, times dh/dR = 1/v₂.
        let headway = normal(log_ratio, 0.0, self.headway_log_sd) / h / v2;
        normal(v1, self.speed_mean, self.speed_sd)
            * normal(v2, v1, self.relative_speed_sd)
            * headway
    }

    /// The exposure on a `(p₁, v₁, p₂, v₂)` grid (`p₁` uniform).
    pub fn mass_on(&self, grid: Grid) -> GridMass {
        assert_eq!(
            grid.dimensions(),
            4,
            "the highway-exit grid is four-dimensional"
        );
        let weights = (0..grid.len())
            .map(|cell| {
                let x = grid.values(cell);
                self.density(x[1], x[0] - x[2], x[3])
            })
            .collect();
        GridMass::from_weights(grid, weights).expect("the density is positive where p₁ > p₂")
    }
}

/// The paper's grid: positions −100 … 200 m in steps of `position_step`,
/// speeds 20 … 40 m/s in steps of `speed_step` (5 m and 1 m/s: 61 × 21 × 61
/// × 21 = 1,640,961 scenarios).
pub fn exit_grid(position_step: f64, speed_step: f64) -> Grid {
    let positions = (300.0 / position_step).round() as usize + 1;
    let speeds = (20.0 / speed_step).round() as usize + 1;
    let p = |name| Axis::uniform(name, -100.0, position_step, positions).expect("valid axis");
    let v = |name| Axis::uniform(name, 20.0, speed_step, speeds).expect("valid axis");
    Grid::new(vec![p("p1"), v("v1"), p("p2"), v("v2")]).expect("valid grid")
}
