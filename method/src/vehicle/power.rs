//! `x^δ` for the free-road term of the IDM family, `1 − (v/v₀)^δ`.
//!
//! Every calibration here has a whole δ (4); `powf` costs about 20 ns,
//! squaring two multiplications. Square-and-multiply is written out rather
//! than left to `powi`, whose expansion LLVM may choose differently by
//! target and optimisation level: the outcome of a run must not depend on
//! the build (libraries, replays and audits compare outcomes bit for bit).

/// The largest exponent taken by squaring.
const MAX_WHOLE: u32 = 64;

/// `x^n` by square-and-multiply (`n ≥ 1`).
#[inline]
pub fn pow_whole(x: f64, mut n: u32) -> f64 {
    let mut result = 1.0;
    let mut base = x;
    loop {
        if n & 1 == 1 {
            result *= base;
        }
        n >>= 1;
        if n == 0 {
            return result;
        }
        base *= base;
    }
}

/// `x^δ`: [`pow_whole`] when δ is a whole number in `1..=64`, else `powf`.
#[inline]
pub fn pow(x: f64, delta: f64) -> f64 {
    match whole(delta) {
        Some(n) => pow_whole(x, n),
        None => x.powf(delta),
    }
}

/// δ as the whole exponent [`pow`] squares by, if it is one (`1..=64`).
#[inline]
pub fn whole(delta: f64) -> Option<u32> {
    // Whole when the conversion is exact (`as` saturates: NaN and negative
    // δ give 0, which is not in range). Not `delta.fract()`: without
    // SSE4.1 that is a call to libm's `trunc` at every step.
    let whole = delta as u32;
    (f64::from(whole) == delta && (1..=MAX_WHOLE).contains(&whole)).then_some(whole)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn whole_powers_are_products_and_others_powf() {
        assert_eq!(pow(1.5, 4.0), 1.5 * 1.5 * (1.5 * 1.5));
        assert_eq!(pow(2.0, 10.0), 1024.0);
        assert_eq!(pow(-2.0, 3.0), -8.0);
        assert_eq!(pow(0.9, 1.0), 0.9);
        assert_eq!(pow(1.1, 2.5), 1.1f64.powf(2.5));
        assert_eq!(pow(1.1, 100.0), 1.1f64.powf(100.0));
        // Exponents that are not whole in 1..=64 go to powf, also those
        // that saturate the conversion.
        for delta in [0.0, -2.0, 0.5, 64.5, 65.0, 4294967296.0, 1e300] {
            assert_eq!(pow(1.1, delta), 1.1f64.powf(delta), "{delta}");
        }
        assert_eq!(pow(1.1, 64.0), pow_whole(1.1, 64));
        assert!(pow(1.1, f64::NAN).is_nan());
        // Within a few ulps of powf on the speeds the models meet.
        for i in 0..=4000 {
            let x = i as f64 / 1000.0;
            let (a, b) = (pow(x, 4.0), x.powf(4.0));
            assert!((a - b).abs() <= 4.0 * f64::EPSILON * b, "{x}: {a} {b}");
        }
    }
}
