//! What the replay checks did since the coordinator started, for
//! `/metrics` ([`crate::report::replay::verify_counted`] counts each check).

use std::sync::atomic::{AtomicU64, Ordering};

/// Where a report's check ran: on the writer, in the report's own
/// transaction (small checks); on the request's task (a few
/// microseconds); or on the blocking pool.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Place {
    Writer = 0,
    Request = 1,
    Pool = 2,
}

impl Place {
    pub const ALL: [Place; 3] = [Place::Writer, Place::Request, Place::Pool];

    /// The label `/metrics` gives it.
    pub fn label(self) -> &'static str {
        match self {
            Place::Writer => "writer",
            Place::Request => "request",
            Place::Pool => "pool",
        }
    }
}

/// What the replay checks did since the coordinator started, for
/// `/metrics`: reports checked by place, and for the reports whose quiet
/// tests were sampled, the tests the sample was drawn from and the tests
/// it chose (their ratio is the replay share).
#[derive(Debug, Default)]
pub struct ReplayCounts {
    reports: [AtomicU64; 3],
    sample_range: AtomicU64,
    sampled: AtomicU64,
}

/// [`ReplayCounts`] read at one moment.
#[derive(Debug, Default, Clone, Copy, PartialEq)]
pub struct ReplayTotals {
    /// Reports checked, by [`Place::ALL`] (a place's value is its index).
    pub reports: [u64; 3],
    pub sample_range: u64,
    pub sampled: u64,
}

impl ReplayCounts {
    /// A report checked at `place`, its quiet tests sampled from
    /// `range` tests with `sampled` chosen (both 0 when every test is run).
    pub fn record(&self, place: Place, range: u64, sampled: u64) {
        self.reports[place as usize].fetch_add(1, Ordering::Relaxed);
        self.sample_range.fetch_add(range, Ordering::Relaxed);
        self.sampled.fetch_add(sampled, Ordering::Relaxed);
    }

    pub fn totals(&self) -> ReplayTotals {
        ReplayTotals {
            reports: self.reports.each_ref().map(|r| r.load(Ordering::Relaxed)),
            sample_range: self.sample_range.load(Ordering::Relaxed),
            sampled: self.sampled.load(Ordering::Relaxed),
        }
    }
}
