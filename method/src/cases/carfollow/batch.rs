//! Car-following tests in batches: [`LANES`] tests side by side. Each
//! lane draws its own initial state and BV actions from its own stream, as
//! [`FollowSampler::run`] does (the same code: [`FollowSampler::start`],
//! [`FollowSampler::draw_action`]); the ten steps between decisions run
//! for every lane at once, the vehicle's accelerations through
//! [`BatchFollower`], every quantity an array over the lanes, so that the
//! divisions and the model's arithmetic of eight tests go through vector
//! instructions instead of waiting on each other. Each lane performs
//! [`super::world::advance_with`]'s operations in its order, so a lane's
//! test is the scalar test bit for bit (tested): its accident, its weight
//! and its initial state. A lane that crashes stops drawing; the batch
//! ends when every lane has crashed or run its decisions.

use super::sampling::{FollowSampler, FollowTest};
use super::world::{FollowState, FollowWorld};
use crate::vehicle::batch::{clamp, Lanes};
pub use crate::vehicle::batch::{BatchFollower, LANES};

impl FollowSampler {
    /// Tests `indices` (at most [`LANES`]) of a campaign with seed `seed`
    /// on `follower`: what [`FollowSampler::run`] gives for each.
    pub fn run_batch(
        &self,
        follower: &BatchFollower,
        seed: u64,
        indices: &[u64],
    ) -> Vec<FollowTest> {
        assert!(indices.len() <= LANES, "at most {LANES} tests a batch");
        let world = *self.world();
        let n = indices.len();
        let mut streams: Vec<_> = indices.iter().map(|&i| self.start(seed, i)).collect();
        let mut states: Vec<FollowState> = streams
            .iter()
            .map(|&(_, s1, _)| self.grid().state(s1))
            .collect();
        let mut alive = [false; LANES];
        let mut accident = [false; LANES];
        alive[..n].fill(true);
        let mut mixed = vec![0.0; world.actions];
        let mut u: Lanes = [0.0; LANES];
        let (mut bv, mut own, mut range): (Lanes, Lanes, Lanes) =
            ([0.0; LANES], [0.0; LANES], [0.0; LANES]);
        for _ in 0..world.decisions {
            if !alive.iter().any(|&a| a) {
                break;
            }
            for lane in 0..n {
                if !alive[lane] {
                    continue;
                }
                let (rng, _, log_weight) = &mut streams[lane];
                let x = states[lane];
                let k = self.draw_action(&x, rng, &mut mixed, log_weight);
                u[lane] = world.action(k);
                bv[lane] = x.bv_speed;
                own[lane] = x.vut_speed();
                range[lane] = x.range;
            }
            // A crashed (or unused) lane keeps computing on its last
            // values; nothing of it is read again.
            let mut crashed = [false; LANES];
            let done = |crashed: &[bool; LANES]| (0..n).all(|lane| !alive[lane] || crashed[lane]);
            steps(
                &world,
                follower,
                &u,
                (&mut bv, &mut own, &mut range),
                &mut crashed,
                &done,
            );
            for lane in 0..n {
                if !alive[lane] {
                    continue;
                }
                if crashed[lane] {
                    alive[lane] = false;
                    accident[lane] = true;
                } else {
                    states[lane] = FollowState {
                        bv_speed: bv[lane],
                        range: range[lane],
                        range_rate: bv[lane] - own[lane],
                    };
                }
            }
        }
        streams
            .into_iter()
            .enumerate()
            .map(|(lane, (_, s1, log_weight))| FollowTest {
                accident: accident[lane],
                log_weight,
                initial_state: s1,
            })
            .collect()
    }
}

/// The steps of one decision for every lane, until they are done or
/// `done(crashed)`; compiled for AVX2 as well, picked at run time (no FMA:
/// it would round once where the scalar path rounds twice).
#[multiversion::multiversion(targets("x86_64+avx2"))]
fn steps(
    world: &FollowWorld,
    follower: &BatchFollower,
    u: &Lanes,
    (bv, own, range): (&mut Lanes, &mut Lanes, &mut Lanes),
    crashed: &mut [bool; LANES],
    done: &dyn Fn(&[bool; LANES]) -> bool,
) {
    let (dt, (a_lo, a_hi), (v_lo, v_hi)) = (world.dt, world.vut_accel, world.vut_speed);
    let (bv_lo, bv_hi) = world.bv_speed;
    let mut a_own: Lanes = [0.0; LANES];
    for _ in 0..world.steps_per_decision {
        follower.accelerations(own, bv, range, &mut a_own);
        for i in 0..LANES {
            let a_bv = clamp(u[i], (bv_lo - bv[i]) / dt, (bv_hi - bv[i]) / dt);
            let a = clamp(a_own[i], a_lo, a_hi);
            let a = clamp(a, (v_lo - own[i]) / dt, (v_hi - own[i]) / dt);
            range[i] += (bv[i] - own[i]) * dt + 0.5 * (a_bv - a) * dt * dt;
            bv[i] += a_bv * dt;
            own[i] += a * dt;
            crashed[i] |= range[i] <= world.accident_range;
        }
        if done(crashed) {
            return;
        }
    }
}
