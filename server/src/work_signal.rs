//! Lease requests that wait for work (`wait_seconds`, long polling).
//!
//! A worker with nothing to do asks with a wait; the coordinator holds the
//! request until work may have appeared and asks the store again. Where
//! work appears by a request (a campaign created running, a library ready
//! and its campaigns with it, a library build's runs, a lease given back)
//! the handler [`WorkSignal::announce`]s it and every waiting request asks
//! at once, so a new campaign starts without a worker's polling delay.
//! Work also appears without a request: a lease expires, a campaign's
//! leases fall back below its predicted stop, an adaptive campaign opens
//! its next stage. A waiting request therefore also asks again every
//! recheck (`--claim-recheck-seconds`, half a second by default), which bounds the delay there as the workers' idle polling
//! did (their backoff's ceiling was half a second), at one store claim per
//! waiting worker per recheck instead of a request and a claim per poll.
//!
//! The signal is a generation count in a `watch` channel: a request reads
//! it before it asks the store, so an announcement between the store's
//! answer and the wait is not missed. On shutdown the signal closes and
//! every wait ends, so the server's graceful shutdown is not held by them.

use std::future::Future;
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::watch;
use tokio::time::Instant;

/// What the waiting requests watch: the generation of announced work and
/// whether the coordinator is shutting down.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Generation {
    count: u64,
    closed: bool,
}

/// Wakes the lease requests that wait for work.
#[derive(Debug, Clone)]
pub struct WorkSignal {
    sender: Arc<watch::Sender<Generation>>,
}

impl Default for WorkSignal {
    fn default() -> Self {
        Self {
            sender: Arc::new(watch::Sender::new(Generation::default())),
        }
    }
}

impl WorkSignal {
    /// Work may have appeared: every waiting request asks again now.
    pub fn announce(&self) {
        self.sender.send_modify(|g| g.count += 1);
    }

    /// The coordinator is shutting down: every wait ends, and none starts.
    pub fn close(&self) {
        self.sender.send_modify(|g| g.closed = true);
    }

