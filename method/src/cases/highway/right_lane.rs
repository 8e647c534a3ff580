//! The right-lane tails of built-in drivers' runs, [`LANES`] side by side.
//!
//! Once a built-in driver has taken the VUT into the right lane, its action
//! is [`super::drivers::follow_in_right_lane`] (IDM behind the nearest BV
//! ahead) and the rest of the run depends only on the run's state: the
//! right lane holds about four fifths of a highway run's steps. One by one
//! such a step is bound by its instruction count (≈ 34 ns; four runs
//! interleaved, ≈ 30 ns). Here the tails run as arrays over lanes
//! (structure of arrays) that the compiler turns into vector instructions;
//! a lane whose run ends takes the next tail, so no lane idles while tails
//! are left.
//!
//! Each lane performs the scalar step's operations in their order
//! ([`super::simulation::RunInProgress::step`] with
//! [`super::drivers::IdmSteps`]): the nearest BV ahead by `(position,
//! speed)`, `free − α (s*/s)²` (`−∞` for a gap ≤ 0), the clamps of
//! `f64::clamp`, `p += v Δt + ½ a Δt²`, `v ← max(0, v + a Δt)`, the BVs' car-following
//! rule, then the overlap and exit tests. The branches become selects,
//! which compute both sides and keep one, so every record is the scalar
//! one, bit for bit (tested on every coarse cell and an eighth of the
//! paper grid per vehicle, and on other worlds; the highway benchmark
//! checks every paper cell).

use super::drivers::IdmSteps;
use super::simulation::{ExitOutcome, ExitRun, RunInProgress};
use super::world::ExitWorld;
use crate::vehicle::batch::{clamp, whole_powers, Lanes, LANES};
use crate::vehicle::power::whole;

/// A run that has entered the right lane, and its scenario's index.
#[derive(Debug, Clone, Copy)]
pub struct Tail {
    /// The scenario's index among those of the batch.
    pub index: usize,
    /// The run, in the right lane.
    pub run: RunInProgress,
}

/// The lanes' runs, one array per quantity.
struct TailLanes {
    p: Lanes,
    v: Lanes,
    /// The two BVs' positions and speeds.
    bp: [Lanes; 2],
    bs: [Lanes; 2],
    /// Steps taken and the time cap, as floats so that they vectorise.
    k: Lanes,
    cap: Lanes,
}

/// How each lane's step ended: 0 it goes on, else 1 + the outcome's place
/// in [`ENDINGS`].
type Endings = [u8; LANES];

const ENDINGS: [ExitOutcome; 3] = [
    ExitOutcome::FailedToExit,
    ExitOutcome::Collision,
    ExitOutcome::Exited,
];

impl TailLanes {
    fn load(&mut self, i: usize, run: &RunInProgress) {
        self.p[i] = run.p;
        self.v[i] = run.v;
        for b in 0..2 {
            self.bp[b][i] = run.traffic.bvs[b].position;
            self.bs[b][i] = run.traffic.bvs[b].speed;
        }
        self.k[i] = run.k as f64;
        self.cap[i] = run.steps as f64;
    }
}

/// Runs every tail to its end and calls `record(index, run)` as each ends.
/// All tails must come from drivers that follow with `idm`.
pub fn finish(
    world: &ExitWorld,
    idm: &IdmSteps,
    tails: &[Tail],
    record: &mut dyn FnMut(usize, ExitRun),
) {
    finish_dispatch(world, idm, tails, record);
}

