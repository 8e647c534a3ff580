//! A vehicle under test of our own design (the paper's, Nilsson et al.
//! 2016, is not available): a rule-based controller that accepts gaps by
//! time gaps and a kinematic closing check, and tracks a speed command
//! toward one slot of the right lane. It differs from the MOBIL surrogate
//! on purpose: it knows the BVs will not yield, it does not search over
//! plans, and it grows bolder as the exit approaches.
//!
//! In the left lane, at every step, with `s = max(s_min, (L − p)/D_u)`
//! capped at 1 (the urgency scale: 1 far from the exit, down to `s_min`
//! within `D_u` of it):
//!
//! - **accept** the right lane at the VUT's position when the task's safe
//!   time gaps hold (`|p − b| − ℓ ≥ t_min u`), the bumper gap to the BV
//!   ahead is at least `s·h_f·v` and to the BV behind at least `s·h_r·u`
//!   (its speed `u`), both at least 1 m, and a faster BV behind (closing
//!   speed `w`) is far enough for the VUT to pull away at half its free-road
//!   IDM acceleration: gap `≥ w² / a_free(v)`;
//! - otherwise **seek** a slot: a stretch of the right lane at least 10 m
//!   long that meets the unscaled time gaps `h_f u`, `h_r u` now, moving
//!   with the BVs that bound it; the one reached soonest (full acceleration
//!   or braking relative to the slot) before the exit, with the comfort
//!   bounds `[a_brake, a_accel]` when one can be reached with them and the
//!   world's `[a_min, a_max]` otherwise or within `D_u` of the exit.
//!   The command tracks the braking curve toward the slot's nearest point
//!   (5 m inside), arriving at the slot's speed `u_s`:
//!   `a = k_v (u_s + sign(e) √(2 a_b |e|) − v)`, `e` the distance to it and
//!   `a_b` the bound in its direction; speeds kept in `[v_min, v_max]`.
//!
//! In the right lane it follows the BV ahead by IDM with its own desired
//! speed and headway.

use super::gaps::{follow_in_right_lane, neighbours, safe_gaps, within_speed_bounds};
use super::idm::{Idm, IdmSteps};
use super::view::{Action, DriverView, Lane};
use crate::cases::highway::world::{Bv, ExitWorld};
use crate::vehicle::{check, ParamError};
use serde::{Deserialize, Serialize};

/// Parameters of the gap seeker (a highway-exit VUT).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GapSeekerParams {
    /// Accepted time gap to the new leader, at own speed (s).
    pub front_gap: f64,
    /// Accepted time gap of the new follower, at its speed (s).
    pub rear_gap: f64,
    /// Distance to the exit below which the thresholds shrink (m).
    pub urgency_distance: f64,
    /// Smallest urgency scale.
    pub min_scale: f64,
    /// Gain of the speed tracker (1/s).
    pub k_speed: f64,
    /// Comfort bounds of the seeker's commands (m/s²).
    pub brake: f64,
    /// Upper comfort bound of the seeker's commands (m/s²).
    pub accelerate: f64,
    /// IDM in the right lane: desired speed (m/s) and headway (s).
    pub v0: f64,
    /// IDM desired time headway in the right lane (s).
    pub headway: f64,
}

impl Default for GapSeekerParams {
    fn default() -> Self {
        Self {
            front_gap: 0.8,
            rear_gap: 0.6,
            urgency_distance: 60.0,
            min_scale: 0.3,
            k_speed: 1.2,
            brake: -3.0,
            accelerate: 1.5,
            v0: 36.0,
            headway: 1.0,
        }
    }
}