    /// Runs `ask` until it gives `Some`, or `wait` has passed, or the
    /// signal closes: again after each announcement and every `recheck`.
    /// `ask` runs at least once; a zero `wait` runs it once. The deadline
    /// ends the wait without asking again: the worker asks anew at once.
    pub async fn ask_until<T, E, F, Fut>(
        &self,
        wait: Duration,
        recheck: Duration,
        mut ask: F,
    ) -> Result<Option<T>, E>
    where
        F: FnMut() -> Fut,
        Fut: Future<Output = Result<Option<T>, E>>,
    {
        let deadline = Instant::now() + wait;
        loop {
            // Subscribed before asking: an announcement from here on wakes
            // the wait below.
            let mut watching = self.sender.subscribe();
            if let Some(found) = ask().await? {
                return Ok(Some(found));
            }
            let now = Instant::now();
            if now >= deadline || watching.borrow().closed {
                return Ok(None);
            }
            let until = (now + recheck).min(deadline);
            // An announcement (or the close), the recheck or the deadline
            // (a dropped sender cannot happen while `self` holds it).
            let announced = tokio::time::timeout_at(until, watching.changed())
                .await
                .is_ok();
            if watching.borrow().closed || (!announced && until >= deadline) {
                return Ok(None);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicU32, Ordering};

    /// Asks that find work from `ready` on (virtual time since the start).
    async fn run(
        signal: &WorkSignal,
        wait: Duration,
        ready: Duration,
    ) -> (Option<u32>, u32, Duration) {
        let start = Instant::now();
        let asked = AtomicU32::new(0);
        let found = signal
            .ask_until(wait, ms(500), || {
                let n = asked.fetch_add(1, Ordering::SeqCst) + 1;
                let found = (start.elapsed() >= ready).then_some(n);
                async move { Ok::<_, ()>(found) }
            })
            .await
            .unwrap();
        (found, asked.load(Ordering::SeqCst), start.elapsed())
    }

    fn ms(ms: u64) -> Duration {
        Duration::from_millis(ms)
    }

    /// Work that appears by an announcement is found at the announcement,
    /// not at the next recheck: with tokio's clock paused, the times are
    /// exact.
    #[tokio::test(start_paused = true)]
    async fn an_announcement_wakes_the_wait_at_once() {
        let signal = WorkSignal::default();
        let announcer = signal.clone();
        tokio::spawn(async move {
            tokio::time::sleep(Duration::from_millis(1234)).await;
            announcer.announce();
        });
        let (found, asked, at) = run(
            &signal,
            Duration::from_secs(10),
            Duration::from_millis(1234),
        )
        .await;
        // Asked at 0, at the rechecks 0.5 and 1.0 s, then at the
        // announcement.
        assert_eq!((found, asked), (Some(4), 4));
        assert_eq!(at, ms(1234));
    }

    /// Without an announcement, work is found at the first recheck after
    /// it appears; without work, the request ends at its deadline, having
    /// asked at every recheck (not again at the deadline).
    #[tokio::test(start_paused = true)]
    async fn rechecks_find_unannounced_work_and_the_deadline_ends_the_wait() {
        let signal = WorkSignal::default();
        let (found, asked, at) = run(
            &signal,
            Duration::from_secs(10),
            Duration::from_millis(1100),
        )
        .await;
        assert_eq!((found, asked, at), (Some(4), 4, ms(1500)));
        let (found, asked, at) = run(
            &signal,
            Duration::from_millis(1200),
            Duration::from_secs(1000),
        )
        .await;
        assert_eq!((found, asked, at), (None, 3, ms(1200)));
        // A zero wait asks once and answers at once.
        let (found, asked, at) = run(&signal, Duration::ZERO, Duration::from_secs(1000)).await;
        assert_eq!((found, asked, at), (None, 1, ms(0)));
        // Work there at once is found by the first ask.
        let (found, asked, at) = run(&signal, Duration::from_secs(10), Duration::ZERO).await;
        assert_eq!((found, asked, at), (Some(1), 1, ms(0)));
    }

    /// With a recheck longer than the wait, only an announcement wakes it:
    /// unannounced work is left to the worker's next request.
    #[tokio::test(start_paused = true)]
    async fn a_long_recheck_leaves_unannounced_work_to_the_next_request() {
        let signal = WorkSignal::default();
        let asked = AtomicU32::new(0);
        let start = Instant::now();
        let found = signal
            .ask_until(Duration::from_secs(2), Duration::from_secs(30), || {
                let n = asked.fetch_add(1, Ordering::SeqCst) + 1;
                let found = (start.elapsed() >= ms(100)).then_some(n);
                async move { Ok::<_, ()>(found) }
            })
            .await
            .unwrap();
        assert_eq!((found, asked.load(Ordering::SeqCst)), (None, 1));
        assert_eq!(start.elapsed(), ms(2000));
    }

    /// Closing ends the waits in progress at once, and later requests ask
    /// once without waiting.
    #[tokio::test(start_paused = true)]
    async fn closing_ends_every_wait() {
        let signal = WorkSignal::default();
        let closer = signal.clone();
        tokio::spawn(async move {
            tokio::time::sleep(Duration::from_millis(700)).await;
            closer.close();
        });
        let (found, asked, at) =
            run(&signal, Duration::from_secs(30), Duration::from_secs(1000)).await;
        assert_eq!((found, asked, at), (None, 2, ms(700)));
        let (found, asked, at) =
            run(&signal, Duration::from_secs(30), Duration::from_secs(1000)).await;
        assert_eq!((found, asked, at), (None, 1, ms(0)));
    }

    /// An announcement made while the store is being asked (after the
    /// request read the generation) is not lost: the wait returns at once
    /// and asks again.
    #[tokio::test(start_paused = true)]
    async fn an_announcement_during_the_ask_is_not_missed() {
        let signal = WorkSignal::default();
        let inner = signal.clone();
        let asked = AtomicU32::new(0);
        let start = Instant::now();
        let found = signal
            .ask_until(Duration::from_secs(10), ms(500), || {
                let n = asked.fetch_add(1, Ordering::SeqCst) + 1;
                if n == 1 {
                    inner.announce();
                }
                async move { Ok::<_, ()>((n == 2).then_some(n)) }
            })
            .await
            .unwrap();
        assert_eq!(found, Some(2));
        assert_eq!(start.elapsed(), Duration::ZERO);
    }
}
