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
use crate::vehicle::{VehicleModel, VehicleSpec};

/// Scenarios per batch: four SSE2 registers of two `f64`.
pub const LANES: usize = 8;

type Lanes = [f64; LANES];

/// A follower the batch can run.
#[derive(Debug, Clone, Copy)]
pub struct BatchFollower(Follower);

#[derive(Debug, Clone, Copy)]
enum Follower {
    /// The IDM, with `2√(αb)` computed once and δ split into a whole
    /// exponent (squaring) or a real one (`powf`).
    Idm {
        alpha: f64,
        v0: f64,
        whole_delta: Option<u32>,
        delta: f64,
        s0: f64,
        length: f64,
        headway: f64,
        two_sqrt_ab: f64,
    },
    /// The FVDM.
    Fvdm(crate::vehicle::FvdmParams),
}

impl BatchFollower {
    /// The batch form of `vehicle`, when it has one.
    pub fn of(vehicle: &VehicleModel) -> Option<Self> {
        match vehicle.spec() {
            VehicleSpec::Idm(p) => Some(BatchFollower(Follower::Idm {
                alpha: p.alpha,
                v0: p.v0,
                whole_delta: (p.delta.fract() == 0.0 && (1.0..=64.0).contains(&p.delta))
                    .then_some(p.delta as u32),
                delta: p.delta,
                s0: p.s0,
                length: p.length,
                headway: p.headway,
                two_sqrt_ab: 2.0 * (p.alpha * p.b).sqrt(),
            })),
            VehicleSpec::Fvdm(p) => Some(BatchFollower(Follower::Fvdm(*p))),
            _ => None,
        }
    }

    /// Each lane's acceleration (before the simulation's clamps), as
    /// [`crate::vehicle::IdmParams::acceleration`] and
    /// [`crate::vehicle::FvdmParams::acceleration`] compute it.
    #[inline(always)]
    fn accelerations(&self, speed: &Lanes, lead: &Lanes, gap: &Lanes, a: &mut Lanes) {
        match self.0 {
            Follower::Idm {
                alpha,
                v0,
                whole_delta,
                delta,
                s0,
                length,
                headway,
                two_sqrt_ab,
            } => {
                let mut free = [0.0; LANES];
                match whole_delta {
                    Some(n) => whole_powers(speed, v0, n, &mut free),
                    None => {
                        for i in 0..LANES {
                            free[i] = (speed[i] / v0).powf(delta);
                        }
                    }
                }
                for i in 0..LANES {
                    let v = speed[i];
                    let desired = s0 + v * headway + v * (v - lead[i]) / two_sqrt_ab;
                    let interaction = desired / (gap[i] - length);
                    let x = alpha * (1.0 - free[i] - interaction * interaction);
                    a[i] = if x.is_nan() { f64::NEG_INFINITY } else { x };
                }
            }
            Follower::Fvdm(p) => {
                for i in 0..LANES {
                    let optimal = p.v1 + p.v2 * (p.c1 * (gap[i] - p.length) - p.c2).tanh();
                    a[i] = p.k * (optimal - speed[i]);
                }
            }
        }
    }
}

/// `(v/v₀)^n` per lane by square-and-multiply, the operations of
/// [`crate::vehicle::power::pow_whole`] lane by lane.
#[inline(always)]
fn whole_powers(speed: &Lanes, v0: f64, mut n: u32, out: &mut Lanes) {
    let mut base = [0.0; LANES];
    for i in 0..LANES {
        base[i] = speed[i] / v0;
        out[i] = 1.0;
    }
    loop {
        if n & 1 == 1 {
            for i in 0..LANES {
                out[i] *= base[i];
            }
        }
        n >>= 1;
        if n == 0 {
            return;
        }
        for b in &mut base {
            *b *= *b;
        }
    }
}

/// `f64::clamp`'s operations (`if x < lo {lo}; if x > hi {hi}`), written
/// out so they vectorise.
#[inline(always)]
fn clamp(x: f64, lo: f64, hi: f64) -> f64 {
    let x = if x < lo { lo } else { x };
    if x > hi {
        hi
    } else {
        x
    }
}

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

#[inline(always)]
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

#[cfg(test)]
mod tests {
    use crate::case::Case;
    use crate::cases::cutin::{CutIn, CutInPreset};
    use crate::vehicle::{VehicleModel, VehicleSpec};

    /// Every cell of the built-in grid, batched against one by one.
    fn batched_equals_scalar(case: &CutIn, vehicle: &VehicleModel) -> usize {
        let cells: Vec<usize> = (0..case.grid().len()).collect();
        let mut batched = vec![false; cells.len()];
        case.events(vehicle, &cells, &mut batched);
        for &cell in &cells {
            assert_eq!(
                batched[cell],
                case.run(vehicle, cell).accident,
                "cell {cell}, {:?}, {vehicle:?}",
                case.preset()
            );
        }
        // Out of order and a batch cut short by the end of the list.
        let odd: Vec<usize> = cells.iter().rev().step_by(3).copied().take(13).collect();
        let mut some = vec![false; odd.len()];
        case.events(vehicle, &odd, &mut some);
        for (event, &cell) in some.iter().zip(&odd) {
            assert_eq!(*event, batched[cell], "cell {cell}");
        }
        batched.iter().filter(|&&e| e).count()
    }

    #[test]
    fn batched_outcomes_are_the_scalar_ones_on_every_cell_of_every_preset() {
        let vehicles: Vec<VehicleModel> = [
            r#"{"model": "idm"}"#,
            r#"{"model": "fvdm"}"#,
            // A real exponent (powf) and other parameters.
            r#"{"model": "idm", "delta": 3.5, "v0": 30, "headway": 1.5}"#,
            r#"{"model": "idm", "delta": 1}"#,
            r#"{"model": "fvdm", "k": 0.6, "c2": 1.2}"#,
            // Stateful followers run one by one.
            r#"{"model": "switching-acc"}"#,
            r#"{"model": "acc-aeb"}"#,
        ]
        .iter()
        .map(|text| {
            let spec: VehicleSpec = serde_json::from_str(text).unwrap();
            VehicleModel::try_from(spec).unwrap()
        })
        .collect();
        for preset in [CutInPreset::PaperCode, CutInPreset::PaperTable] {
            let case = CutIn::builtin(preset);
            for vehicle in &vehicles {
                let events = batched_equals_scalar(&case, vehicle);
                // Neither trivially safe nor trivially failing.
                assert!(events > 0 && events < case.grid().len(), "{vehicle:?}");
            }
        }
    }
}
