//! The car-following world of case 3 (SPEC §6, paper §V): the vehicle under
//! test (VUT) follows one background vehicle (BV) for 30 s. Every second the
//! BV picks an acceleration `u` from 31 values in [−4, 2] m/s²; between
//! decisions both vehicles move with a 0.1 s step. An accident is a range
//! (bumper gap) `R ≤ 1 m` at any step.

use crate::vehicle::{Controller, FollowDriver, FollowStep, FollowerObservation};

/// The world's constants. [`FollowWorld::paper`] holds the paper's values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FollowWorld {
    /// Fine time step (s).
    pub dt: f64,
    /// Fine steps per BV decision (10: a decision every second).
    pub steps_per_decision: usize,
    /// BV decisions per test (30 s).
    pub decisions: usize,
    /// The BV's lowest acceleration and the action step (m/s²): actions are
    /// `u_min + k · u_step`, `k = 0 … actions − 1`.
    pub u_min: f64,
    /// Step between the BV's actions (m/s²).
    pub u_step: f64,
    /// Number of BV actions.
    pub actions: usize,
    /// The BV's speed stays in this interval: the grid's speeds (m/s).
    pub bv_speed: (f64, f64),
    /// The VUT's acceleration and speed bounds.
    pub vut_accel: (f64, f64),
    /// The VUT's speed bounds (m/s).
    pub vut_speed: (f64, f64),
    /// Accident: range `≤ accident_range` (m).
    pub accident_range: f64,
}

impl FollowWorld {
    /// Δt 0.1 s, a decision per second for 30 s, u ∈ [−4, 2] step 0.2,
    /// BV speeds in [20, 40] m/s, VUT a ∈ [−4, 2] m/s² and v ∈ [0, 45] m/s,
    /// accident at R ≤ 1 m.
    pub fn paper() -> Self {
        Self {
            dt: 0.1,
            steps_per_decision: 10,
            decisions: 30,
            u_min: -4.0,
            u_step: 0.2,
            actions: 31,
            bv_speed: (20.0, 40.0),
            vut_accel: (-4.0, 2.0),
            vut_speed: (0.0, 45.0),
            accident_range: 1.0,
        }
    }

    /// The acceleration of action `k`.
    pub fn action(&self, k: usize) -> f64 {
        self.u_min + k as f64 * self.u_step
    }
}

/// The continuous state of a run: `(v_BV, R, Ṙ)` with `Ṙ = v_BV − v_VUT`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FollowState {
    /// The BV's speed v (m/s).
    pub bv_speed: f64,
    /// The range R (m).
    pub range: f64,
    /// The range rate `Ṙ = v_BV − v_VUT` (m/s).
    pub range_rate: f64,
}

impl FollowState {
    /// The VUT's speed `v_BV − Ṙ` (m/s).
    pub fn vut_speed(&self) -> f64 {
        self.bv_speed - self.range_rate
    }
}

/// How far a test has come: fine steps taken and the VUT's distance
/// driven, for the observations of an external program.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Odometer {
    /// Fine steps taken since the test started.
    pub step: usize,
    /// The VUT's distance driven (m).
    pub position: f64,
}

/// One BV decision with a built-in controller ([`advance_with`]).
pub fn advance(
    world: &FollowWorld,
    state: FollowState,
    u: f64,
    vut: &mut Controller,
) -> Option<FollowState> {
    let Ok(next) = advance_with(world, state, u, vut, &mut Odometer::default());
    next
}

/// One BV decision: the BV holds `u` (cut so its speed stays in bounds) for
/// `steps_per_decision` steps while `vut` follows. Per step: the VUT's
/// command is clipped to its bounds and to what keeps its speed in bounds;
/// each vehicle moves `v Δt + a Δt²/2`, then `v += a Δt`. Returns the new
/// state, or `None` when the range fell to `accident_range` or below; a
/// driver error ends the test with that error.
pub fn advance_with<D: FollowDriver>(
    world: &FollowWorld,
    state: FollowState,
    u: f64,
    vut: &mut D,
    odometer: &mut Odometer,
) -> Result<Option<FollowState>, D::Error> {
    let dt = world.dt;
    let mut bv = state.bv_speed;
    let mut own = state.vut_speed();
    let mut range = state.range;
    for _ in 0..world.steps_per_decision {
        let a_bv = u.clamp((world.bv_speed.0 - bv) / dt, (world.bv_speed.1 - bv) / dt);
        let step = FollowStep {
            step: odometer.step,
            time: odometer.step as f64 * dt,
            position: odometer.position,
            obs: FollowerObservation {
                speed: own,
                lead_speed: bv,
                gap: range,
            },
            clip: world.vut_accel,
            dt,
        };
        let a_own = vut
            .decide(&step)?
            .clamp(world.vut_accel.0, world.vut_accel.1)
            .clamp(
                (world.vut_speed.0 - own) / dt,
                (world.vut_speed.1 - own) / dt,
            );
        range += (bv - own) * dt + 0.5 * (a_bv - a_own) * dt * dt;
        odometer.position += own * dt + 0.5 * a_own * dt * dt;
        odometer.step += 1;
        bv += a_bv * dt;
        own += a_own * dt;
        if range <= world.accident_range {
            return Ok(None);
        }
    }
    Ok(Some(FollowState {
        bv_speed: bv,
        range,
        range_rate: bv - own,
    }))
}
