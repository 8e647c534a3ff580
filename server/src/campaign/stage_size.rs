//! How long an adaptive campaign's estimation stages are (issue 68).
//!
//! A campaign plans each stage from the results of the one before, so a
//! stage of `s` tests on `T` threads of one-test work runs `⌈s/T⌉` rounds,
//! its last `s − T (⌈s/T⌉ − 1)` busy: the default 100 keeps at most 100
//! threads busy, 78 % of 128. A fleet of more than 20 threads gets stages
//! of `20 ⌈5 T / 20⌉` tests (at most 2,000), about five rounds (a multiple of 20, as every
//! stage must be: it holds its exploring share exactly), so that all but
//! the last round keep every thread busy and the next stage waits on one
//! test's time. The length is chosen once, at the campaign's creation, from
//! the live workers that offer its vehicle, and stored: every stage's plan
//! still depends on the seed and the results before it alone, so the
//! estimate, its interval and the guard are those of any fixed length (the
//! guard's campaign stops at a stage's end, so a longer stage can run up to
//! a stage past its stop). A campaign created with up to 20 threads, or
//! given `stage_tests`, is as before.

/// The length of campaigns created without a large fleet.
pub const DEFAULT_STAGE_TESTS: u64 = 100;
/// Threads above which stages are sized from the fleet.
const FLEET_FROM: u32 = 20;
/// The longest stage.
pub const MAX_STAGE_TESTS: u64 = 100_000;
/// The longest stage a fleet gets without asking: a guarded campaign
/// stops at a stage's end only, so a stage past what the campaign needs is
/// tests run for nothing (400 threads and more get stages of 2,000).
const MAX_FLEET_STAGE: u64 = 2_000;

/// The stage length for a campaign created while `threads` threads of live
/// workers offer its vehicle.
pub fn for_fleet(threads: u32) -> u64 {
    if threads <= FLEET_FROM {
        return DEFAULT_STAGE_TESTS;
    }
    (20 * (5 * u64::from(threads)).div_ceil(20)).clamp(DEFAULT_STAGE_TESTS, MAX_FLEET_STAGE)
}

/// Whether `tests` may be a stage's length: a multiple of 20 from 20 to
/// [`MAX_STAGE_TESTS`].
pub fn valid(tests: u64) -> bool {
    (20..=MAX_STAGE_TESTS).contains(&tests) && tests.is_multiple_of(20)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_large_fleet_gets_about_five_rounds_a_stage() {
        assert_eq!(for_fleet(0), 100);
        assert_eq!(for_fleet(20), 100);
        assert_eq!(for_fleet(21), 120);
        assert_eq!(for_fleet(32), 160);
        assert_eq!(for_fleet(128), 640);
        assert_eq!(for_fleet(400), 2_000);
        assert_eq!(for_fleet(1_000_000), 2_000);
        for threads in 21..=400 {
            let s = for_fleet(threads);
            assert!(valid(s), "{threads}: {s}");
            // Every round but the last is full, and there are about five.
            let rounds = s.div_ceil(u64::from(threads));
            assert!(
                (5..=6).contains(&rounds),
                "{threads}: {s} in {rounds} rounds"
            );
        }
    }

    #[test]
    fn a_stage_is_a_multiple_of_20_within_bounds() {
        assert!(valid(20) && valid(100) && valid(MAX_STAGE_TESTS));
        assert!(!valid(0) && !valid(10) && !valid(110) && !valid(MAX_STAGE_TESTS + 20));
    }
}