impl GapSeekerParams {
    /// Checks every parameter is finite and in range.
    pub fn validate(&self) -> Result<(), ParamError> {
        let m = "gap-seeker";
        check(m, "front_gap", self.front_gap, |x| x >= 0.0, "must be ≥ 0")?;
        check(m, "rear_gap", self.rear_gap, |x| x >= 0.0, "must be ≥ 0")?;
        check(
            m,
            "urgency_distance",
            self.urgency_distance,
            |x| x > 0.0,
            "must be > 0",
        )?;
        check(
            m,
            "min_scale",
            self.min_scale,
            |x| x > 0.0 && x <= 1.0,
            "must be in (0, 1]",
        )?;
        check(m, "k_speed", self.k_speed, |x| x >= 0.0, "must be ≥ 0")?;
        check(m, "brake", self.brake, |x| x < 0.0, "must be < 0")?;
        check(m, "accelerate", self.accelerate, |x| x > 0.0, "must be > 0")?;
        check(m, "v0", self.v0, |x| x > 0.0, "must be > 0")?;
        check(m, "headway", self.headway, |x| x >= 0.0, "must be ≥ 0")
    }

    fn idm(&self) -> Idm {
        Idm {
            v0: self.v0,
            headway: self.headway,
            ..Idm::HIGHWAY
        }
    }
}

#[derive(Debug, Clone)]
pub struct GapSeekerDriver {
    params: GapSeekerParams,
    idm: IdmSteps,
}

impl GapSeekerDriver {
    pub fn new(params: GapSeekerParams) -> Self {
        Self {
            idm: IdmSteps::new(params.idm()),
            params,
        }
    }

    /// The IDM it follows with in the right lane ([`follow_in_right_lane`]).
    pub fn right_lane_idm(&self) -> &IdmSteps {
        &self.idm
    }

    pub fn act(&mut self, view: &DriverView) -> Action {
        if view.lane == Lane::Right {
            return Action {
                accel: follow_in_right_lane(&self.idm, view),
                change_lane: false,
            };
        }
        let world = view.world;
        let to_exit = world.exit - view.position;
        let scale = (to_exit / self.params.urgency_distance).clamp(self.params.min_scale, 1.0);
        if self.accepts(view, scale) {
            return Action {
                accel: 0.0,
                change_lane: true,
            };
        }
        // Comfort bounds while a slot can be reached with them before the
        // exit; the world's full bounds when none can, or near the exit.
        let comfort = (self.params.brake, self.params.accelerate);
        let slot = match self.best_slot(view, comfort) {
            Some((slot, true)) if scale >= 1.0 => Some((slot, comfort)),
            _ => self
                .best_slot(view, world.accel)
                .map(|(slot, _)| (slot, world.accel)),
        };
        let (brake, accelerate) = slot.map_or(comfort, |(_, bounds)| bounds);
        let command = match slot {
            Some(((target, slot_speed), _)) => {
                // Speed command from the braking curve: close the distance
                // e as fast as the bound allows while arriving at the slot's
                // speed, v_cmd = u + sign(e) √(2 a |e|).
                let e = target - view.position;
                let bound = if e > 0.0 { accelerate } else { -brake };
                let command_speed = slot_speed + e.signum() * (2.0 * bound * e.abs()).sqrt();
                self.params.k_speed * (command_speed - view.speed)
            }
            None => 0.0,
        };
        Action {
            accel: within_speed_bounds(world, view.speed, command.clamp(brake, accelerate)),
            change_lane: false,
        }
    }

    fn accepts(&self, view: &DriverView, scale: f64) -> bool {
        let (world, p, v) = (view.world, view.position, view.speed);
        let bvs = &view.traffic.bvs;
        if !safe_gaps(world, bvs, p) {
            return false;
        }
        let n = neighbours(bvs, p);
        let front_ok = n.ahead.is_none_or(|a| {
            let gap = a.position - p - world.length;
            gap >= 1.0 && gap >= scale * self.params.front_gap * v
        });
        let rear_ok = n.behind.is_none_or(|b| {
            let gap = p - b.position - world.length;
            // The BV will not brake: the VUT must outrun a faster follower,
            // so the gap has to absorb the closing speed at half the VUT's
            // free-road IDM acceleration, `w²/(2 · ½ a_free(v))`.
            let closing = (b.speed - v).max(0.0);
            let escape = 0.5 * self.idm.accel(v, None).max(0.1);
            gap >= 1.0
                && gap >= scale * self.params.rear_gap * b.speed
                && gap >= closing * closing / (2.0 * escape)
        });
        front_ok && rear_ok
    }

