//! How many tests a worker runs between two reports of a lease: a chunk of
//! about [`CHUNK_SECONDS`] of work, measured on each campaign, and one
//! test per thread when a test takes longer than that.

/// A chunk aims at this much work: reports double as heartbeats, the
/// coordinator's prefix (and so a campaign's stop) moves while a lease
/// runs, and an audit handed to the worker with a report waits for at most
/// the chunk that runs meanwhile (docs/operations.md, "Slow vehicles").
/// Half a second kept fast campaigns' reports few; a quarter costs them
/// nothing measurable (a report every 0.25 s per worker) and halves the
/// wait of a slow program's audits.
const CHUNK_SECONDS: f64 = 0.25;
/// Most tests in a chunk: a chunk's events are held until it is
/// reported, so this bounds the worker's memory on a campaign whose tests
/// are mostly events (2²² tests, at most 64 MB of events), whatever its
/// threads' rate. A lease longer than that runs in several chunks.
const MAX_CHUNK: u64 = 1 << 22;

/// The next chunk of a campaign whose last chunk ran at `rate` tests a
/// second on `threads` threads: [`CHUNK_SECONDS`] of work, at least one
/// test per thread (a test slower than the chunk's time is reported as
/// soon as it ends) and at most [`MAX_CHUNK`].
pub fn measured_chunk(rate: f64, threads: usize) -> u64 {
    ((rate * CHUNK_SECONDS) as u64).clamp(threads.max(1) as u64, MAX_CHUNK)
}

/// Campaigns whose chunk size a worker remembers: more than a coordinator
/// runs side by side in practice (leases take turns between campaigns).
const REMEMBERED_CAMPAIGNS: usize = 16;

/// The chunk size last measured on each of the campaigns a worker ran
/// most recently, so that a lease of any of them starts at its own size
/// ([`first_chunk`]) when leases alternate between campaigns.
#[derive(Debug, Default)]
pub struct ChunkSizes {
    /// `(campaign, size)`, the most recently measured first.
    sizes: Vec<(i64, u64)>,
}

impl ChunkSizes {
    /// The size last measured on `campaign`, if it is remembered.
    pub fn get(&self, campaign: i64) -> Option<u64> {
        self.sizes
            .iter()
            .find(|(c, _)| *c == campaign)
            .map(|&(_, size)| size)
    }

    /// Remembers `size` for `campaign`, forgetting the campaign measured
    /// longest ago beyond [`REMEMBERED_CAMPAIGNS`].
    pub fn set(&mut self, campaign: i64, size: u64) {
        self.sizes.retain(|(c, _)| *c != campaign);
        self.sizes.insert(0, (campaign, size));
        self.sizes.truncate(REMEMBERED_CAMPAIGNS);
    }
}

/// The first chunk of a lease of `left` tests. Of a campaign the worker
/// has measured a chunk of (`known`), that size, but at most half the
/// lease: so the lease runs in two chunks or more, the report of the last
/// but one asks for the next lease, and the threads start the second chunk
/// while the first is reported. Else [`CHUNK_SECONDS`] of work at the cost
/// per test the coordinator has measured (`seconds_per_test`, on one
/// thread; it comes with the lease), or, where nobody knows the cost yet,
/// one test per thread: a slow program's first result comes after one
/// test, and its time sizes the next chunk.
///
/// A first chunk of 64 tests per thread at every lease, as before, cost a
/// cheap campaign a tenth of the threads' time: a chunk of a few ms ran
/// while the last lease's final reports were checked and folded, and the
/// threads waited for that acknowledgement (measured: 1.8 of 2 cores busy
/// through the service, 1.9 after). Remembering only the last campaign's
/// size did the same to campaigns run side by side, whose leases alternate.
pub fn first_chunk(
    known: Option<u64>,
    threads: usize,
    left: u64,
    seconds_per_test: Option<f64>,
) -> u64 {
    let threads = threads.max(1) as u64;
    let size = match (known, seconds_per_test) {
        (Some(size), _) => size,
        (None, Some(cost)) if cost > 0.0 => {
            ((CHUNK_SECONDS * threads as f64 / cost) as u64).clamp(threads, MAX_CHUNK)
        }
        (None, _) => threads,
    };
    size.min(left.div_ceil(2)).max(1)
}

#[cfg(test)]
mod tests {
    use super::{first_chunk, measured_chunk, ChunkSizes, MAX_CHUNK, REMEMBERED_CAMPAIGNS};

    #[test]
    fn a_lease_of_a_known_campaign_starts_at_the_measured_chunk_but_in_two_parts() {
        // A campaign whose cost nobody knows: one test per thread.
        assert_eq!(first_chunk(None, 2, 1 << 20, None), 2);
        // The coordinator's cost: a quarter of a second of work, at least
        // a test per thread (50 ms a test on 2 threads: 10; 10 s: 2).
        assert_eq!(first_chunk(None, 2, 1 << 20, Some(0.05)), 10);
        assert_eq!(first_chunk(None, 2, 1 << 20, Some(10.0)), 2);
        assert_eq!(first_chunk(None, 2, 1 << 30, Some(1e-9)), MAX_CHUNK);
        // A measured one: its size, if the lease is twice that.
        assert_eq!(first_chunk(Some(5_000), 2, 1 << 20, Some(0.05)), 5_000);
        // A lease smaller than two chunks: its first half (rounded up).
        assert_eq!(first_chunk(Some(1 << 24), 2, 1_001, None), 501);
        assert_eq!(first_chunk(Some(1 << 24), 2, 1, None), 1);
        assert_eq!(first_chunk(Some(1 << 24), 2, 0, None), 1);
    }

    #[test]
    fn a_test_slower_than_a_chunk_is_reported_alone() {
        // 20 tests a second on 4 threads: 5 a chunk, more than a thread's.
        assert_eq!(measured_chunk(20.0, 4), 5);
        // One test every 10 s: one per thread.
        assert_eq!(measured_chunk(0.4, 4), 4);
        assert_eq!(measured_chunk(1e12, 1), MAX_CHUNK);
    }

    #[test]
    fn campaigns_whose_leases_alternate_keep_their_own_chunk_sizes() {
        let mut sizes = ChunkSizes::default();
        assert_eq!(sizes.get(7), None);
        sizes.set(7, 5_000);
        sizes.set(8, 90_000);
        // Leases of 7 and 8 alternating: each starts at its own size.
        assert_eq!(sizes.get(7), Some(5_000));
        assert_eq!(sizes.get(8), Some(90_000));
        sizes.set(7, 6_000);
        assert_eq!(sizes.get(7), Some(6_000));
        assert_eq!(sizes.get(8), Some(90_000));
        // Past the limit, the campaign measured longest ago is forgotten.
        for c in 100..100 + REMEMBERED_CAMPAIGNS as i64 - 1 {
            sizes.set(c, 1);
        }
        assert_eq!(sizes.get(7), Some(6_000));
        assert_eq!(sizes.get(8), None);
        assert_eq!(sizes.sizes.len(), REMEMBERED_CAMPAIGNS);
    }
}
