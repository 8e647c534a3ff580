//! `rand_distr`'s alias-table draw, computed with two integer comparisons.
//!
//! Every test's scenario is defined as the draw of
//! `rand_distr::weighted::WeightedAliasIndex<f64>` from the test's stream
//! ([`crate::test_stream`]): that fixes every scenario a campaign has ever
//! drawn, so the draw must not change, only how it is computed. The crate
//! draws a cell in two steps:
//!
//! 1. a candidate `c = Uniform<u32>(0, n)`: a word `v`, `v·n = hi·2³² + lo`,
//!    drawn again while `lo < 2³² mod n` (Lemire's multiply-high without
//!    bias), then `c = hi`;
//! 2. a uniform `u` in `[0, W)`, `W` the weights' sum, from a 64-bit word
//!    `x`: `m = x >> 12` (52 bits), `u = ((1 + m·2⁻⁵²) − 1)·scale`; the cell
//!    is `c` when `u < odds[c]`, else `alias[c]`.
//!
//! Through the crate's generic `Uniform` samplers, a float comparison
//! whose branch a random cell mispredicts about half the time (stalling
//! the next tests' draws too) and bounds-checked loads, replaying a cut-in
//! test (its stream's block, the draw, the cell's remembered outcome) took
//! 21.7 ns on this machine; through this table, 17 ns, of which the block
//! is 9.5 (docs/benchmarks.md). `u` never decreases as `m` grows, so the
//! `m` that keep `c` are exactly `m < k[c]` for one integer `k[c]`. This
//! table holds `k[c]` and `alias[c]` for each candidate and draws with the
//! same two words: `c` from the first by multiply-high, then `m < k[c]`.
//!
//! `k[c]` and `alias[c]` are not recomputed by copying the crate's table
//! construction: [`AliasTable::new`] builds the crate's table and *reads*
//! them off its own draws, by bisection on `m` with scripted words (53
//! draws a candidate: 2.5 ms for the cut-in's 3,420 cells, 113 ms for 10⁶
//! cells on two cores, once per campaign). So the table is the crate's,
//! whatever its construction does; the tests below check the draws equal
//! the crate's word for word.

use rand::distr::Distribution;
use rand::RngCore;
use rand_distr::weighted::{Error, WeightedAliasIndex};
use rayon::prelude::*;

/// Bits of the 64-bit word that make the uniform: its top 52.
const UNIFORM_BITS: u32 = 52;

/// Candidates probed per rayon task, at least.
const PROBE_CHUNK: usize = 4096;

/// A weighted draw of indices `0..n`, equal to `WeightedAliasIndex<f64>`'s
/// with the same weights on every stream of words.
#[derive(Debug, Clone)]
pub struct AliasTable {
    n: u32,
    /// `2³² mod n`: a first word whose low product falls below it is drawn
    /// again (the crate's rejection zone).
    redraw_below: u32,
    candidates: Box<[Candidate]>,
}

/// What the second word decides for one candidate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Candidate {
    /// The candidate is kept when `m < keep_below` (`2⁵²`: always).
    keep_below: u64,
    /// Else the draw is this index.
    alias: u32,
}

impl AliasTable {
    /// The table of `weights`, failing exactly when
    /// `WeightedAliasIndex::new` does (no weights, a negative, NaN or too
    /// large weight, all zero).
    pub fn new(weights: Vec<f64>) -> Result<Self, Error> {
        // The crate accepts at most `u32::MAX` weights.
        let n = weights.len() as u32;
        let crate_table = WeightedAliasIndex::new(weights)?;
        let redraw_below = n.wrapping_neg() % n;
        let candidates = (0..n)
            .into_par_iter()
            .with_min_len(PROBE_CHUNK)
            .map(|c| probe(&crate_table, n, redraw_below, c))
            .collect();
        Ok(Self {
            n,
            redraw_below,
            candidates,
        })
    }

