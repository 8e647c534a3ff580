//! The secret sample: which reported tests the coordinator checks.
//!
//! Each test of a report's range is chosen independently with probability
//! `share`, by a generator seeded by the operating system when the
//! coordinator starts (ChaCha12, `rand`'s `StdRng`), so a worker cannot
//! know which of its tests will be run again, and a worker hiding `k`
//! events escapes with probability `(1 − share)^k` (docs/operations.md).
//!
//! Two exact ways to draw the same thing, whichever costs less:
//!
//! - **Byte by byte** for `1/16 ≤ share ≤ 1/2` (the replay's default 0.1):
//!   test `i` is chosen when `Uᵢ < share`, with `Uᵢ` uniform on [0, 1),
//!   compared a byte at a time. Write `p = share · 2⁶⁴` (an integer for
//!   `share ≥ 2⁻¹¹`), `t` its top byte and `r` its low 56 bits. The first
//!   random byte `b` of the test decides at once when `b ≠ t` (chosen when
//!   `b < t`); on `b = t` (one time in 256) 56 more random bits `R` decide
//!   (chosen when `R < r`). So `P(chosen) = t/256 + r/2⁶⁴ = share`, exactly.
//!   Eight tests' first bytes are compared in one 64-bit word (the bytes'
//!   high bits kept apart so no borrow crosses a byte), and the chosen
//!   tests of 64 at a time are read off one mask: about 0.6 ns a test
//!   (0.28 ns of it the random byte), 6 ns a chosen test at 0.1.
//! - **By gaps** otherwise (shares below 1/16, and above 1/2): the gaps
//!   between chosen tests are geometric, `⌊ln(1 − U)/ln(1 − share)⌋`
//!   (exact up to the rounding of a 53-bit uniform and a logarithm), so the
//!   cost is in the chosen tests (about 13 ns each), not in the range; for
//!   small shares (the audit's 0.01) that is far cheaper than a byte a
//!   test.

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::sync::Mutex;

/// Below this share a test's random byte costs about what the gaps do
/// (0.6 ns a test against 13 ns a chosen test: even near 0.05); the
/// byte-wise draw's arithmetic is exact from `2⁻¹¹` up.
const BYTEWISE_FROM: f64 = 1.0 / 16.0;

/// Above this share a test's first byte no longer fits the comparison's
/// borrow-free range (`t ≤ 128`).
const BYTEWISE_TO: f64 = 0.5;

/// Random words drawn at once: 4,096 tests' first bytes.
const WORDS: usize = 512;

/// The high bit of each byte of a word.
const HIGH: u64 = 0x8080_8080_8080_8080;

/// The low seven bits of each byte.
const LOW7: u64 = 0x7f7f_7f7f_7f7f_7f7f;

/// One in each byte.
const ONES: u64 = 0x0101_0101_0101_0101;

/// Which tests are checked: drawn when a report arrives, from a generator
/// seeded by the operating system when the coordinator starts, so a worker
/// cannot know which of its tests will be run again.
pub struct Sampler {
    rng: Mutex<StdRng>,
}

impl Default for Sampler {
    fn default() -> Self {
        Self {
            rng: Mutex::new(StdRng::from_os_rng()),
        }
    }
}

impl Sampler {
    /// A sampler whose draws `seed` fixes: for tests, which must not fail
    /// by chance one run in ten thousand.
    #[cfg(test)]
    fn seeded(seed: u64) -> Self {
        Self {
            rng: Mutex::new(StdRng::seed_from_u64(seed)),
        }
    }

    /// The indices of `from..to` each chosen with probability `share`,
    /// independently, in increasing order.
    pub fn pick(&self, share: f64, from: u64, to: u64) -> Vec<u64> {
        if share.is_nan() || share <= 0.0 || from >= to {
            return Vec::new();
        }
        if share >= 1.0 {
            return (from..to).collect();
        }
        // A generator of this draw's own, seeded from the shared one: the
        // lock is held for the seed, not for the draw (milliseconds for a
        // report of 2²² tests, while other reports wait to be checked).
        let mut rng = {
            let mut shared = self.rng.lock().unwrap_or_else(|p| p.into_inner());
            StdRng::from_rng(&mut *shared)
        };
        if (BYTEWISE_FROM..=BYTEWISE_TO).contains(&share) {
            bytewise(&mut rng, share, from, to)
        } else {
            by_gaps(&mut rng, share, from, to)
        }
    }
}