/// Compiled for AVX2 as well, picked at run time (no FMA: a fused
/// multiply-add rounds once where the scalar path rounds twice).
#[multiversion::multiversion(targets("x86_64+avx2"))]
fn finish_dispatch(
    world: &ExitWorld,
    idm: &IdmSteps,
    tails: &[Tail],
    record: &mut dyn FnMut(usize, ExitRun),
) {
    let Some(first) = tails.first() else {
        return;
    };
    let mut lanes = TailLanes {
        p: [0.0; LANES],
        v: [0.0; LANES],
        bp: [[0.0; LANES]; 2],
        bs: [[0.0; LANES]; 2],
        k: [0.0; LANES],
        cap: [0.0; LANES],
    };
    // Which tail each lane runs; a lane with none runs a copy of the first
    // tail whose results are dropped.
    let mut running: [Option<usize>; LANES] = [None; LANES];
    let mut next = 0;
    for (i, slot) in running.iter_mut().enumerate() {
        if next < tails.len() {
            *slot = Some(next);
            lanes.load(i, &tails[next].run);
            next += 1;
        } else {
            lanes.load(i, &first.run);
        }
    }
    let whole_delta = whole(idm.idm().delta);
    let mut endings: Endings = [0; LANES];
    while running.iter().any(Option::is_some) {
        step(world, idm, whole_delta, &mut lanes, &mut endings);
        if endings.iter().all(|&e| e == 0) {
            continue;
        }
        for i in 0..LANES {
            let (ending, Some(t)) = (endings[i], running[i]) else {
                continue;
            };
            if ending == 0 {
                continue;
            }
            let outcome = ENDINGS[usize::from(ending - 1)];
            let steps = if outcome == ExitOutcome::FailedToExit {
                lanes.cap[i]
            } else {
                lanes.k[i]
            };
            record(
                tails[t].index,
                ExitRun {
                    outcome,
                    time: steps * world.dt,
                    lane_change: tails[t].run.lane_change,
                },
            );
            if next < tails.len() {
                running[i] = Some(next);
                lanes.load(i, &tails[next].run);
                next += 1;
            } else {
                running[i] = None;
            }
        }
    }
}

/// One step of every lane; `endings[i]` says whether and how lane `i`'s
/// run ended with it (its `k` then counts the steps of the record).
#[inline(always)]
fn step(
    world: &ExitWorld,
    idm: &IdmSteps,
    whole_delta: Option<u32>,
    s: &mut TailLanes,
    endings: &mut Endings,
) {
    let m = idm.idm();
    let (dt, length) = (world.dt, world.length);
    let mut power = [0.0; LANES];
    match whole_delta {
        Some(n) => whole_powers(&s.v, m.v0, n, &mut power),
        None => {
            for (power, v) in power.iter_mut().zip(&s.v) {
                *power = (v / m.v0).powf(m.delta);
            }
        }
    }
    let close = world.d_cf + 1e-9;
    for i in 0..LANES {
        let (p, v) = (s.p[i], s.v[i]);
        let (p0, p1, s0, s1) = (s.bp[0][i], s.bp[1][i], s.bs[0][i], s.bs[1][i]);
        // The nearest BV ahead: BV 1 when it is ahead and BV 0 is not, or
        // both are and (p₁, v₁) < (p₀, v₀).
        let (ahead0, ahead1) = (p0 >= p, p1 >= p);
        let one_nearer = p1 < p0 || (p1 == p0 && s1 < s0);
        let pick1 = ahead1 && (!ahead0 || one_nearer);
        let (lead_p, lead_s) = if pick1 { (p1, s1) } else { (p0, s0) };
        let gap = lead_p - p - length;
        let free = m.alpha * (1.0 - power[i]);
        let dynamic = v * m.headway + v * (v - lead_s) / idm.two_sqrt_ab();
        let desired = m.s0 + dynamic.max(0.0);
        let behind = free - m.alpha * (desired / gap).powi(2);
        let behind = if gap <= 0.0 {
            f64::NEG_INFINITY
        } else {
            behind
        };
        let accel = if ahead0 || ahead1 { behind } else { free };
        let followed = clamp(accel, world.emergency_brake, world.accel.1);
        let a = clamp(followed, world.emergency_brake, world.accel.1);
        let a = clamp(a, -v / dt, (world.speed.1 - v) / dt);
        let p = p + (v * dt + 0.5 * a * dt * dt);
        s.p[i] = p;
        s.v[i] = (v + a * dt).max(0.0);
        // The BVs: the rear one takes the front one's speed within d_cf.
        let one_front = p1 > p0 || (p1 == p0 && -s1 > -s0);
        let (fp, fs, rp, rs) = if one_front {
            (p1, s1, p0, s0)
        } else {
            (p0, s0, p1, s1)
        };
        let slows = fp - rp - length <= close && rs > fs;
        let s0 = if slows && one_front { fs } else { s0 };
        let s1 = if slows && !one_front { fs } else { s1 };
        let (p0, p1) = (p0 + s0 * dt, p1 + s1 * dt);
        s.bs[0][i] = s0;
        s.bs[1][i] = s1;
        s.bp[0][i] = p0;
        s.bp[1][i] = p1;
        let capped = s.k[i] >= s.cap[i];
        s.k[i] += 1.0;
        let collided = (p0 - p).abs() < length || (p1 - p).abs() < length;
        let exited = p >= world.exit;
        endings[i] = if capped {
            1
        } else if collided {
            2
        } else if exited {
            3
        } else {
            0
        };
    }
}
