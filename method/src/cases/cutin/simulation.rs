//! The cut-in simulation: after the cut-in the leader keeps its speed and the
//! vehicle under test follows it for a fixed horizon.

use crate::vehicle::{FollowDriver, FollowStep, FollowerObservation, VehicleModel};
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// Simulation settings. Two named presets exist; see [`CutInPreset::PaperCode`]
/// and [`CutInPreset::PaperTable`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CutInSettings {
    /// Speed of the vehicle under test at the cut-in (m/s); the leader drives at `v + Ṙ`.
    pub initial_speed: f64,
    /// Time step (s).
    pub dt: f64,
    /// Number of steps.
    pub steps: usize,
    /// Acceleration bounds (m/s²).
    pub acceleration: (f64, f64),
    /// Speed bounds of the vehicle under test (m/s), kept as `speed_bound` says.
    pub speed: (f64, f64),
    /// How the speed bounds act on a step.
    #[serde(default)]
    pub speed_bound: SpeedBound,
    /// An accident is a range `≤ accident_gap` (`inclusive`) or `< accident_gap`.
    pub accident_gap: f64,
    /// Whether a range equal to `accident_gap` is an accident.
    pub inclusive: bool,
}

/// How a cut-in step keeps the speed of the vehicle under test in bounds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SpeedBound {
    /// The acceleration is limited to `[(v_min − v)/dt, (v_max − v)/dt]`,
    /// so one step never leaves the bounds (the paper's Table III preset).
    #[default]
    LimitsAcceleration,
    /// The authors' code (`update_state.m`): the acceleration is dropped
    /// only when the speed already sits on a bound and the acceleration
    /// pushes past it; otherwise the whole step uses it, the position
    /// included (`x += v dt + a dt²/2`), and the speed `v + a dt` is
    /// clipped to the bounds afterwards. A vehicle braking to a stop thus
    /// covers less distance in its last step than one whose braking is
    /// limited to the speed it has.
    ClipsSpeed,
}

/// A named simulation preset.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum CutInPreset {
    /// The authors' published code: the settings that reproduce the 184-cell library.
    #[default]
    PaperCode,
    /// The paper's Table III.
    PaperTable,
}

impl CutInPreset {
    /// The preset's settings.
    pub fn settings(self) -> CutInSettings {
        match self {
            // dt 1 s for 10 s; a ∈ [−3, 3]; v ∈ [0, 40]; accident at R ≤ 0.
            CutInPreset::PaperCode => CutInSettings {
                initial_speed: 20.0,
                dt: 1.0,
                steps: 10,
                acceleration: (-3.0, 3.0),
                speed: (0.0, 40.0),
                speed_bound: SpeedBound::ClipsSpeed,
                accident_gap: 0.0,
                inclusive: true,
            },
            // dt 0.1 s for 10 s; a ∈ [−4, 2]; v ∈ [2, 40]; accident at R < 1 m.
            CutInPreset::PaperTable => CutInSettings {
                initial_speed: 20.0,
                dt: 0.1,
                steps: 100,
                acceleration: (-4.0, 2.0),
                speed: (2.0, 40.0),
                speed_bound: SpeedBound::LimitsAcceleration,
                accident_gap: 1.0,
                inclusive: false,
            },
        }
    }

    /// The preset's name on the wire (`paper-code`, `paper-table`).
    pub fn name(self) -> &'static str {
        match self {
            CutInPreset::PaperCode => "paper-code",
            CutInPreset::PaperTable => "paper-table",
        }
    }
}

impl fmt::Display for CutInPreset {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for CutInPreset {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "paper-code" => Ok(Self::PaperCode),
            "paper-table" => Ok(Self::PaperTable),
            other => Err(format!(
                "unknown cut-in preset `{other}`; presets are paper-code, paper-table"
            )),
        }
    }
}

/// What one run produced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CutInRun {
    /// Whether an accident happened.
    pub accident: bool,
    /// Step at which it happened.
    pub accident_step: Option<usize>,
    /// mnpETTC: the minimum over the run of the normalised positive enhanced
    /// time to collision (0 after an accident, at most 1).
    pub mnp_ettc: f64,
}

/// Enhanced time to collision with constant relative acceleration `u_r`:
/// the first positive root of `R + Ṙt + u_r t²/2 = 0`,
/// `ETTC = (−Ṙ − √(Ṙ² − 2u_r R)) / u_r`, or `R/(−Ṙ)` when `u_r = 0`.
/// `None` when the vehicles never meet (no real, non-negative root).
pub fn enhanced_ttc(range: f64, range_rate: f64, relative_acceleration: f64) -> Option<f64> {
    let ettc = if relative_acceleration == 0.0 {
        if range_rate >= 0.0 {
            return None;
        }
        range / -range_rate
    } else {
        let discriminant = range_rate * range_rate - 2.0 * relative_acceleration * range;
        if discriminant < 0.0 {
            return None;
        }
        (-range_rate - discriminant.sqrt()) / relative_acceleration
    };
    (ettc >= 0.0 && ettc.is_finite()).then_some(ettc)
}

