//! Lease requests that wait for work (`wait_seconds`, long polling).
//!
//! A worker with nothing to do asks with a wait; the coordinator holds the
//! request until work may have appeared and asks the store again (a claim,
//! one write). Where a request makes work claimable, its handler wakes the
//! waiting requests: all of them for a campaign created running, a library
//! turned ready (its pending campaigns run), a library build's runs or
//! results taken back ([`WorkSignal::announce`]); one for a single lease
//! given back ([`WorkSignal::announce_one`]), so a rolling restart of many
//! workers does not make every idle one claim at each release.
//!
//! Work also appears without such a request: a lease expires, a report
//! lets a campaign's leases go past where they stopped (its predicted stop,
//! a paired campaign's partner), an adaptive campaign opens its next stage.
//! A waiting request finds these by asking again on its own, first soon and
//! then less often, like the workers' idle polling it replaces: the k-th
//! recheck comes uniformly in `[c/2, c]`, `c = min(50 ms · 2ᵏ, recheck)`
//! (`--claim-recheck-seconds`, 5 s by default, the standalone worker's old
//! backoff ceiling). A worker whose last wait found nothing starts at `c =
//! recheck`: its rechecks do not begin anew at each of its requests. The
//! jitter spreads the rechecks of requests that started together. So an
//! idle worker costs the store about one claim per 3.75 s (its polling
//! cost one per 2.5 s), and a campaign starts at once instead of a poll
//! later.
//!
//! Registration before the ask: a request enables its wake-up before it
//! asks the store, so a wake between the store's answer and the wait is not
//! missed. On shutdown the signal closes and every wait ends, so the
//! server's graceful shutdown is not held by them.

use std::future::Future;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;
use tokio::sync::Notify;
use tokio::time::Instant;

/// The first recheck's ceiling of a worker's request after work; each one
/// after doubles it, up to the configured recheck.
pub const FIRST_RECHECK: Duration = Duration::from_millis(50);

/// Wakes the lease requests that wait for work.
#[derive(Debug, Clone, Default)]
pub struct WorkSignal {
    inner: Arc<Inner>,
}

#[derive(Debug, Default)]
struct Inner {
    notify: Notify,
    closed: AtomicBool,
    /// Wake-ups sent, of all and of one (what the tests check handlers
    /// send).
    announced: [AtomicU64; 2],
    /// Requests waiting now (`/metrics`: `tslg_lease_requests_waiting`):
    /// what an operator sees of idle workers, and what a test waits for
    /// before it makes work appear, so that the wake-up is what answers.
    waiting: AtomicU64,
}

/// One request counted as waiting until it stops (returns or is dropped
/// with its connection).
struct Waiting<'a>(&'a AtomicU64);

impl<'a> Waiting<'a> {
    fn new(count: &'a AtomicU64) -> Self {
        count.fetch_add(1, Ordering::SeqCst);
        Self(count)
    }
}

impl Drop for Waiting<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::SeqCst);
    }
}

impl WorkSignal {
    /// Work for many may have appeared: every waiting request asks again.
    pub fn announce(&self) {
        self.inner.announced[0].fetch_add(1, Ordering::Relaxed);
        self.inner.notify.notify_waiters();
    }

    /// One range may have become claimable: one waiting request asks again
    /// (or the next to wait asks at once, when none waits).
    pub fn announce_one(&self) {
        self.inner.announced[1].fetch_add(1, Ordering::Relaxed);
        self.inner.notify.notify_one();
    }

    /// Wake-ups sent so far: `[of all, of one]`.
    #[cfg(test)]
    pub fn announced(&self) -> [u64; 2] {
        self.inner
            .announced
            .each_ref()
            .map(|a| a.load(Ordering::Relaxed))
    }

    /// The coordinator is shutting down: every wait ends, and none starts.
    pub fn close(&self) {
        self.inner.closed.store(true, Ordering::SeqCst);
        self.inner.notify.notify_waiters();
    }

    fn closed(&self) -> bool {
        self.inner.closed.load(Ordering::SeqCst)
    }

    /// Lease requests waiting for work now: each counts from its first ask
    /// that found nothing (its wake-up registered) until it ends.
    pub fn waiting(&self) -> u64 {
        self.inner.waiting.load(Ordering::SeqCst)
    }