    /// An index drawn with `rng`: the crate's draw, from the same words.
    #[inline]
    pub fn sample<R: RngCore + ?Sized>(&self, rng: &mut R) -> usize {
        let candidate = loop {
            let product = u64::from(rng.next_u32()) * u64::from(self.n);
            if product as u32 >= self.redraw_below {
                break (product >> 32) as usize;
            }
        };
        let m = rng.next_u64() >> (64 - UNIFORM_BITS);
        let Candidate { keep_below, alias } = self.candidates[candidate];
        // A select rather than a branch: which way a random cell goes is
        // not predictable, and a mispredicted branch stalls the tests after
        // it too (with a branch, 21 ns a replayed cut-in test; with the
        // select, 17 ns, of which 9.5 is the stream's block).
        let alias = alias as usize;
        let keep = usize::from(m < keep_below).wrapping_neg();
        alias ^ ((alias ^ candidate) & keep)
    }
}

/// Candidate `c`'s `keep_below` and alias, read off the crate's draws: a
/// first word that gives `c`, then bisection on the second word's `m`.
fn probe(table: &WeightedAliasIndex<f64>, n: u32, redraw_below: u32, c: u32) -> Candidate {
    let never_drawn = Candidate {
        keep_below: 1 << UNIFORM_BITS,
        alias: c,
    };
    let Some(word) = word_for(n, redraw_below, c) else {
        return never_drawn;
    };
    let draw = |m: u64| {
        table.sample(&mut Scripted {
            word,
            wide: m << (64 - UNIFORM_BITS),
            read: false,
        })
    };
    let last = (1 << UNIFORM_BITS) - 1;
    let alias = draw(last);
    if alias == c as usize {
        return never_drawn;
    }
    // Kept below `low` and not from `high` on.
    let (mut low, mut high) = (0u64, last);
    while low < high {
        let mid = low + (high - low) / 2;
        if draw(mid) == c as usize {
            low = mid + 1;
        } else {
            high = mid;
        }
    }
    Candidate {
        keep_below: low,
        alias: alias as u32,
    }
}

/// A first word whose draw is candidate `c` without a redraw: the smallest
/// `v` with `⌊v·n / 2³²⌋ = c` and a low part out of the rejection zone.
/// There always is one among the first two of the candidate's words: the
/// first one's low part is below `n`, only it can fall in the zone
/// (`2³² mod n < n`), and at least one word of the candidate is kept. So
/// `None` would mean the crate's rule is not the one written here.
fn word_for(n: u32, redraw_below: u32, c: u32) -> Option<u32> {
    let first = (u64::from(c) << 32).div_ceil(u64::from(n));
    (first..=u64::from(u32::MAX))
        .take(2)
        .find(|&v| {
            let product = v * u64::from(n);
            product >> 32 == u64::from(c) && product as u32 >= redraw_below
        })
        .map(|v| v as u32)
}

/// A generator that gives the same 32-bit word and the same 64-bit word
/// every time: how [`probe`] puts chosen words to the crate's draw.
struct Scripted {
    word: u32,
    wide: u64,
    /// Whether the word was read: a second read would mean the crate
    /// redrew a word [`word_for`] took to be kept, a rule that changed.
    read: bool,
}

impl RngCore for Scripted {
    fn next_u32(&mut self) -> u32 {
        assert!(
            !std::mem::replace(&mut self.read, true),
            "rand's Uniform<u32> redrew a word outside its rejection zone as \
             tslg computes it (2³² mod n): the crate's rule changed"
        );
        self.word
    }

    fn next_u64(&mut self) -> u64 {
        self.wide
    }