/// npETTC = ETTC/U_I when ETTC exists, else 1; capped at 1 so that a distant
/// collision is never scored as safer than no collision.
pub fn normalised_ettc(range: f64, range_rate: f64, relative_acceleration: f64, u_i: f64) -> f64 {
    enhanced_ttc(range, range_rate, relative_acceleration).map_or(1.0, |t| (t / u_i).min(1.0))
}

impl CutInSettings {
    /// The acceleration a step at speed `speed` applies, from the driver's
    /// `a` (already within the acceleration bounds); see [`SpeedBound`].
    fn within_speed_bounds(&self, a: f64, speed: f64) -> f64 {
        match self.speed_bound {
            SpeedBound::LimitsAcceleration => a.clamp(
                (self.speed.0 - speed) / self.dt,
                (self.speed.1 - speed) / self.dt,
            ),
            SpeedBound::ClipsSpeed => {
                let pushes_past =
                    (speed >= self.speed.1 && a > 0.0) || (speed <= self.speed.0 && a < 0.0);
                if pushes_past {
                    0.0
                } else {
                    a
                }
            }
        }
    }

    fn is_accident(&self, gap: f64) -> bool {
        if self.inclusive {
            gap <= self.accident_gap
        } else {
            gap < self.accident_gap
        }
    }

    /// Runs `vehicle` after a cut-in at range `range` and range rate
    /// `range_rate` (see [`CutInSettings::run_with`]).
    pub fn run(&self, vehicle: &VehicleModel, range: f64, range_rate: f64, u_i: f64) -> CutInRun {
        let Ok(run) = self.run_with(&mut vehicle.controller(), range, range_rate, u_i);
        run
    }

