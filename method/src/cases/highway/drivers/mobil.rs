//! The surrogate model: MOBIL gap acceptance (Kesting et al. 2007) with a
//! short-horizon predictive speed plan toward a gap, and IDM longitudinal
//! control.
//!
//! In the left lane, at every step:
//!
//! 1. **Merge now** if the right lane at the VUT's position is safe: the
//!    task's safe time gaps hold (`|p − b| − ℓ ≥ t_min u` for each BV) and
//!    MOBIL's safety criterion holds: neither the VUT behind its new
//!    leader nor the new follower behind the VUT would need to brake harder
//!    than `b_safe` (IDM accelerations `ã ≥ −b_safe`, `ã_new ≥ −b_safe`).
//!    The lane change is mandatory (the exit), so the incentive criterion is
//!    always met once it is safe.
//! 2. Otherwise follow a **speed plan**, renewed every `replan` seconds: for
//!    each constant acceleration `a_c` of a fixed set in `[a_min, a_max]`,
//!    predict the VUT (speeds kept in `[v_min, v_max]`) and the BVs
//!    (constant speeds) every `plan_step` seconds up to `plan_horizon`, and
//!    find the first instant `τ` before the exit at which merging passes the
//!    safety criterion. Its value is the MOBIL utility there,
//!    `U = ã − a + p (ã_new − a_new + ã_old − a_old)` (the left lane is empty,
//!    so the old-follower term is 0), minus `wait_cost · τ`. The plan with
//!    the largest value is applied; with none feasible the VUT cruises (IDM,
//!    free road).
//!
//! In the right lane the VUT follows the BV ahead by IDM. The BVs do not
//! react, so a merge in front of a faster BV that MOBIL judged safe (it
//! assumes the follower brakes up to `b_safe`) can still end in a collision.

use super::gaps::{follow_in_right_lane, safe_gaps, within_speed_bounds};
use super::idm::{Idm, IdmSteps};
use super::merge::{advance, Criterion, Predicted};
use super::view::{Action, DriverView, Lane};
use crate::cases::highway::world::{Bv, ExitWorld};
use crate::vehicle::{check, ParamError};
use serde::{Deserialize, Serialize};

/// Plan accelerations (m/s²), clamped to the world's bounds.
const PLAN_ACCELS: [f64; 10] = [-4.0, -3.0, -2.0, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0];

/// Parameters of the MOBIL driver (the highway-exit surrogate).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MobilParams {
    /// Politeness factor p.
    pub politeness: f64,
    /// Safe braking b_safe imposed on anyone by a lane change (m/s²).
    pub b_safe: f64,
    /// Time between plan renewals (s).
    pub replan: f64,
    /// Prediction step (s) and horizon (s) of the speed plan.
    pub plan_step: f64,
    /// Horizon of the speed plan (s).
    pub plan_horizon: f64,
    /// Utility lost per second of waiting for a gap (m/s² per s).
    pub wait_cost: f64,
    /// Bounds of the plan's accelerations (m/s²), within the world's.
    pub brake: f64,
    /// Upper bound of the plan's accelerations (m/s²).
    pub accelerate: f64,
    /// IDM: desired speed v₀ (m/s), headway T (s), jam gap s₀ (m),
    /// acceleration α and comfortable braking b (m/s²), exponent δ.
    pub v0: f64,
    /// IDM desired time headway T (s).
    pub headway: f64,
    /// IDM jam distance s₀ (m).
    pub s0: f64,
    /// IDM maximum acceleration α (m/s²).
    pub alpha: f64,
    /// IDM comfortable deceleration b (m/s²).
    pub b: f64,
    /// IDM acceleration exponent δ.
    pub delta: f64,
}

impl Default for MobilParams {
    fn default() -> Self {
        let idm = Idm::HIGHWAY;
        Self {
            politeness: 0.1,
            b_safe: 4.0,
            replan: 0.5,
            plan_step: 0.5,
            plan_horizon: 8.0,
            wait_cost: 0.2,
            brake: -4.0,
            accelerate: 2.0,
            v0: idm.v0,
            headway: idm.headway,
            s0: idm.s0,
            alpha: idm.alpha,
            b: idm.b,
            delta: idm.delta,
        }
    }
}