    fn fill_bytes(&mut self, dst: &mut [u8]) {
        for (byte, source) in dst.iter_mut().zip(self.wide.to_le_bytes().iter().cycle()) {
            *byte = *source;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_stream::TestStreams;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Weight vectors that stress the construction: one weight, two,
    /// zeros, ties, a huge range, many cells, random ones and the cut-in
    /// exposure's.
    fn weight_sets() -> Vec<Vec<f64>> {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut sets = vec![
            vec![1.0],
            vec![0.3, 0.7],
            vec![0.0, 1.0, 0.0, 2.0],
            vec![1.0; 7],
            vec![1e-300, 1.0, 1e-12, 5.0, 1e300 / 8.0, 0.0, 3.0, 1e-200],
            (0..1000).map(|i| f64::from(i % 17)).collect(),
        ];
        for n in [3, 10, 100, 5000] {
            sets.push((0..n).map(|_| rng.random::<f64>().powi(4)).collect());
        }
        // A candidate kept for every `m` but the last (`k = 2⁵² − 1`),
        // the bisection's upper end (found by a reviewer's fuzz).
        sets.push((0..63).map(|i| 1.0 / f64::from(i % 7 + 1) / 63.0).collect());
        // A sum at the largest double, and a subnormal one.
        sets.push(vec![f64::MAX / 4.0; 4]);
        sets.push(vec![5e-324, 0.0, 5e-324]);
        let cut_in = crate::cases::cutin::CutIn::builtin(Default::default());
        sets.push(crate::case::Case::exposure(&cut_in).masses().to_vec());
        sets
    }

    /// The crate's draw and the table's, from two copies of one stream,
    /// agree on every draw and leave the stream at the same word.
    fn assert_same_draws(weights: &[f64], rng: &mut impl RngCore, draws: usize) {
        let crate_table = WeightedAliasIndex::new(weights.to_vec()).unwrap();
        let table = AliasTable::new(weights.to_vec()).unwrap();
        for k in 0..draws {
            let mine = Recorded::new(rng);
            let want = crate_table.sample(&mut mine.replay());
            let got = table.sample(&mut mine.replay());
            assert_eq!(got, want, "draw {k} of {} weights", weights.len());
        }
    }

    /// Words taken from a stream once, then handed out again to each draw.
    struct Recorded {
        words: Vec<u32>,
    }

    impl Recorded {
        /// Enough words for any draw that does not redraw more than thirty
        /// times (each word below the zone has probability `n/2³²`).
        fn new(rng: &mut impl RngCore) -> Self {
            Self {
                words: (0..64).map(|_| rng.next_u32()).collect(),
            }
        }

        fn replay(&self) -> Replay<'_> {
            Replay {
                words: &self.words,
                next: 0,
            }
        }
    }

    struct Replay<'a> {
        words: &'a [u32],
        next: usize,
    }

    impl RngCore for Replay<'_> {
        fn next_u32(&mut self) -> u32 {
            self.next += 1;
            self.words[self.next - 1]
        }

        fn next_u64(&mut self) -> u64 {
            let low = u64::from(self.next_u32());
            (u64::from(self.next_u32()) << 32) | low
        }

