//! ChaCha8's block function (Bernstein 2008) on `N` streams side by side:
//! state `(σ, key, counter = 0, stream)`, four double rounds of quarter
//! rounds on columns then diagonals, and the input added back word by
//! word. The portable form of what [`super::avx2`] computes in registers.

/// Tests whose first blocks are computed together.
pub const LANES: usize = 8;

/// "expand 32-byte k".
pub(super) const SIGMA: [u32; 4] = [0x6170_7865, 0x3320_646e, 0x7962_2d32, 0x6b20_6574];

/// Words of one ChaCha block.
pub(super) const BLOCK_WORDS: usize = 16;

/// ChaCha8's rounds, as double rounds.
pub(super) const DOUBLE_ROUNDS: usize = 4;

/// One double round of ChaCha on `$x` with `$quarter_round(x, a, b, c, d)`:
/// the columns, then the diagonals. A macro rather than a loop over the
/// word indices so that they are constants in the code: the AVX2 block
/// then keeps its state in registers (a loop over a table of indices,
/// left rolled, put it on the stack: 31 → 53 ns a draw).
macro_rules! double_round {
    ($quarter_round:path, $x:expr) => {
        $quarter_round($x, 0, 4, 8, 12);
        $quarter_round($x, 1, 5, 9, 13);
        $quarter_round($x, 2, 6, 10, 14);
        $quarter_round($x, 3, 7, 11, 15);
        $quarter_round($x, 0, 5, 10, 15);
        $quarter_round($x, 1, 6, 11, 12);
        $quarter_round($x, 2, 7, 8, 13);
        $quarter_round($x, 3, 4, 9, 14);
    };
}
#[cfg(target_arch = "x86_64")]
pub(super) use double_round;

/// ChaCha's quarter round on words `a, b, c, d` of `x`, for each lane.
/// (Four rows of one array, so a lane index rather than iterators.)
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn quarter_round<const N: usize>(x: &mut [[u32; N]; 16], a: usize, b: usize, c: usize, d: usize) {
    for l in 0..N {
        x[a][l] = x[a][l].wrapping_add(x[b][l]);
        x[d][l] = (x[d][l] ^ x[a][l]).rotate_left(16);
        x[c][l] = x[c][l].wrapping_add(x[d][l]);
        x[b][l] = (x[b][l] ^ x[c][l]).rotate_left(12);
        x[a][l] = x[a][l].wrapping_add(x[b][l]);
        x[d][l] = (x[d][l] ^ x[a][l]).rotate_left(8);
        x[c][l] = x[c][l].wrapping_add(x[d][l]);
        x[b][l] = (x[b][l] ^ x[c][l]).rotate_left(7);
    }
}

/// Block 0 of `N` streams at once: `out[w][l]` is word `w` of stream
/// `streams[l]`.
#[inline(always)]
pub(super) fn blocks<const N: usize>(key: &[u32; 8], streams: &[u64; N], out: &mut [[u32; N]; 16]) {
    let mut input = [[0u32; N]; 16];
    for (w, &s) in SIGMA.iter().enumerate() {
        input[w] = [s; N];
    }
    for (w, &k) in key.iter().enumerate() {
        input[4 + w] = [k; N];
    }
    // Words 12 and 13 are the block counter, 0.
    for (l, &stream) in streams.iter().enumerate() {
        input[14][l] = stream as u32;
        input[15][l] = (stream >> 32) as u32;
    }
    let mut x = input;
    for _ in 0..DOUBLE_ROUNDS {
        double_round!(quarter_round, &mut x);
    }
    for ((out, x), input) in out.iter_mut().zip(&x).zip(&input) {
        for ((out, x), input) in out.iter_mut().zip(x).zip(input) {
            *out = x.wrapping_add(*input);
        }
    }
}

/// The first block of one stream.
pub(super) fn first_block(key: &[u32; 8], stream: u64) -> [u32; BLOCK_WORDS] {
    let mut out = [[0u32; 1]; 16];
    blocks(key, &[stream], &mut out);
    out.map(|[w]| w)
}