impl MobilParams {
    /// Checks every parameter is finite and in range.
    pub fn validate(&self) -> Result<(), ParamError> {
        let m = "mobil";
        check(
            m,
            "politeness",
            self.politeness,
            |x| (0.0..=1.0).contains(&x),
            "must be in [0, 1]",
        )?;
        check(m, "b_safe", self.b_safe, |x| x > 0.0, "must be > 0")?;
        check(m, "replan", self.replan, |x| x > 0.0, "must be > 0")?;
        check(
            m,
            "plan_step",
            self.plan_step,
            |x| x >= 0.05,
            "must be ≥ 0.05",
        )?;
        check(
            m,
            "plan_horizon",
            self.plan_horizon,
            |x| (0.0..=60.0).contains(&x),
            "must be in [0, 60]",
        )?;
        check(m, "wait_cost", self.wait_cost, |x| x >= 0.0, "must be ≥ 0")?;
        // The plan's accelerations are those of a fixed set (which holds 0)
        // within [brake, accelerate] and the world's bounds (which hold 0).
        check(m, "brake", self.brake, |x| x <= 0.0, "must be ≤ 0")?;
        check(
            m,
            "accelerate",
            self.accelerate,
            |x| x >= 0.0,
            "must be ≥ 0",
        )?;
        self.idm().validate(m)
    }

    /// The IDM these parameters describe.
    pub fn idm(&self) -> Idm {
        Idm {
            alpha: self.alpha,
            b: self.b,
            v0: self.v0,
            headway: self.headway,
            s0: self.s0,
            delta: self.delta,
        }
    }
}

#[derive(Debug, Clone)]
pub struct MobilDriver {
    params: MobilParams,
    criterion: Criterion,
    /// The plan's acceleration and when it is renewed.
    plan: Option<f64>,
    replan_at: f64,
    /// Prediction instants of a plan, `⌊plan_horizon / plan_step⌋`.
    points: usize,
    /// The BVs at each prediction instant of the plan being searched, with
    /// the positions each blocks (shared by every plan acceleration:
    /// computed once per replan, reused across replans).
    predicted: Vec<Predicted>,
}

impl MobilDriver {
    pub fn new(params: MobilParams) -> Self {
        let points = (params.plan_horizon / params.plan_step).floor() as usize;
        Self {
            criterion: Criterion {
                idm: IdmSteps::new(params.idm()),
                b_safe: params.b_safe,
                politeness: params.politeness,
            },
            params,
            plan: None,
            replan_at: 0.0,
            points,
            predicted: Vec::with_capacity(points),
        }
    }

    /// The IDM it follows with in the right lane ([`follow_in_right_lane`]).
    pub fn right_lane_idm(&self) -> &IdmSteps {
        &self.criterion.idm
    }

    pub fn act(&mut self, view: &DriverView) -> Action {
        let idm = &self.criterion.idm;
        if view.lane == Lane::Right {
            return Action {
                accel: follow_in_right_lane(idm, view),
                change_lane: false,
            };
        }
        let bvs = view.traffic.bvs;
        if self
            .merge_utility(view.world, view.position, view.speed, &bvs)
            .is_some()
        {
            return Action {
                accel: idm
                    .free(view.speed)
                    .clamp(view.world.accel.0, view.world.accel.1),
                change_lane: true,
            };
        }
        if self.plan.is_none() || view.time + 1e-9 >= self.replan_at {
            self.plan = self.best_plan(view);
            self.replan_at = view.time + self.params.replan;
        }
        let accel = self
            .plan
            .unwrap_or_else(|| self.criterion.idm.free(view.speed))
            .clamp(view.world.accel.0, view.world.accel.1);
        let accel = within_speed_bounds(view.world, view.speed, accel);
        Action {
            accel,
            change_lane: false,
        }
    }

    /// MOBIL at a (possibly predicted) state: `None` when merging is unsafe,
    /// else the utility `ã − a + p (ã_new − a_new)`.
    fn merge_utility(&self, world: &ExitWorld, p: f64, v: f64, bvs: &[Bv; 2]) -> Option<f64> {
        if !safe_gaps(world, bvs, p) {
            return None;
        }
        let c = &self.criterion;
        c.utility(world, p, v, bvs, |i| {
            let free = c.idm.free(bvs[i].speed);
            (free, c.before(world, bvs, i, free))
        })
    }

