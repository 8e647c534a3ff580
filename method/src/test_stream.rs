//! The random stream of each test, computed cheaply and side by side.
//!
//! Test `i` of a campaign seeded `s` draws from ChaCha8 keyed by
//! `seed_from_u64(s)` at stream `i`, word 0 ([`crate::sampling`]): that
//! definition fixes every scenario a campaign has ever drawn, so it must
//! not change. What does change is how the words are computed.
//! `rand_chacha`'s `ChaCha8Rng` fills a buffer of four blocks (256 bytes)
//! before its first word, while a grid test uses three or four words of
//! the first block; and positioning a fresh generator per test costs more
//! than the block itself. [`TestRng`] holds only the stream's first block
//! (16 words) and hands the rest, when a test wants more (car-following
//! draws an action per decision), to a `ChaCha8Rng` positioned at word 16:
//! the words it yields are those of `ChaCha8Rng`, in the same order, for
//! every mix of `next_u32`, `next_u64` and `fill_bytes` (test against
//! `rand_chacha` below). [`TestStreams::each`] computes the first blocks of
//! [`LANES`] tests at once, each of the sixteen state words a vector over
//! the tests (AVX2's intrinsics where the processor has them, [`avx2`];
//! else the same arithmetic on arrays).
//!
//! The block function is ChaCha's (Bernstein 2008), with eight rounds:
//! state `(σ, key, counter = 0, stream)`, four double rounds of quarter
//! rounds `a += b; d ^= a; d <<<= 16; c += d; b ^= c; b <<<= 12; a += b;
//! d ^= a; d <<<= 8; c += d; b ^= c; b <<<= 7` on columns then diagonals,
//! and the input added back word by word.

use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

#[cfg(target_arch = "x86_64")]
mod avx2;
mod chacha;

pub use chacha::LANES;
use chacha::{blocks, first_block, BLOCK_WORDS};

/// A ChaCha8 key from a campaign seed, derived exactly as
/// `ChaCha8Rng::seed_from_u64` derives its key: both use `rand_core`'s
/// provided `seed_from_u64` (PCG32 output, little-endian) on a 32-byte seed.
struct Key([u8; 32]);

impl SeedableRng for Key {
    type Seed = [u8; 32];
    fn from_seed(seed: [u8; 32]) -> Self {
        Key(seed)
    }
}

/// The streams of one campaign seed: its key, ready for many tests.
#[derive(Debug, Clone, Copy)]
pub struct TestStreams {
    seed: u64,
    key: [u32; 8],
}

impl TestStreams {
    /// The streams of the campaign seeded `seed`.
    pub fn new(seed: u64) -> Self {
        let Key(bytes) = Key::seed_from_u64(seed);
        let key = std::array::from_fn(|i| {
            u32::from_le_bytes([
                bytes[4 * i],
                bytes[4 * i + 1],
                bytes[4 * i + 2],
                bytes[4 * i + 3],
            ])
        });
        Self { seed, key }
    }

    /// The stream of test `index`.
    pub fn rng(&self, index: u64) -> TestRng {
        TestRng::new(self.seed, index, first_block(&self.key, index))
    }

    /// Calls `f(index, stream)` for each of `indices` in order, computing
    /// the first blocks [`LANES`] at a time.
    pub fn each(&self, indices: impl IntoIterator<Item = u64>, mut f: impl FnMut(u64, TestRng)) {
        let mut indices = indices.into_iter().peekable();
        let mut streams = [0u64; LANES];
        let mut words = [[0u32; LANES]; BLOCK_WORDS];
        while indices.peek().is_some() {
            let mut n = 0;
            while n < LANES {
                let Some(index) = indices.next() else { break };
                streams[n] = index;
                n += 1;
            }
            first_blocks(&self.key, &streams, &mut words);
            for (lane, &index) in streams[..n].iter().enumerate() {
                let block = std::array::from_fn(|w| words[w][lane]);
                f(index, TestRng::new(self.seed, index, block));
            }
        }
    }
}

/// The stream of test `index` of the campaign seeded `seed`.
pub fn test_rng(seed: u64, index: u64) -> TestRng {
    TestStreams::new(seed).rng(index)
}

/// The same stream as [`test_rng`], as `rand_chacha` generates it: four
/// blocks at a time, for tests that draw many numbers (car-following
/// draws two words a decision, about 60 a test), where computing the
/// first block apart would only add to the four.
pub fn long_test_rng(seed: u64, index: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(index);
    rng
}

/// One test's ChaCha8 stream: its first block held, the rest from
/// `rand_chacha` once the first block is used up.
#[derive(Debug, Clone)]
pub struct TestRng {
    block: [u32; BLOCK_WORDS],
    /// The next word of `block` to hand out; `BLOCK_WORDS` once it is used up.
    next: usize,
    seed: u64,
    stream: u64,
    /// Words 16 on, made on first use.
    rest: Option<Box<ChaCha8Rng>>,
}

impl TestRng {
    fn new(seed: u64, stream: u64, block: [u32; BLOCK_WORDS]) -> Self {
        Self {
            block,
            next: 0,
            seed,
            stream,
            rest: None,
        }
    }

    /// The stream past its first block.
    fn rest(&mut self) -> &mut ChaCha8Rng {
        let (seed, stream) = (self.seed, self.stream);
        self.rest.get_or_insert_with(|| {
            let mut rng = long_test_rng(seed, stream);
            rng.set_word_pos(BLOCK_WORDS as u128);
            Box::new(rng)
        })
    }
}

