//! Cut-in runs in batches: [`LANES`] scenarios side by side, each quantity
//! an array over them (structure of arrays), so the compiler turns every
//! step into vector instructions.
//!
//! Only the outcome is computed (no mnpETTC: workers and exact answers ask
//! for the event alone), and only for the followers whose acceleration is
//! a pure function of the observation (IDM, FVDM); a stateful one
//! (switching ACC, ACC with AEB and its actuator lag) runs the scalar path.
//! Each lane performs the scalar path's operations in its order
//! ([`CutInSettings::run_with`]): `gap += (v_lead − v)·dt − a·dt·dt/2`,
//! `v += a·dt`, the same clamps, so every outcome is the scalar one, bit for
//! bit (tested on every cell of every preset). Lanes that crash keep
//! computing until the batch ends (their outcome is kept); the batch stops
//! early once every lane has crashed.

use super::simulation::{CutInSettings, SpeedBound};
use crate::vehicle::batch::{clamp, Lanes};
pub use crate::vehicle::batch::{BatchFollower, LANES};

/// The steps of a batch, for one preset's kind of speed bound and
/// accident test.
#[inline(always)]
fn run_lanes<const CLIPS_SPEED: bool, const INCLUSIVE: bool>(
    s: &CutInSettings,
    follower: &BatchFollower,
    range: &Lanes,
    range_rate: &Lanes,
) -> [bool; LANES] {
    let crashed = |gap: f64| {
        if INCLUSIVE {
            gap <= s.accident_gap
        } else {
            gap < s.accident_gap
        }
    };
    let mut lead = [0.0; LANES];
    let mut speed = [s.initial_speed; LANES];
    let mut gap = *range;
    let mut accident = [false; LANES];
    for i in 0..LANES {
        lead[i] = s.initial_speed + range_rate[i];
        accident[i] = crashed(gap[i]);
    }
    let (dt, (a_lo, a_hi), (v_lo, v_hi)) = (s.dt, s.acceleration, s.speed);
    let mut a = [0.0; LANES];
    for _ in 0..s.steps {
        if accident.iter().all(|&x| x) {
            break;
        }
        follower.accelerations(&speed, &lead, &gap, &mut a);
        for i in 0..LANES {
            let v = speed[i];
            let mut ai = clamp(a[i], a_lo, a_hi);
            if CLIPS_SPEED {
                let pushes_past = (v >= v_hi && ai > 0.0) || (v <= v_lo && ai < 0.0);
                ai = if pushes_past { 0.0 } else { ai };
            } else {
                ai = clamp(ai, (v_lo - v) / dt, (v_hi - v) / dt);
            }
            gap[i] += (lead[i] - v) * dt - ai * dt * dt / 2.0;
            let v = v + ai * dt;
            speed[i] = if CLIPS_SPEED { clamp(v, v_lo, v_hi) } else { v };
            accident[i] |= crashed(gap[i]);
        }
    }
    accident
}

/// Compiled for AVX2 as well, picked at run time (no FMA: a fused
/// multiply-add rounds once where the scalar path rounds twice).
#[multiversion::multiversion(targets("x86_64+avx2"))]
fn dispatch(
    s: &CutInSettings,
    follower: &BatchFollower,
    range: &Lanes,
    range_rate: &Lanes,
) -> [bool; LANES] {
    match (s.speed_bound, s.inclusive) {
        (SpeedBound::ClipsSpeed, true) => run_lanes::<true, true>(s, follower, range, range_rate),
        (SpeedBound::ClipsSpeed, false) => run_lanes::<true, false>(s, follower, range, range_rate),
        (SpeedBound::LimitsAcceleration, true) => {
            run_lanes::<false, true>(s, follower, range, range_rate)
        }
        (SpeedBound::LimitsAcceleration, false) => {
            run_lanes::<false, false>(s, follower, range, range_rate)
        }
    }
}

/// Whether each of the [`LANES`] runs after a cut-in at `range[i]`,
/// `range_rate[i]` ends in an accident: [`CutInSettings::run`]'s
/// `accident`, computed side by side.
pub fn accidents(
    s: &CutInSettings,
    follower: &BatchFollower,
    range: &Lanes,
    range_rate: &Lanes,
) -> [bool; LANES] {
    dispatch(s, follower, range, range_rate)
}
