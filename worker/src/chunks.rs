//! How many tests a worker runs between two reports of a lease: a chunk of
//! about [`CHUNK_SECONDS`] of work, measured on each campaign.

/// A chunk aims at this much work, so reports double as heartbeats and a
/// stopped campaign is noticed quickly.
const CHUNK_SECONDS: f64 = 0.5;
const FIRST_CHUNK_PER_THREAD: u64 = 64;
/// Most tests in a chunk: a chunk's events are held until it is
/// reported, so this bounds the worker's memory on a campaign whose tests
/// are mostly events (2²² tests, at most 64 MB of events), whatever its
/// threads' rate. A lease longer than that runs in several chunks.
const MAX_CHUNK: u64 = 1 << 22;

/// The next chunk of a campaign whose last chunk ran at `rate` tests a
/// second: [`CHUNK_SECONDS`] of work, at least 16 tests and at most
/// [`MAX_CHUNK`].
pub fn measured_chunk(rate: f64) -> u64 {
    ((rate * CHUNK_SECONDS) as u64).clamp(16, MAX_CHUNK)
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
/// while the first is reported. Else a small first chunk, whose time sizes
/// the next.
///
/// A first chunk of 64 tests per thread at every lease, as before, cost a
/// cheap campaign a tenth of the threads' time: a chunk of a few ms ran
/// while the last lease's final reports were checked and folded, and the
/// threads waited for that acknowledgement (measured: 1.8 of 2 cores busy
/// through the service, 1.9 after). Remembering only the last campaign's
/// size did the same to campaigns run side by side, whose leases alternate.
pub fn first_chunk(known: Option<u64>, threads: usize, left: u64) -> u64 {
    match known {
        Some(size) => size.min(left.div_ceil(2)).max(1),
        None => FIRST_CHUNK_PER_THREAD * threads as u64,
    }
}

#[cfg(test)]
mod tests {
    use super::{first_chunk, ChunkSizes, REMEMBERED_CAMPAIGNS};

    #[test]
    fn a_lease_of_a_known_campaign_starts_at_the_measured_chunk_but_in_two_parts() {
        // A campaign never measured: a small first chunk.
        assert_eq!(first_chunk(None, 2, 1 << 20), 128);
        // A measured one: its size, if the lease is twice that.
        assert_eq!(first_chunk(Some(5_000), 2, 1 << 20), 5_000);
        // A lease smaller than two chunks: its first half (rounded up).
        assert_eq!(first_chunk(Some(1 << 24), 2, 1_001), 501);
        assert_eq!(first_chunk(Some(1 << 24), 2, 1), 1);
        assert_eq!(first_chunk(Some(1 << 24), 2, 0), 1);
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