impl RngCore for TestRng {
    #[inline]
    fn next_u32(&mut self) -> u32 {
        if self.next < BLOCK_WORDS {
            self.next += 1;
            return self.block[self.next - 1];
        }
        self.rest().next_u32()
    }

    /// Two consecutive words, the first the low half (as `rand_core`'s
    /// block generators read them, across block boundaries too).
    #[inline]
    fn next_u64(&mut self) -> u64 {
        if self.next >= BLOCK_WORDS {
            return self.rest().next_u64();
        }
        let low = u64::from(self.next_u32());
        let high = u64::from(self.next_u32());
        (high << 32) | low
    }

    /// Whole words, little-endian; the unused bytes of a last partial word
    /// are dropped, as `rand_core`'s block generators drop them.
    fn fill_bytes(&mut self, dst: &mut [u8]) {
        let mut filled = 0;
        while filled < dst.len() && self.next < BLOCK_WORDS {
            let bytes = self.block[self.next].to_le_bytes();
            let take = (dst.len() - filled).min(4);
            dst[filled..filled + take].copy_from_slice(&bytes[..take]);
            self.next += 1;
            filled += take;
        }
        if filled < dst.len() {
            self.rest().fill_bytes(&mut dst[filled..]);
        }
    }
}

/// [`LANES`] first blocks side by side: with AVX2's intrinsics where the
/// processor has AVX2 ([`avx2`]: about 9 ns a block here, against about
/// 40 ns for the portable code compiled for AVX2, which the compiler
/// vectorised only in part), else the portable code.
fn first_blocks(key: &[u32; 8], streams: &[u64; LANES], out: &mut [[u32; LANES]; 16]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the processor has AVX2, the one feature the function
        // is compiled for.
        #[allow(unsafe_code)]
        return unsafe { avx2::first_blocks(key, streams, out) };
    }
    blocks(key, streams, out);
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng;

    /// Each test's stream, read in a random mix of calls, equals
    /// `ChaCha8Rng::seed_from_u64(seed)` at that stream, past the first
    /// block too, one at a time and side by side.
    #[test]
    fn streams_equal_rand_chacha_word_for_word() {
        let mut calls = ChaCha8Rng::seed_from_u64(99);
        for seed in [0, 1, 42, u64::MAX] {
            let streams = TestStreams::new(seed);
            let indices = [0, 1, 2, 7, 8, 1 << 32, (1 << 32) + 5, u64::MAX, 12345];
            let mut batched = Vec::new();
            streams.each(indices, |index, rng| batched.push((index, rng)));
            assert_eq!(batched.len(), indices.len());
            for ((index, mut lane), &want_index) in batched.into_iter().zip(&indices) {
                assert_eq!(index, want_index);
                let mut want = ChaCha8Rng::seed_from_u64(seed);
                want.set_stream(index);
                let mut long = long_test_rng(seed, index);
                let mut single = streams.rng(index);
                for _ in 0..40 {
                    match calls.random_range(0..3) {
                        0 => {
                            let w = want.next_u32();
                            assert_eq!(long.next_u32(), w);
                            assert_eq!(single.next_u32(), w, "seed {seed} test {index}");
                            assert_eq!(lane.next_u32(), w);
                        }
                        1 => {
                            let w = want.next_u64();
                            assert_eq!(long.next_u64(), w);
                            assert_eq!(single.next_u64(), w, "seed {seed} test {index}");
                            assert_eq!(lane.next_u64(), w);
                        }
                        _ => {
                            let len = calls.random_range(0..23);
                            let mut w = vec![0; len];
                            let (mut s, mut l, mut g) = (vec![0; len], vec![0; len], vec![0; len]);
                            want.fill_bytes(&mut w);
                            single.fill_bytes(&mut s);
                            lane.fill_bytes(&mut l);
                            long.fill_bytes(&mut g);
                            assert_eq!((&s, &l, &g), (&w, &w, &w), "seed {seed} test {index}");
                        }
                    }
                }
            }
        }
    }

    /// The first blocks [`LANES`] at a time, by whichever path this
    /// processor takes (AVX2's intrinsics here), equal the portable
    /// arithmetic's word for word, over many keys and streams (the streams
    /// test above checks the portable one-lane path against `rand_chacha`).
    #[test]
    fn side_by_side_blocks_equal_the_portable_ones() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for _ in 0..2_000 {
            let key: [u32; 8] = std::array::from_fn(|_| rng.next_u32());
            let streams: [u64; LANES] = std::array::from_fn(|_| rng.next_u64());
            let (mut fast, mut portable) = ([[0; LANES]; 16], [[0; LANES]; 16]);
            first_blocks(&key, &streams, &mut fast);
            blocks(&key, &streams, &mut portable);
            assert_eq!(fast, portable, "key {key:?} streams {streams:?}");
        }
    }

    /// Odd counts of tests fill the last group of lanes partly.
    #[test]
    fn each_visits_every_index_once_in_order() {
        let streams = TestStreams::new(5);
        for n in [0u64, 1, 7, 8, 9, 17] {
            let mut seen = Vec::new();
            streams.each(100..100 + n, |index, mut rng| {
                seen.push(index);
                assert_eq!(rng.next_u64(), streams.rng(index).next_u64());
            });
            assert_eq!(seen, (100..100 + n).collect::<Vec<_>>());
        }
    }
}