/// [`Sampler::pick`] by geometric gaps.
fn by_gaps(rng: &mut impl Rng, share: f64, from: u64, to: u64) -> Vec<u64> {
    let log_miss = (1.0 - share).ln();
    let mut picked = Vec::new();
    let mut at = from;
    while at < to {
        let u: f64 = rng.random();
        let gap = ((1.0 - u).ln() / log_miss).floor();
        if gap.is_nan() || gap >= (to - at) as f64 {
            break;
        }
        at += gap as u64;
        picked.push(at);
        at += 1;
    }
    picked
}

/// `share · 2⁶⁴` as its top byte and its low 56 bits, exact for
/// `2⁻¹¹ ≤ share < 1` (the product is then an integer below 2⁶⁴).
fn threshold(share: f64) -> (u8, u64) {
    let p = (share * 2f64.powi(64)) as u64;
    ((p >> 56) as u8, p & ((1 << 56) - 1))
}

/// The high bit of byte `k` of the result is set where byte `k` of `x` is
/// below `t` (for `t ≤ 128`): `x | 0x80` less `t` cannot borrow from the
/// next byte, and its high bit stays set exactly where `x`'s low seven
/// bits reach `t`.
fn bytes_below(x: u64, t: u8) -> u64 {
    !((x | HIGH).wrapping_sub(u64::from(t) * ONES)) & !x & HIGH
}

/// The high bit of byte `k` is set where byte `k` of `x` equals `t`:
/// `z = x ^ t` is zero there, and `(z & 0x7f) + 0x7f` (no carry out of
/// the byte) or `z` has its high bit clear only there.
fn bytes_equal(x: u64, t: u8) -> u64 {
    let z = x ^ (u64::from(t) * ONES);
    !(((z & LOW7).wrapping_add(LOW7)) | z) & HIGH
}