    /// Runs `ask` until it gives `Some`, or `wait` has passed, or the
    /// signal closes: again at each wake-up and at rechecks whose ceiling
    /// starts at `first` and doubles up to `recheck` (module doc), each
    /// `jitter()` (in `[0.5, 1]`) of its ceiling. `ask` runs at least once;
    /// a zero `wait` runs it once. The deadline ends the wait without
    /// asking again: the worker asks anew at once.
    pub async fn ask_until<T, E, F, Fut>(
        &self,
        wait: Duration,
        (first, recheck): (Duration, Duration),
        mut jitter: impl FnMut() -> f64,
        mut ask: F,
    ) -> Result<Option<T>, E>
    where
        F: FnMut() -> Fut,
        Fut: Future<Output = Result<Option<T>, E>>,
    {
        let deadline = Instant::now() + wait;
        let mut ceiling = first.min(recheck);
        let mut counted = None;
        loop {
            // Registered before asking: a wake-up from here on ends the
            // wait below at once.
            let woken = self.inner.notify.notified();
            tokio::pin!(woken);
            woken.as_mut().enable();
            if let Some(found) = ask().await? {
                return Ok(Some(found));
            }
            let now = Instant::now();
            if now >= deadline || self.closed() {
                return Ok(None);
            }
            counted.get_or_insert_with(|| Waiting::new(&self.inner.waiting));
            let pause = ceiling.mul_f64(jitter().clamp(0.5, 1.0));
            ceiling = (ceiling * 2).min(recheck);
            let until = (now + pause).min(deadline);
            let was_woken = tokio::time::timeout_at(until, woken).await.is_ok();
            if self.closed() || (!was_woken && until >= deadline) {
                return Ok(None);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(ms: u64) -> Duration {
        Duration::from_millis(ms)
    }

    /// The rechecks at their ceilings (`jitter() = 1`), growing to 0.5 s,
    /// with asks that find work from `ready` on (virtual time since the
    /// start): what they found, how many asks, and when it ended.
    async fn run(
        signal: &WorkSignal,
        wait: Duration,
        ready: Duration,
    ) -> (Option<u32>, u32, Duration) {
        let start = Instant::now();
        let mut asked = 0;
        let found = signal
            .ask_until(
                wait,
                (ms(50), ms(500)),
                || 1.0,
                || {
                    asked += 1;
                    let found = (start.elapsed() >= ready).then_some(asked);
                    async move { Ok::<_, ()>(found) }
                },
            )
            .await
            .unwrap();
        (found, asked, start.elapsed())
    }

    /// Work that appears with a wake-up is found at the wake-up, not at
    /// the next recheck: with tokio's clock paused, the times are exact.
    #[tokio::test(start_paused = true)]
    async fn a_wake_up_ends_the_wait_at_once() {
        for one in [false, true] {
            let signal = WorkSignal::default();
            let announcer = signal.clone();
            tokio::spawn(async move {
                tokio::time::sleep(ms(1234)).await;
                if one {
                    announcer.announce_one();
                } else {
                    announcer.announce();
                }
            });
            let (found, asked, at) = run(&signal, ms(10_000), ms(1234)).await;
            // Asked at 0 and at the rechecks 0.05, 0.15, 0.35 and 0.75 s,
            // then at the wake-up.
            assert_eq!((found, asked, at), (Some(6), 6, ms(1234)), "one: {one}");
            assert_eq!(signal.announced(), if one { [0, 1] } else { [1, 0] });
        }
    }

    /// Without a wake-up, work is found at the first recheck after it
    /// appears; the rechecks grow from 50 ms by doubling to the configured
    /// 0.5 s. Without work, the request ends at its deadline without asking
    /// again there.
    #[tokio::test(start_paused = true)]
    async fn rechecks_grow_find_unannounced_work_and_the_deadline_ends_the_wait() {
        let signal = WorkSignal::default();
        // Asks at 0, 0.05, 0.15, 0.35, 0.75, 1.25, 1.75, 2.25 s.
        let (found, asked, at) = run(&signal, ms(10_000), ms(1800)).await;
        assert_eq!((found, asked, at), (Some(8), 8, ms(2250)));
        let (found, asked, at) = run(&signal, ms(1200), ms(1_000_000)).await;
        assert_eq!((found, asked, at), (None, 5, ms(1200)));
        // A zero wait asks once and answers at once.
        let (found, asked, at) = run(&signal, Duration::ZERO, ms(1_000_000)).await;
        assert_eq!((found, asked, at), (None, 1, ms(0)));
        // Work there at once is found by the first ask.
        let (found, asked, at) = run(&signal, ms(10_000), Duration::ZERO).await;
        assert_eq!((found, asked, at), (Some(1), 1, ms(0)));
    }

    /// A request counts as waiting from its first empty ask until it ends:
    /// answered by a wake-up, or dropped (its client went away).
    #[tokio::test(start_paused = true)]
    async fn a_request_counts_as_waiting_until_it_ends() {
        let signal = WorkSignal::default();
        let waiter = {
            let signal = signal.clone();
            tokio::spawn(async move { run(&signal, ms(10_000), ms(1_000_000)).await })
        };
        tokio::time::sleep(ms(100)).await;
        assert_eq!(signal.waiting(), 1);
        waiter.abort();
        let _ = waiter.await;
        assert_eq!(signal.waiting(), 0, "a dropped request stops counting");
        let announcer = signal.clone();
        let counted = tokio::spawn(async move {
            tokio::time::sleep(ms(300)).await;
            let seen = announcer.waiting();
            announcer.announce();
            seen
        });
        // Found at the wake-up (the work is there from 0.3 s on).
        let (found, _, at) = run(&signal, ms(10_000), ms(300)).await;
        assert_eq!((found.is_some(), at), (true, ms(300)));
        assert_eq!((counted.await.unwrap(), signal.waiting()), (1, 0));
        // A request answered by its first ask never waits.
        run(&signal, ms(10_000), Duration::ZERO).await;
        assert_eq!(signal.waiting(), 0);
    }

    /// A request of an idle worker starts at the long ceiling: asks at 0,
    /// 0.5, 1.0 s and so on, not at 0.05, 0.15 s.
    #[tokio::test(start_paused = true)]
    async fn an_idle_worker_s_rechecks_start_at_the_ceiling() {
        let signal = WorkSignal::default();
        let start = Instant::now();
        let mut at = Vec::new();
        let found = signal
            .ask_until(
                ms(1200),
                (ms(500), ms(500)),
                || 1.0,
                || {
                    at.push(start.elapsed());
                    async move { Ok::<Option<()>, ()>(None) }
                },
            )
            .await
            .unwrap();
        assert_eq!(found, None);
        assert_eq!(at, [ms(0), ms(500), ms(1000)]);
        assert_eq!(start.elapsed(), ms(1200));
    }

    /// The jitter shortens a recheck to between half its ceiling and all
    /// of it: at half, the asks come at 0, 0.025, 0.075, 0.175 s.
    #[tokio::test(start_paused = true)]
    async fn the_jitter_spreads_the_rechecks() {
        let signal = WorkSignal::default();
        let start = Instant::now();
        let mut at = Vec::new();
        let found = signal
            .ask_until(
                ms(10_000),
                (ms(50), ms(500)),
                || 0.0,
                || {
                    at.push(start.elapsed());
                    let n = at.len();
                    async move { Ok::<_, ()>((n == 4).then_some(n)) }
                },
            )
            .await
            .unwrap();
        assert_eq!(found, Some(4));
        assert_eq!(at, [ms(0), ms(25), ms(75), ms(175)]);
    }

    /// Closing ends the waits in progress at once, and later requests ask
    /// once without waiting.
    #[tokio::test(start_paused = true)]
    async fn closing_ends_every_wait() {
        let signal = WorkSignal::default();
        let closer = signal.clone();
        tokio::spawn(async move {
            tokio::time::sleep(ms(700)).await;
            closer.close();
        });
        let (found, asked, at) = run(&signal, ms(30_000), ms(1_000_000)).await;
        assert_eq!((found, asked, at), (None, 4, ms(700)));
        let (found, asked, at) = run(&signal, ms(30_000), ms(1_000_000)).await;
        assert_eq!((found, asked, at), (None, 1, ms(0)));
    }

    /// A wake-up sent while the store is being asked (after the request
    /// registered) is not lost: the wait ends at once and asks again. Of
    /// all, or of one with no other request waiting.
    #[tokio::test(start_paused = true)]
    async fn a_wake_up_during_the_ask_is_not_missed() {
        for one in [false, true] {
            let signal = WorkSignal::default();
            let inner = signal.clone();
            let mut asked = 0;
            let start = Instant::now();
            let found = signal
                .ask_until(
                    ms(10_000),
                    (ms(50), ms(500)),
                    || 1.0,
                    || {
                        asked += 1;
                        if asked == 1 {
                            if one {
                                inner.announce_one();
                            } else {
                                inner.announce();
                            }
                        }
                        let n = asked;
                        async move { Ok::<_, ()>((n == 2).then_some(n)) }
                    },
                )
                .await
                .unwrap();
            assert_eq!(found, Some(2), "one: {one}");
            assert_eq!(start.elapsed(), Duration::ZERO, "one: {one}");
        }
    }

    /// A wake-up of one wakes one of two waiting requests, and the other
    /// waits on to its recheck; a wake-up of all wakes both.
    #[tokio::test(start_paused = true)]
    async fn one_wakes_one_and_all_wake_all() {
        for one in [true, false] {
            let signal = WorkSignal::default();
            let announcer = signal.clone();
            tokio::spawn(async move {
                tokio::time::sleep(ms(1000)).await;
                if one {
                    announcer.announce_one();
                } else {
                    announcer.announce();
                }
            });
            // Work from 1 s on for both; a recheck ceiling of 30 s, so
            // after 0.75 s only a wake-up asks before 1.55 s.
            let wait_for = |signal: WorkSignal| async move {
                let start = Instant::now();
                signal
                    .ask_until(
                        ms(10_000),
                        (ms(50), ms(30_000)),
                        || 1.0,
                        || {
                            let found = (start.elapsed() >= ms(1000)).then_some(start.elapsed());
                            async move { Ok::<_, ()>(found) }
                        },
                    )
                    .await
                    .unwrap()
                    .unwrap()
            };
            let (a, b) = tokio::join!(wait_for(signal.clone()), wait_for(signal.clone()));
            let mut ends = [a, b];
            ends.sort();
            let expected = if one {
                [ms(1000), ms(1550)]
            } else {
                [ms(1000), ms(1000)]
            };
            assert_eq!(ends, expected, "one: {one}");
        }
    }
}
