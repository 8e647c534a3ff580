//! What the benchmark programs share.

use std::time::Instant;

/// Median wall time of `f` in seconds over `repeats` runs (odd, so one
/// noisy run does not decide it).
pub fn median_seconds(repeats: usize, mut f: impl FnMut()) -> f64 {
    let mut times: Vec<f64> = (0..repeats)
        .map(|_| {
            let t = Instant::now();
            f();
            t.elapsed().as_secs_f64()
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[repeats / 2]
}