/// [`Sampler::pick`] byte by byte, for `BYTEWISE_FROM ≤ share ≤
/// BYTEWISE_TO` (see the module's documentation).
fn bytewise(rng: &mut impl Rng, share: f64, from: u64, to: u64) -> Vec<u64> {
    let (t, rest) = threshold(share);
    let expected = (to - from) as f64 * share;
    // Room for all but one sample in 10⁴ (4 sd), within reason.
    let room = (expected + 4.0 * expected.sqrt()).min(f64::from(1 << 24));
    let mut picked = Vec::with_capacity(room as usize + 8);
    let mut words = [0u64; WORDS];
    let mut at = from;
    while at < to {
        let tests = (to - at).min(8 * WORDS as u64);
        // Whole groups of 64 tests (words past the range are drawn and
        // masked off): every test of a group takes a byte of its own.
        let words = &mut words[..(tests as usize).div_ceil(64) * 8];
        rng.fill(&mut *words);
        for (group, eight) in words.chunks_exact(8).enumerate() {
            let mut chosen = 0u64;
            let mut ties = 0u64;
            // Test `base + 8j + k` takes byte `j` of word `k` (any fixed
            // assignment of the random bytes would do): so the flag of
            // byte j of word k, at bit 8j + 7, moves to bit 8j + k, and the
            // set bits of the group's mask are its chosen tests in order.
            for (k, &x) in eight.iter().enumerate() {
                chosen |= bytes_below(x, t) >> (7 - k);
                ties |= bytes_equal(x, t) >> (7 - k);
            }
            // One test in 256: 56 more bits decide.
            while ties != 0 {
                let bit = ties & ties.wrapping_neg();
                ties ^= bit;
                if rng.next_u64() >> 8 < rest {
                    chosen |= bit;
                }
            }
            let base = at + 64 * group as u64;
            if to - base < 64 {
                chosen &= (1 << (to - base)) - 1;
            }
            while chosen != 0 {
                picked.push(base + u64::from(chosen.trailing_zeros()));
                chosen &= chosen - 1;
            }
        }
        at += tests;
    }
    picked
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::RngCore;

    /// Every byte value at every position against every threshold the
    /// byte-wise draw uses: the word arithmetic is the plain comparison.
    #[test]
    fn the_word_comparisons_are_the_byte_comparisons_for_every_byte_and_threshold() {
        for t in 0..=128u8 {
            for b in 0..=255u8 {
                for k in 0..8 {
                    // The other bytes: values around the threshold, which
                    // would carry or borrow into byte k if anything did.
                    let others = [
                        0u8,
                        0x7f,
                        0x80,
                        0xff,
                        t,
                        t.wrapping_sub(1),
                        t.wrapping_add(1),
                    ];
                    for &o in &others {
                        let mut bytes = [o; 8];
                        bytes[k] = b;
                        let x = u64::from_le_bytes(bytes);
                        let below = bytes_below(x, t);
                        let equal = bytes_equal(x, t);
                        for (j, &byte) in bytes.iter().enumerate() {
                            assert_eq!(below >> (8 * j + 7) & 1 == 1, byte < t, "{x:x} < {t}");
                            assert_eq!(equal >> (8 * j + 7) & 1 == 1, byte == t, "{x:x} = {t}");
                        }
                        assert_eq!(below & !HIGH, 0);
                        assert_eq!(equal & !HIGH, 0);
                    }
                }
            }
        }
    }

    /// The word-wise draw against the rule written out test by test, on
    /// the same random stream: test `base + 8j + k` of a group of 64 takes
    /// byte `j` of the group's word `k`; below `t` it is chosen, at `t`
    /// the next 56 random bits decide, the group's ties in test order.
    fn bytewise_test_by_test(rng: &mut StdRng, share: f64, from: u64, to: u64) -> Vec<u64> {
        let (t, rest) = threshold(share);
        let mut picked = Vec::new();
        let mut at = from;
        while at < to {
            let tests = (to - at).min(8 * WORDS as u64);
            let mut words = vec![0u64; (tests as usize).div_ceil(64) * 8];
            rng.fill(&mut words[..]);
            for (group, eight) in words.chunks(8).enumerate() {
                let byte = |m: usize| eight[m % 8].to_le_bytes()[m / 8];
                let chosen: Vec<bool> = (0..64)
                    .map(|m| match byte(m) {
                        b if b == t => rng.next_u64() >> 8 < rest,
                        b => b < t,
                    })
                    .collect();
                let base = at + 64 * group as u64;
                picked.extend((0..64).filter(|&m| chosen[m]).map(|m| base + m as u64));
            }
            at += tests;
        }
        picked.retain(|&i| i < to);
        picked
    }

    #[test]
    fn the_word_wise_draw_is_the_rule_test_by_test() {
        for (seed, share, from, to) in [
            (1, 0.1, 0, 100_000),
            (2, 0.5, 7, 10_007),
            (3, BYTEWISE_FROM, 3, 4096 * 3 + 11),
            (4, 0.37, 1 << 40, (1 << 40) + 70),
            (5, 0.2, 10, 15),
        ] {
            let word_wise = bytewise(&mut StdRng::seed_from_u64(seed), share, from, to);
            let test_by_test =
                bytewise_test_by_test(&mut StdRng::seed_from_u64(seed), share, from, to);
            assert_eq!(word_wise, test_by_test, "{share} {from}..{to}");
        }
    }

    /// `P(chosen) = t/256 + r/2⁶⁴` equals the share exactly (in integers)
    /// across the byte-wise range, ends included.
    #[test]
    fn the_bytewise_rule_chooses_with_exactly_the_share() {
        let mut shares = vec![BYTEWISE_FROM, 0.1, 0.25, 1.0 / 3.0, BYTEWISE_TO];
        let mut rng = StdRng::seed_from_u64(7);
        shares.extend((0..1000).map(|_| rng.random_range(BYTEWISE_FROM..=BYTEWISE_TO)));
        for share in shares {
            let (t, rest) = threshold(share);
            assert!(t <= 128 && rest < 1 << 56);
            // Enumerate the first byte: below t chosen; t decided by R < r.
            let chosen = (0..=255u8).filter(|&b| b < t).count() as u128;
            let numerator = (chosen << 56) + u128::from(rest);
            // share = m · 2^e exactly; share · 2⁶⁴ must be that integer.
            let exact = share * 2f64.powi(64);
            assert_eq!(exact.fract(), 0.0);
            assert_eq!(numerator, exact as u128, "share {share}");
        }
    }

    #[test]
    fn the_secret_sample_has_its_share_independently_and_differs_between_coordinators() {
        let sampler = Sampler::seeded(11);
        // Both ways of drawing: byte by byte (0.1, 0.3, 0.5 and the ends
        // of its range) and by gaps (1e-6, 0.01, 0.7).
        for share in [0.1, BYTEWISE_FROM, 0.3, 0.01, BYTEWISE_TO, 0.7] {
            // The count of a large range: 5 sd is 0.3 % of it at 0.1, so
            // a rule that missed the ties (25/256 = 0.0977) fails by 15 sd.
            let n = 4_000_000u64;
            let count = sampler.pick(share, 0, n).len() as f64;
            let sd = (n as f64 * share * (1.0 - share)).sqrt();
            assert!(
                (count - n as f64 * share).abs() < 5.0 * sd,
                "{share}: {count}"
            );
            let n = 200_000u64;
            let picked = sampler.pick(share, 1000, 1000 + n);
            assert!(picked.windows(2).all(|w| w[0] < w[1]));
            assert!(picked.first() >= Some(&1000) && picked.last() < Some(&(1000 + n)));
            // Independent: pairs both chosen about share² of the time, at
            // lag 1 (the same byte of neighbouring words) and at lag 8
            // (neighbouring bytes of one word).
            let set: std::collections::HashSet<u64> = picked.iter().copied().collect();
            for lag in [1, 8] {
                let pairs = (1000..1000 + n - lag)
                    .filter(|i| set.contains(i) && set.contains(&(i + lag)))
                    .count() as f64;
                let p2 = share * share;
                let sd = (n as f64 * p2 * (1.0 - p2)).sqrt() * 2.0;
                assert!(
                    (pairs - n as f64 * p2).abs() < 5.0 * sd,
                    "{share}: lag {lag}: {pairs}"
                );
            }
            // Each position of a word, and of a group of 64, alike.
            let mut by_position = [0f64; 64];
            for &i in &picked {
                by_position[((i - 1000) % 64) as usize] += 1.0;
            }
            let per = n as f64 / 64.0;
            let sd = (per * share * (1.0 - share)).sqrt();
            for (k, &c) in by_position.iter().enumerate() {
                assert!(
                    (c - per * share).abs() < 5.0 * sd,
                    "{share}: position {k}: {c}"
                );
            }
            // Each range in many small reports (ranges not a multiple of
            // eight or of 64): the same share.
            let small: usize = (0..20_000u64)
                .map(|k| sampler.pick(share, k * 13, k * 13 + 13))
                .map(|p| {
                    assert!(p.iter().all(|i| (i / 13) == p[0] / 13));
                    p.len()
                })
                .sum();
            let mean = 260_000.0 * share;
            let sd = (mean * (1.0 - share)).sqrt();
            assert!((small as f64 - mean).abs() < 5.0 * sd, "{share}: {small}");
        }
        let other = Sampler::default().pick(0.5, 0, 1000);
        let mine = Sampler::default().pick(0.5, 0, 1000);
        assert_ne!(other, mine, "two coordinators draw alike");
        assert!(sampler.pick(0.0, 0, 100).is_empty());
        // A tiny share: gaps of a million.
        let rare = sampler.pick(1e-6, 0, 100_000_000);
        assert!((50..=150).contains(&rare.len()), "{}", rare.len());
        // Gaps are geometric, P(gap = k) = share (1 − share)^k, both ways.
        for share in [0.3, 0.7] {
            let picked = sampler.pick(share, 0, 3_000_000);
            let mut counts = [0u64; 4];
            for w in picked.windows(2) {
                counts[((w[1] - w[0] - 1) as usize).min(3)] += 1;
            }
            let n = (picked.len() - 1) as f64;
            for (k, &c) in counts.iter().enumerate().take(3) {
                let p = share * (1.0 - share).powi(k as i32);
                let sd = (n * p * (1.0 - p)).sqrt();
                assert!(
                    (c as f64 - n * p).abs() < 5.0 * sd,
                    "{share}: gap {k}: {c} of {n}"
                );
            }
        }
        assert_eq!(sampler.pick(1.0, 5, 8), [5, 6, 7]);
        assert!(sampler.pick(0.5, 8, 8).is_empty());
        assert!(sampler.pick(f64::NAN, 0, 8).is_empty());
    }
}