    /// Runs a fresh `driver` after a cut-in at range `range` and range rate
    /// `range_rate`. Per step: the driver's acceleration is clipped to the
    /// acceleration bounds and then to what keeps the speed in bounds;
    /// positions advance by `v dt + a dt²/2`, then `v += a dt`; the leader
    /// moves at constant speed. `u_i` normalises the ETTC. A driver error
    /// ends the run with that error.
    pub fn run_with<D: FollowDriver>(
        &self,
        driver: &mut D,
        range: f64,
        range_rate: f64,
        u_i: f64,
    ) -> Result<CutInRun, D::Error> {
        let lead_speed = self.initial_speed + range_rate;
        let mut speed = self.initial_speed;
        let mut position = 0.0;
        let mut gap = range;
        let mut mnp_ettc: f64 = 1.0;
        if self.is_accident(gap) {
            return Ok(CutInRun {
                accident: true,
                accident_step: Some(0),
                mnp_ettc: 0.0,
            });
        }
        for step in 1..=self.steps {
            let a = driver
                .decide(&FollowStep {
                    step: step - 1,
                    time: (step - 1) as f64 * self.dt,
                    position,
                    obs: FollowerObservation {
                        speed,
                        lead_speed,
                        gap,
                    },
                    clip: self.acceleration,
                    dt: self.dt,
                })?
                .clamp(self.acceleration.0, self.acceleration.1);
            let a = self.within_speed_bounds(a, speed);
            mnp_ettc = mnp_ettc.min(normalised_ettc(gap, lead_speed - speed, -a, u_i));
            gap += (lead_speed - speed) * self.dt - a * self.dt * self.dt / 2.0;
            position += speed * self.dt + a * self.dt * self.dt / 2.0;
            speed += a * self.dt;
            if self.speed_bound == SpeedBound::ClipsSpeed {
                speed = speed.clamp(self.speed.0, self.speed.1);
            }
            if self.is_accident(gap) {
                return Ok(CutInRun {
                    accident: true,
                    accident_step: Some(step),
                    mnp_ettc: 0.0,
                });
            }
        }
        Ok(CutInRun {
            accident: false,
            accident_step: None,
            mnp_ettc,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ettc_is_the_first_meeting_time() {
        // Closing at 10 m/s from 20 m, no acceleration: 2 s.
        assert_eq!(enhanced_ttc(20.0, -10.0, 0.0), Some(2.0));
        // Opening: never meet.
        assert_eq!(enhanced_ttc(20.0, 10.0, 0.0), None);
        // Closing at 10 m/s from 10 m, follower braking at 3 (u_r = +3):
        // 10 − 10t + 1.5t² = 0 → t = (10 − √40)/3 = 1.2251 s.
        let t = enhanced_ttc(10.0, -10.0, 3.0).unwrap();
        assert!((t - (10.0 - 40f64.sqrt()) / 3.0).abs() < 1e-12);
        // From 20 m the same braking avoids the meeting: 100 − 120 < 0.
        assert_eq!(enhanced_ttc(20.0, -10.0, 3.0), None);
        assert_eq!(normalised_ettc(20.0, -10.0, 0.0, 100.0), 0.02);
        assert_eq!(normalised_ettc(20.0, 10.0, 0.0, 100.0), 1.0);
    }

    #[test]
    fn leader_much_slower_and_close_means_an_accident() {
        let idm = VehicleModel::builtin("idm").unwrap();
        let s = CutInPreset::PaperCode.settings();
        // Leader at 0 m/s, 3 m ahead: even full braking cannot stop in time.
        let run = s.run(&idm, 3.0, -20.0, 100.0);
        assert!(run.accident);
        assert_eq!(run.accident_step, Some(1));
        // Leader faster than us and far ahead: safe, and no meeting ever predicted.
        let run = s.run(&idm, 60.0, 2.0, 100.0);
        assert!(!run.accident);
        assert_eq!(run.mnp_ettc, 1.0);
    }

    #[test]
    fn hand_worked_steps_with_full_braking() {
        // R = 10, Ṙ = −10 (leader at 10 m/s, VUT at 20). The IDM brakes at the
        // clip −3: after step 1 the gap is 10 − 10·1 + 3/2 = 1.5 m and v = 17;
        // after step 2 it is 1.5 − 7 + 1.5 = −4: an accident at step 2.
        let idm = VehicleModel::builtin("idm").unwrap();
        let one_step = CutInSettings {
            steps: 1,
            ..CutInPreset::PaperCode.settings()
        };
        let run = one_step.run(&idm, 10.0, -10.0, 100.0);
        assert!(!run.accident);
        // ETTC before step 1 with u_r = 3: (10 − √40)/3 s, normalised by 100.
        let expected = (10.0 - 40f64.sqrt()) / 3.0 / 100.0;
        assert!((run.mnp_ettc - expected).abs() < 1e-12);
        let run = CutInPreset::PaperCode
            .settings()
            .run(&idm, 10.0, -10.0, 100.0);
        assert_eq!(run.accident_step, Some(2));
        assert_eq!(run.mnp_ettc, 0.0);
    }

    #[test]
    fn paper_table_counts_a_gap_below_one_metre_at_the_start() {
        let idm = VehicleModel::builtin("idm").unwrap();
        let run = CutInPreset::PaperTable
            .settings()
            .run(&idm, 0.74, 5.0, 100.0);
        assert_eq!(run.accident_step, Some(0));
        // paper-code counts only R ≤ 0, and a faster leader pulls away.
        let code = CutInPreset::PaperCode
            .settings()
            .run(&idm, 0.74, 5.0, 100.0);
        assert_eq!(code.accident_step, None);
    }

    /// A driver that always commands full braking.
    struct Brake;

    impl FollowDriver for Brake {
        type Error = std::convert::Infallible;
        fn decide(&mut self, _: &FollowStep) -> Result<f64, Self::Error> {
            Ok(-3.0)
        }
    }

    #[test]
    fn the_speed_floor_acts_as_each_preset_says() {
        // Full braking from 20 m/s: speeds 17, 14, …, 2, then the step
        // from 2 m/s. The authors' update (paper-code) applies the whole
        // −3 m/s² to that step (x += 2 − 1.5 = 0.5 m) and clips the speed to
        // 0; limiting the acceleration to −2 m/s² advances 1 m.
        let code = CutInPreset::PaperCode.settings();
        assert_eq!(code.speed_bound, SpeedBound::ClipsSpeed);
        let limited = CutInSettings {
            speed_bound: SpeedBound::LimitsAcceleration,
            ..code
        };
        // Leader at 0 m/s (Ṙ = −20): the follower stops after 66.5 m with the
        // authors' update (7 steps of 3 m/s², then 0.5 m) and after 67 m
        // with the limited one. A gap of 66.75 m separates them.
        let run = |s: &CutInSettings| s.run_with(&mut Brake, 66.75, -20.0, 100.0).unwrap();
        assert_eq!(run(&code).accident_step, None);
        assert_eq!(run(&limited).accident_step, Some(7));
        // Stopped, neither creeps on: a far leader is never reached.
        let far = |s: &CutInSettings| s.run_with(&mut Brake, 80.0, -20.0, 100.0).unwrap();
        assert!(!far(&code).accident && !far(&limited).accident);
    }
}