    /// The slot reached soonest (its nearest point, 5 m inside) and the
    /// speed it moves at, and whether it is reached before the exit. A slot
    /// is a stretch of the right lane that meets the unscaled time gaps now;
    /// the time to reach it is that of full acceleration (slots ahead) or
    /// braking (slots behind) within `bounds`, relative to the slot; slots
    /// not reached before the exit are skipped unless none is.
    fn best_slot(&self, view: &DriverView, bounds: (f64, f64)) -> Option<((f64, f64), bool)> {
        let (world, p, v) = (view.world, view.position, view.speed);
        let (front, rear) = (view.traffic.front(), view.traffic.rear());
        let after = |bv: Bv| bv.position + world.length + self.params.rear_gap * bv.speed;
        let before = |bv: Bv| bv.position - world.length - self.params.front_gap * bv.speed;
        // (lower, upper, speed) of the slots ahead of, between and behind the BVs.
        let slots = [
            (after(front), f64::INFINITY, front.speed.max(v)),
            (after(rear), before(front), 0.5 * (front.speed + rear.speed)),
            (f64::NEG_INFINITY, before(rear), rear.speed),
        ];
        let margin = 5.0;
        let candidates: Vec<(f64, f64, f64)> = slots
            .into_iter()
            .filter(|(lo, hi, _)| hi - lo > 2.0 * margin)
            .map(|(lo, hi, speed)| {
                let target = p.clamp(lo + margin, hi - margin);
                (
                    target,
                    speed,
                    time_to_reach(world, bounds, target - p, v, speed),
                )
            })
            .collect();
        // Where the VUT meets the slot: the target point moved on at the slot's speed.
        let reachable = |&&(target, speed, t): &&(f64, f64, f64)| {
            t.is_finite() && target + speed * t < world.exit
        };
        let soonest = |a: &&(f64, f64, f64), b: &&(f64, f64, f64)| a.2.total_cmp(&b.2);
        match candidates.iter().filter(reachable).min_by(soonest) {
            Some(&(target, speed, _)) => Some(((target, speed), true)),
            None => candidates
                .iter()
                .min_by(soonest)
                .map(|&(target, speed, _)| ((target, speed), false)),
        }
    }
}

/// Time to close a distance `d` (target − own position) to a point moving
/// at `u`, accelerating at `bounds.1` up to `v_max` (target ahead) or
/// braking at `bounds.0` down to `v_min` (target behind): the first `t`
/// with `∫₀ᵗ (v(s) − u) ds = d`; infinite when the speed bound stops the VUT
/// from ever getting there.
fn time_to_reach(world: &ExitWorld, bounds: (f64, f64), d: f64, v: f64, u: f64) -> f64 {
    if d == 0.0 {
        return 0.0;
    }
    // Work in the direction of travel toward the target: gain = ±(v − u).
    let (a, bound, sign) = if d > 0.0 {
        (bounds.1, world.speed.1, 1.0)
    } else {
        (-bounds.0, world.speed.0, -1.0)
    };
    let (dist, w, w_end) = (d.abs(), sign * (v - u), sign * (bound - u));
    let t1 = (sign * (bound - v) / a).max(0.0);
    // Phase 1: w t + ½ a t² = dist, if reached before the speed bound.
    let root = (-w + (w * w + 2.0 * a * dist).sqrt()) / a;
    if root <= t1 {
        return root;
    }
    // Phase 2: at the bound, closing at w_end.
    let covered = w * t1 + 0.5 * a * t1 * t1;
    if w_end <= 0.0 {
        f64::INFINITY
    } else {
        t1 + (dist - covered) / w_end
    }
}
