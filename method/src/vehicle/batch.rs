//! Followers run side by side: [`LANES`] vehicles' observations as arrays
//! (structure of arrays), so that the compiler turns an acceleration of
//! every lane into vector instructions. Each lane performs the scalar
//! model's operations in its order ([`crate::vehicle::IdmParams::acceleration`],
//! [`crate::vehicle::FvdmParams::acceleration`]), so a lane's acceleration is
//! the scalar one bit for bit. Used by the cut-in and car-following batches.

use super::tanh::tanh;
use super::{VehicleModel, VehicleSpec};

/// Scenarios per batch: four SSE2 registers of two `f64`.
pub const LANES: usize = 8;

/// One quantity of every lane.
pub type Lanes = [f64; LANES];

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
        if vehicle.is_noisy() {
            // Each test of a noisy model draws its own noise: one by one.
            return None;
        }
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
    pub fn accelerations(&self, speed: &Lanes, lead: &Lanes, gap: &Lanes, a: &mut Lanes) {
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
                    let optimal = p.v1 + p.v2 * tanh(p.c1 * (gap[i] - p.length) - p.c2);
                    a[i] = p.k * (optimal - speed[i]);
                }
            }
        }
    }
}

/// `(v/v₀)^n` per lane by square-and-multiply, the operations of
/// [`crate::vehicle::power::pow_whole`] lane by lane.
#[inline(always)]
pub fn whole_powers(speed: &Lanes, v0: f64, mut n: u32, out: &mut Lanes) {
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
pub fn clamp(x: f64, lo: f64, hi: f64) -> f64 {
    let x = if x < lo { lo } else { x };
    if x > hi {
        hi
    } else {
        x
    }
}