        fn fill_bytes(&mut self, _: &mut [u8]) {
            unreachable!("an alias draw takes words")
        }
    }

    /// A word `v` with `v·n ≡ low (mod 2³²)`, for `low` a multiple of the
    /// largest power of two dividing `n`: `low / 2ᵃ` times the inverse of
    /// `n`'s odd part, found by Newton's iteration modulo 2³².
    fn word_with_low(n: u32, low: u32) -> u32 {
        let a = n.trailing_zeros();
        let odd = n >> a;
        let mut inverse = odd;
        for _ in 0..5 {
            inverse = inverse.wrapping_mul(2u32.wrapping_sub(odd.wrapping_mul(inverse)));
        }
        let v = (low >> a).wrapping_mul(inverse);
        assert_eq!(v.wrapping_mul(n), low, "n {n} low {low}");
        v
    }

    #[test]
    fn draws_equal_the_crates_on_random_words() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for weights in weight_sets() {
            assert_same_draws(&weights, &mut rng, 20_000);
        }
    }

    /// The words that decide a draw: for every candidate of every set, the
    /// second word at its threshold and one below it, and first words in
    /// the rejection zone followed by a word that is kept.
    #[test]
    fn draws_equal_the_crates_at_every_threshold_and_redraw() {
        let last = (1 << 52) - 1;
        // Whether some candidate is kept for every `m` but the last.
        let mut kept_to_the_last = false;
        for weights in weight_sets() {
            let crate_table = WeightedAliasIndex::new(weights.clone()).unwrap();
            let table = AliasTable::new(weights.clone()).unwrap();
            let n = weights.len() as u32;
            for c in 0..n {
                let word = word_for(n, table.redraw_below, c).expect("a kept first word");
                let keep = table.candidates[c as usize].keep_below;
                kept_to_the_last |= keep == last;
                for m in [keep.saturating_sub(1), keep, keep + 1, 0, last - 1, last] {
                    let m = m.min(last);
                    for low_bits in [0, 0xfff] {
                        let wide = (m << 12) | low_bits;
                        let words = [word, wide as u32, (wide >> 32) as u32];
                        let pick = |sample: &dyn Fn(&mut Replay) -> usize| {
                            sample(&mut Replay {
                                words: &words,
                                next: 0,
                            })
                        };
                        assert_eq!(
                            pick(&|r| table.sample(r)),
                            pick(&|r| crate_table.sample(r)),
                            "candidate {c} of {n}, m {m}"
                        );
                    }
                }
            }
            // First words on both sides of the rejection zone's edge
            // (`v·n mod 2³² < 2³² mod n`, the last low part in it that
            // `v·n` can reach and the first out of it), each followed by
            // ordinary words: the crate redraws exactly the first (checked
            // by the words it reads), and the table draws the same cell.
            let zone = n.wrapping_neg() % n;
            let step = 1u32 << n.trailing_zeros().min(31);
            let edge = [zone.checked_sub(step), Some(zone), Some(0), Some(n - step)];
            for (low, redrawn) in edge.into_iter().flatten().map(|low| (low, low < zone)) {
                let v = word_with_low(n, low);
                let words = [v, 0x9e37_79b9, 0x7f4a_7c15, 0x1234_5678, 0x0bad_cafe];
                let mut crate_words = Replay {
                    words: &words,
                    next: 0,
                };
                let want = crate_table.sample(&mut crate_words);
                assert_eq!(crate_words.next, if redrawn { 4 } else { 3 }, "{n} weights");
                let mine = table.sample(&mut Replay {
                    words: &words,
                    next: 0,
                });
                assert_eq!(mine, want, "first word {v} (low part {low}) of {n} weights");
            }
        }
        assert!(
            kept_to_the_last,
            "no candidate tests the bisection's upper end"
        );
    }

    /// Through the tests' own streams (the first block and past it), as
    /// campaigns draw.
    #[test]
    fn draws_equal_the_crates_on_test_streams() {
        let weights = weight_sets().pop().unwrap();
        let crate_table = WeightedAliasIndex::new(weights.clone()).unwrap();
        let table = AliasTable::new(weights).unwrap();
        let streams = TestStreams::new(3);
        for index in 0..20_000u64 {
            let (mut a, mut b) = (streams.rng(index), streams.rng(index));
            for _ in 0..6 {
                assert_eq!(table.sample(&mut a), crate_table.sample(&mut b));
            }
            assert_eq!(
                a.next_u32(),
                b.next_u32(),
                "test {index} read as many words"
            );
        }
    }

    #[test]
    fn fails_where_the_crate_fails() {
        for weights in [vec![], vec![0.0, 0.0], vec![1.0, f64::NAN], vec![-1.0, 2.0]] {
            let ours = AliasTable::new(weights.clone()).err();
            assert!(ours.is_some(), "{weights:?} accepted");
            assert_eq!(ours, WeightedAliasIndex::new(weights).err());
        }
    }
}
