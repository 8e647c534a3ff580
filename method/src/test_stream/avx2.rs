//! ChaCha8's first block of eight streams in AVX2 registers: each of the
//! sixteen state words one 256-bit vector, a lane per stream.
//!
//! The portable [`super::chacha::blocks`] computes the same words; the compiler
//! vectorised it only in part (scalar rotates mixed with vector adds, the
//! state kept on the stack), about 40 ns a block on this machine's AVX2
//! cores. Written with the intrinsics, rotations by 16 and 8 are byte
//! shuffles and by 12 and 7 two shifts and an or, and the state stays in
//! registers as far as sixteen allow. The words are `rand_chacha`'s (tests
//! in [`super`]).

use super::chacha::{double_round, BLOCK_WORDS, DOUBLE_ROUNDS, LANES, SIGMA};
use std::arch::x86_64::{
    __m256i, _mm256_add_epi32, _mm256_or_si256, _mm256_set1_epi32, _mm256_setr_epi32,
    _mm256_setr_epi8, _mm256_shuffle_epi8, _mm256_slli_epi32, _mm256_srli_epi32,
    _mm256_storeu_si256, _mm256_xor_si256,
};

/// The byte order of `x <<< 16` in each 32-bit lane (of each 128-bit half).
const ROTATE_16: [i8; 16] = [2, 3, 0, 1, 6, 7, 4, 5, 10, 11, 8, 9, 14, 15, 12, 13];

/// The byte order of `x <<< 8` in each 32-bit lane.
const ROTATE_8: [i8; 16] = [3, 0, 1, 2, 7, 4, 5, 6, 11, 8, 9, 10, 15, 12, 13, 14];

/// A rotation by whole bytes in each 32-bit lane: `order` (one of the
/// above) as a byte shuffle in both halves.
#[inline]
#[target_feature(enable = "avx2")]
fn rotate_bytes(x: __m256i, order: [i8; 16]) -> __m256i {
    let o = order;
    let order = _mm256_setr_epi8(
        o[0], o[1], o[2], o[3], o[4], o[5], o[6], o[7], o[8], o[9], o[10], o[11], o[12], o[13],
        o[14], o[15], o[0], o[1], o[2], o[3], o[4], o[5], o[6], o[7], o[8], o[9], o[10], o[11],
        o[12], o[13], o[14], o[15],
    );
    _mm256_shuffle_epi8(x, order)
}

/// `x <<< L` in each 32-bit lane, with `R = 32 − L`: two shifts and an or.
#[inline]
#[target_feature(enable = "avx2")]
fn rotate<const L: i32, const R: i32>(x: __m256i) -> __m256i {
    _mm256_or_si256(_mm256_slli_epi32::<L>(x), _mm256_srli_epi32::<R>(x))
}

/// ChaCha's quarter round on words `a, b, c, d` of `x`, every lane.
#[inline]
#[target_feature(enable = "avx2")]
fn quarter_round(x: &mut [__m256i; BLOCK_WORDS], a: usize, b: usize, c: usize, d: usize) {
    x[a] = _mm256_add_epi32(x[a], x[b]);
    x[d] = rotate_bytes(_mm256_xor_si256(x[d], x[a]), ROTATE_16);
    x[c] = _mm256_add_epi32(x[c], x[d]);
    x[b] = rotate::<12, 20>(_mm256_xor_si256(x[b], x[c]));
    x[a] = _mm256_add_epi32(x[a], x[b]);
    x[d] = rotate_bytes(_mm256_xor_si256(x[d], x[a]), ROTATE_8);
    x[c] = _mm256_add_epi32(x[c], x[d]);
    x[b] = rotate::<7, 25>(_mm256_xor_si256(x[b], x[c]));
}

/// Block 0 of the streams `streams` under `key`: `out[w][l]` is word `w`
/// of stream `streams[l]`.
#[target_feature(enable = "avx2")]
pub fn first_blocks(key: &[u32; 8], streams: &[u64; LANES], out: &mut [[u32; LANES]; 16]) {
    let word = |w: u32| _mm256_set1_epi32(w as i32);
    let lanes = |f: &dyn Fn(u64) -> u32| {
        let s = streams.map(|s| f(s) as i32);
        _mm256_setr_epi32(s[0], s[1], s[2], s[3], s[4], s[5], s[6], s[7])
    };
    // Words 12 and 13 are the block counter, 0; 14 and 15 the stream.
    // Written out: built by `array::from_fn` the block took 8 ns longer.
    let input: [__m256i; BLOCK_WORDS] = [
        word(SIGMA[0]),
        word(SIGMA[1]),
        word(SIGMA[2]),
        word(SIGMA[3]),
        word(key[0]),
        word(key[1]),
        word(key[2]),
        word(key[3]),
        word(key[4]),
        word(key[5]),
        word(key[6]),
        word(key[7]),
        word(0),
        word(0),
        lanes(&|s| s as u32),
        lanes(&|s| (s >> 32) as u32),
    ];
    let mut x = input;
    for _ in 0..DOUBLE_ROUNDS {
        double_round!(quarter_round, &mut x);
    }
    for ((out, x), input) in out.iter_mut().zip(x).zip(input) {
        let word = _mm256_add_epi32(x, input);
        // SAFETY: `out` is 8 × 4 = 32 writable bytes, the width of the
        // store, which needs no alignment.
        #[allow(unsafe_code)]
        unsafe {
            _mm256_storeu_si256(out.as_mut_ptr().cast(), word)
        };
    }
}