    /// The best constant-acceleration plan toward a safe merge, if any.
    ///
    /// The BVs' predicted positions and the positions they block depend on
    /// the instant only, so they are computed once for all plan
    /// accelerations, and so is a BV's acceleration before the change
    /// (once a plan needs it) and its free-road term (its speed is
    /// constant over the prediction); each plan then tests its own position
    /// against them, and runs MOBIL's criterion only where the gaps hold
    /// (the same arithmetic as [`Self::merge_utility`] at every point, so
    /// the same plan, bit for bit).
    fn best_plan(&mut self, view: &DriverView) -> Option<f64> {
        let world = view.world;
        let h = self.params.plan_step;
        let c = self.criterion;
        self.predicted.clear();
        for k in 1..=self.points {
            let tau = k as f64 * h;
            let bvs = view.traffic.bvs.map(|bv| Bv {
                position: bv.position + bv.speed * tau,
                speed: bv.speed,
            });
            self.predicted.push(Predicted::new(world, bvs));
        }
        let free = view.traffic.bvs.map(|bv| c.idm.free(bv.speed));
        let mut best: Option<(f64, f64)> = None;
        let (low, high) = (
            self.params.brake.max(world.accel.0),
            self.params.accelerate.min(world.accel.1),
        );
        if low > high || low.is_nan() || high.is_nan() {
            // A world whose bounds miss the plan's: no plan (validated
            // parameters and the built-in world always overlap).
            return None;
        }
        for a in PLAN_ACCELS.map(|a| a.clamp(low, high)) {
            let (mut p, mut v) = (view.position, view.speed);
            for (k, at) in (1..).zip(&mut self.predicted) {
                (p, v) = advance(world, p, v, a, h);
                if p >= world.exit {
                    break;
                }
                if !at.safe(p) {
                    continue;
                }
                let bvs = at.bvs;
                let before = &mut at.before;
                let follower = |i: usize| {
                    let before =
                        *before[i].get_or_insert_with(|| c.before(world, &bvs, i, free[i]));
                    (free[i], before)
                };
                if let Some(u) = c.utility(world, p, v, &bvs, follower) {
                    let tau = k as f64 * h;
                    let value = u - self.params.wait_cost * tau;
                    if best.is_none_or(|(_, b)| value > b) {
                        best = Some((a, value));
                    }
                    break;
                }
            }
        }
        best.map(|(a, _)| a)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cases::highway::world::Traffic;
    use rand::{Rng, SeedableRng};

    /// The plan search as the model states it: at every point of every
    /// plan, the BVs predicted afresh and [`MobilDriver::merge_utility`].
    fn plain_best_plan(driver: &MobilDriver, view: &DriverView) -> Option<f64> {
        let world = view.world;
        let h = driver.params.plan_step;
        let mut best: Option<(f64, f64)> = None;
        let (low, high) = (
            driver.params.brake.max(world.accel.0),
            driver.params.accelerate.min(world.accel.1),
        );
        for a in PLAN_ACCELS.map(|a| a.clamp(low, high)) {
            let (mut p, mut v) = (view.position, view.speed);
            for k in 1..=driver.points {
                let tau = k as f64 * h;
                (p, v) = advance(world, p, v, a, h);
                if p >= world.exit {
                    break;
                }
                let bvs = view.traffic.bvs.map(|bv| Bv {
                    position: bv.position + bv.speed * tau,
                    speed: bv.speed,
                });
                if let Some(u) = driver.merge_utility(world, p, v, &bvs) {
                    let value = u - driver.params.wait_cost * tau;
                    if best.is_none_or(|(_, b)| value > b) {
                        best = Some((a, value));
                    }
                    break;
                }
            }
        }
        best.map(|(a, _)| a)
    }

    /// The search with the BVs' predictions shared by all plan
    /// accelerations picks the same plan, to the bit, as the plain search,
    /// over random states for three parameter sets; and it finds a plan in
    /// a good share of them, so the comparison is not only of `None`s.
    #[test]
    fn the_shared_predictions_give_the_plain_search_s_plan() {
        let world = ExitWorld::paper();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let sets = [
            MobilParams::default(),
            MobilParams {
                politeness: 0.3,
                wait_cost: 0.5,
                ..MobilParams::default()
            },
            MobilParams {
                b_safe: 3.5,
                plan_step: 0.3,
                ..MobilParams::default()
            },
        ];
        for params in sets {
            let mut driver = MobilDriver::new(params);
            let mut found = 0;
            for _ in 0..20_000 {
                let traffic = Traffic::new([
                    rng.random_range(-50.0..world.exit),
                    rng.random_range(world.speed.0..=world.speed.1),
                    rng.random_range(-50.0..world.exit),
                    rng.random_range(world.speed.0..=world.speed.1),
                ]);
                let view = DriverView {
                    world: &world,
                    time: 0.0,
                    position: rng.random_range(0.0..world.exit),
                    speed: rng.random_range(world.speed.0..=world.speed.1),
                    lane: Lane::Left,
                    traffic: &traffic,
                };
                let plain = plain_best_plan(&driver, &view);
                let shared = driver.best_plan(&view);
                assert_eq!(
                    shared.map(f64::to_bits),
                    plain.map(f64::to_bits),
                    "{params:?} {view:?}"
                );
                found += usize::from(plain.is_some());
            }
            assert!(found > 2_000, "{found} plans found in 20,000 states");
        }
    }
}
