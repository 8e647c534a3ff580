//! `tanh` for the FVDM's optimal speed, `V₁ + V₂ tanh(C₁(R − L) − C₂)`,
//! in basic IEEE operations only.
//!
//! The standard library's `tanh` is a call into the platform's libm, once
//! per vehicle and step: it cannot be vectorised across the scenarios a
//! batch runs side by side, and its last bits are the libm's, so two
//! machines with different libms could disagree on a knife-edge test (the
//! coordinator replays built-in vehicles and compares outcomes bit for
//! bit). This one is additions, multiplications, one division and bit
//! operations, so it gives the same bits on every build and target, and
//! the compiler turns a loop of it into vector instructions.
//!
//! `tanh x = expm1(2x) / (expm1(2x) + 2)`, accurate for small `|x|` too
//! (no cancellation, unlike `1 − 2/(e^{2x} + 1)`). `expm1 y = 2ⁿ(1 + p(r))
//! − 1 = 2ⁿ p(r) + (2ⁿ − 1)` with `n = round(y / ln 2)`, `r = y − n ln 2`
//! (Cody and Waite: `ln 2` in two parts, the first with trailing zeros so
//! `n ln2_hi` is exact), `|r| ≤ ln 2 / 2`, and `p(r) = Σ_{k=1}^{13} r^k/k!`,
//! whose remainder `r¹⁴/14!` is below 4 × 10⁻¹⁸. It runs on `|x|`,
//! clamped to 20 (where `tanh` is 1 to within 10⁻¹⁷), and takes `x`'s sign. The error is within a few units in
//! the last place of `std`'s `tanh` (test).

/// `|x|` beyond which `tanh x` rounds to `±1`.
const SATURATION: f64 = 20.0;

const LOG2_E: f64 = std::f64::consts::LOG2_E;
/// `ln 2 = LN2_HI + LN2_LO`, `LN2_HI` with 32 trailing zero bits.
const LN2_HI: f64 = f64::from_bits(0x3FE6_2E42_FEE0_0000);
const LN2_LO: f64 = f64::from_bits(0x3DEA_39EF_3579_3C76);

/// `1.5 × 2⁵²`: adding it rounds a number of magnitude below 2⁵¹ to an
/// integer, which then sits in the low bits of the sum's representation.
const ROUNDER: f64 = 6_755_399_441_055_744.0;

/// `1/k!` for `k = 13, 12, …, 2`, Horner's order.
const INVERSE_FACTORIALS: [f64; 12] = [
    1.0 / 6_227_020_800.0,
    1.0 / 479_001_600.0,
    1.0 / 39_916_800.0,
    1.0 / 3_628_800.0,
    1.0 / 362_880.0,
    1.0 / 40_320.0,
    1.0 / 5_040.0,
    1.0 / 720.0,
    1.0 / 120.0,
    1.0 / 24.0,
    1.0 / 6.0,
    1.0 / 2.0,
];

/// The hyperbolic tangent of `x` (see the module documentation), computed
/// on `|x|` and given `x`'s sign, so it is exactly odd.
#[inline(always)]
pub fn tanh(x: f64) -> f64 {
    let a = x.abs();
    let a = if a > SATURATION { SATURATION } else { a };
    let y = 2.0 * a;
    let shifted = y * LOG2_E + ROUNDER;
    let n = shifted - ROUNDER;
    let r = (y - n * LN2_HI) - n * LN2_LO;
    let mut q = INVERSE_FACTORIALS[0];
    for c in &INVERSE_FACTORIALS[1..] {
        q = q * r + c;
    }
    // p(r) = r + r² q(r).
    let p = r + r * r * q;
    // 2ⁿ from the rounded sum's low bits: n + 1023 is the biased exponent.
    let two_n = f64::from_bits(shifted.to_bits().wrapping_add(1023) << 52);
    let expm1 = two_n * p + (two_n - 1.0);
    (expm1 / (expm1 + 2.0)).copysign(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Units in the last place between `a` and `b`.
    fn ulps(a: f64, b: f64) -> u64 {
        let key = |v: f64| {
            let bits = v.to_bits() as i64;
            if bits < 0 {
                i64::MIN - bits
            } else {
                bits
            }
        };
        key(a).abs_diff(key(b))
    }

    #[test]
    fn it_is_std_tanh_to_a_few_units_in_the_last_place() {
        let mut worst = 0;
        let mut x = -25.0;
        while x < 25.0 {
            let (ours, std) = (tanh(x), x.tanh());
            let off = ulps(ours, std);
            assert!(
                off <= 4 || (ours - std).abs() <= 1e-17,
                "tanh({x:e}) = {ours:e}, std {std:e}"
            );
            worst = worst.max(off);
            x += 0.000_731;
        }
        assert!(worst <= 4, "{worst} ulps");
        // Small arguments keep their relative accuracy.
        for x in [1e-300, -3e-200, 1e-17, 2.5e-9, -1e-5, 0.01] {
            assert!(ulps(tanh(x), x.tanh()) <= 4, "{x:e}: {:e}", tanh(x));
        }
        assert_eq!(tanh(0.0), 0.0);
        assert_eq!(tanh(20.0), 1.0);
        assert_eq!(tanh(-1e9), -1.0);
        assert_eq!(tanh(f64::INFINITY), 1.0);
        assert!(tanh(f64::NAN).is_nan());
    }

    #[test]
    fn it_is_odd() {
        let mut x = 0.0;
        while x < 21.0 {
            assert_eq!(tanh(-x), -tanh(x), "{x}");
            x += 0.0137;
        }
    }
}
