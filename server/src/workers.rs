//! The workers seen since the coordinator started, from their lease
//! requests: threads, the external programs they offer and those they
//! report unhealthy. Kept in memory: workers announce themselves with every
//! request, so a restarted coordinator knows them again within seconds.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tslg_api::{LeaseRequest, UnhealthyProgram, WorkerView};

/// A worker not heard from this long is not live.
const LIVE: Duration = Duration::from_secs(60);
/// A worker that left (said so) is listed this long after, then dropped:
/// a stopped fleet does not stay on the dashboard for ever.
const LEFT_LISTED: Duration = Duration::from_secs(600);
/// Workers kept at most; the longest unseen goes first.
const MAX_WORKERS: usize = 1024;
/// A counted [`Fleet`] serves the claims of this long, unless a worker
/// joins or changes meanwhile: workers leave on the scale of [`LIVE`],
/// and counting up to [`MAX_WORKERS`] entries at every claim would cost
/// the hot path tens of microseconds.
const FLEET_FRESH: Duration = Duration::from_secs(1);

struct Entry {
    threads: u32,
    offers: Vec<String>,
    /// Of `offers`, those whose program says its runs may differ.
    noisy: Vec<String>,
    unhealthy: Vec<UnhealthyProgram>,
    last_seen: Instant,
    /// Tests of its reports accepted, and how many were invalid.
    tests: u64,
    invalid: u64,
    /// Why it last gave a lease back, when it said.
    last_release: Option<String>,
    /// Its last lease request waited and found nothing: it is idle, and
    /// its next wait rechecks at the long ceiling from the start.
    idle: bool,
    /// It said it is leaving (`POST /api/v1/workers/{name}/leave`): not
    /// live from then on, until it asks for work again.
    left: bool,
    /// How many times it said so: a lease request held since before a
    /// leaving is its dropped wait, and takes nothing ([`Workers::leavings`]).
    leavings: u64,
}

impl Entry {
    /// Heard from within [`LIVE`], and not gone by its own word.
    fn is_live(&self) -> bool {
        !self.left && self.last_seen.elapsed() < LIVE
    }
}

/// The threads of the live workers: all of them, and those of the
/// workers offering each program (`NAME:case:mode`). A campaign's leases
/// are shared among the threads that can run it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Fleet {
    pub threads: u32,
    pub offering: HashMap<String, u32>,
    /// The live workers, and those offering each program.
    pub workers: u32,
    pub offering_workers: HashMap<String, u32>,
}

impl Fleet {
    /// Counts a live worker of `threads` threads offering `offers`.
    pub fn add(&mut self, threads: u32, offers: impl IntoIterator<Item = String>) {
        self.threads = self.threads.saturating_add(threads);
        self.workers = self.workers.saturating_add(1);
        let offers: std::collections::BTreeSet<String> = offers.into_iter().collect();
        for offer in offers {
            let t = self.offering.entry(offer.clone()).or_default();
            *t = t.saturating_add(threads);
            let w = self.offering_workers.entry(offer).or_default();
            *w = w.saturating_add(1);
        }
    }

    /// Live workers able to run a campaign that `requires` a program (all
    /// of them for a built-in vehicle).
    pub fn serving_workers(&self, requires: Option<&str>) -> u32 {
        match requires {
            None => self.workers,
            Some(program) => self.offering_workers.get(program).copied().unwrap_or(0),
        }
    }

    /// Threads able to run a campaign that `requires` a program (or none:
    /// a built-in vehicle, which every worker runs).
    pub fn serving(&self, requires: Option<&str>) -> u32 {
        match requires {
            None => self.threads,
            Some(program) => self.offering.get(program).copied().unwrap_or(0),
        }
    }
}

#[derive(Default)]
pub struct WorkerRegistry {
    workers: Mutex<HashMap<String, Entry>>,
    /// The last [`Fleet`] counted, and when.
    fleet: Mutex<Option<(Instant, Arc<Fleet>)>>,
    /// Set when a worker joined, came back or changed its threads or
    /// offers since the fleet was counted (after the change is in
    /// `workers`, so a count that misses it is done again).
    fleet_changed: AtomicBool,
}

impl WorkerRegistry {
    /// Records a lease request; logs programs turning unhealthy or healthy.
    pub fn seen(&self, request: &LeaseRequest) {
        let mut workers = self.workers.lock().unwrap_or_else(|p| p.into_inner());
        let before: Vec<String> = workers
            .get(&request.worker)
            .map(|e| e.unhealthy.iter().map(|u| u.name.clone()).collect())
            .unwrap_or_default();
        for u in &request.unhealthy {
            if !before.contains(&u.name) {
                tracing::warn!(
                    worker = %request.worker,
                    program = %u.name,
                    failures = u.failures,
                    reason = %u.reason,
                    "worker reports an external program unhealthy"
                );
            }
        }
        for name in before {
            if !request.unhealthy.iter().any(|u| u.name == name) {
                tracing::info!(worker = %request.worker, program = %name, "external program healthy again");
            }
        }
        if workers.len() >= MAX_WORKERS && !workers.contains_key(&request.worker) {
            let oldest = workers
                .iter()
                .min_by_key(|(_, e)| e.last_seen)
                .map(|(name, _)| name.clone());
            if let Some(oldest) = oldest {
                workers.remove(&oldest);
            }
        }
        let entry = workers
            .entry(request.worker.clone())
            .or_insert_with(|| Entry {
                threads: 0,
                offers: Vec::new(),
                noisy: Vec::new(),
                unhealthy: Vec::new(),
                last_seen: Instant::now(),
                tests: 0,
                invalid: 0,
                last_release: None,
                idle: false,
                left: false,
                leavings: 0,
            });
        let changed =
            entry.threads != request.threads || entry.offers != request.offers || !entry.is_live();
        entry.left = false;
        entry.threads = request.threads;
        entry.offers = request.offers.clone();
        entry.noisy = request.noisy.clone();
        entry.unhealthy = request.unhealthy.clone();
        entry.last_seen = Instant::now();
        if changed {
            self.fleet_changed.store(true, Ordering::Release);
        }
    }

    /// Whether `worker`'s last lease request waited and found nothing.
    /// The live workers whose program `requirement` said in its hello that
    /// its runs of one test may differ. Shown, never acted on: a worker's
    /// word must not turn a program's exact audits into statistical ones
    /// (a liar would then go unchecked); the campaign's `vehicle_noise`
    /// does.
    pub fn saying_noisy(&self, requirement: &str) -> Vec<String> {
        let workers = self.workers.lock().unwrap_or_else(|p| p.into_inner());
        let mut names: Vec<String> = workers
            .iter()
            .filter(|(_, e)| e.is_live() && e.noisy.iter().any(|n| n == requirement))
            .map(|(name, _)| name.clone())
            .collect();
        names.sort();
        names
    }

    pub fn idle(&self, worker: &str) -> bool {
        let workers = self.workers.lock().unwrap_or_else(|p| p.into_inner());
        workers.get(worker).is_some_and(|e| e.idle)
    }

    /// Records whether `worker`'s lease request waited and found nothing.
    pub fn set_idle(&self, worker: &str, idle: bool) {
        let mut workers = self.workers.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(entry) = workers.get_mut(worker) {
            entry.idle = idle;
        }
    }

    /// Counts a report's accepted tests toward the worker that sent it (one
    /// not seen by a lease request since the coordinator started is not
    /// listed, so not counted).
    pub fn reported(&self, worker: &str, tests: u64, invalid: u64) {
        let mut workers = self.workers.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(entry) = workers.get_mut(worker) {
            entry.tests += tests;
            entry.invalid += invalid;
            entry.last_seen = Instant::now();
        }
    }

    /// Keeps why a worker gave a lease back.
    pub fn released(&self, worker: &str, reason: &str) {
        let mut workers = self.workers.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(entry) = workers.get_mut(worker) {
            entry.last_release = Some(reason.to_owned());
            entry.last_seen = Instant::now();
        }
    }

    /// Takes `worker` out of the live fleet at once (it said it is
    /// leaving: a stopped pod, a batch job at its end), rather than a
    /// minute after its last request: autoscalers read the fleet.
    pub fn left(&self, worker: &str) {
        let mut workers = self.workers.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(entry) = workers.get_mut(worker) {
            entry.left = true;
            entry.last_seen = Instant::now();
            entry.leavings += 1;
            self.fleet_changed.store(true, Ordering::Release);
        }
    }

    /// How many times `worker` said it is leaving (0 for one not seen): a
    /// held lease request compares it with the count at its start, so
    /// that a wait its worker dropped as it stopped (the coordinator does
    /// not see the connection close while it holds the request) takes no
    /// lease that nobody would work.
    pub fn leavings(&self, worker: &str) -> u64 {
        let workers = self.workers.lock().unwrap_or_else(|p| p.into_inner());
        workers.get(worker).map_or(0, |e| e.leavings)
    }

    /// The live workers offering `requirement` (`NAME:case:mode`).
    pub fn live_offering(&self, requirement: &str) -> Vec<String> {
        let workers = self.workers.lock().unwrap_or_else(|p| p.into_inner());
        workers
            .iter()
            .filter(|(_, e)| e.is_live() && e.offers.iter().any(|o| o == requirement))
            .map(|(name, _)| name.clone())
            .collect()
    }

    /// Notes that `worker` was heard from (a heartbeat): a worker on a
    /// long test asks for no lease for a while, and is still live.
    pub fn heard(&self, worker: &str) {
        let mut workers = self.workers.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(entry) = workers.get_mut(worker) {
            if entry.last_seen.elapsed() >= LIVE {
                self.fleet_changed.store(true, Ordering::Release);
            }
            entry.last_seen = Instant::now();
        }
    }

    /// The threads of the live workers (see [`Fleet`]), counted at most
    /// [`FLEET_FRESH`] ago and since the last change of a worker.
    pub fn fleet(&self) -> Arc<Fleet> {
        let mut kept = self.fleet.lock().unwrap_or_else(|p| p.into_inner());
        let changed = self.fleet_changed.swap(false, Ordering::AcqRel);
        if let Some((at, fleet)) = kept.as_ref() {
            if !changed && at.elapsed() < FLEET_FRESH {
                return Arc::clone(fleet);
            }
        }
        let fleet = Arc::new(self.count_fleet());
        *kept = Some((Instant::now(), Arc::clone(&fleet)));
        fleet
    }

    fn count_fleet(&self) -> Fleet {
        let workers = self.workers.lock().unwrap_or_else(|p| p.into_inner());
        let mut fleet = Fleet::default();
        for entry in workers.values().filter(|e| e.is_live()) {
            fleet.add(entry.threads, entry.offers.iter().cloned());
        }
        fleet
    }

    /// Workers heard from within the last minute, and all workers known.
    pub fn counts(&self) -> (usize, usize) {
        let workers = self.workers.lock().unwrap_or_else(|p| p.into_inner());
        let live = workers.values().filter(|e| e.is_live()).count();
        (live, workers.len())
    }

    /// Every worker, most recently seen first, with why it is flagged if
    /// it is in `flagged` (`(name, reason)`); one that left more than
    /// [`LEFT_LISTED`] ago is forgotten.
    pub fn list(&self, flagged: &[(String, String)]) -> Vec<WorkerView> {
        let mut workers = self.workers.lock().unwrap_or_else(|p| p.into_inner());
        workers.retain(|_, e| !(e.left && e.last_seen.elapsed() >= LEFT_LISTED));
        let flag = |name: &str| {
            flagged
                .iter()
                .find(|(n, _)| n == name)
                .map(|(_, reason)| reason.clone())
        };
        let mut list: Vec<WorkerView> = workers
            .iter()
            .map(|(name, e)| WorkerView {
                name: name.clone(),
                threads: e.threads,
                last_seen_seconds: e.last_seen.elapsed().as_secs_f64(),
                live: e.is_live(),
                left: e.left,
                offers: e.offers.clone(),
                unhealthy: e.unhealthy.clone(),
                tests: e.tests,
                invalid: e.invalid,
                last_release_reason: e.last_release.clone(),
                flagged: flag(name),
                principal: None,
                registered_at: None,
                revoked_at: None,
                audits_given_back: 0,
                audits_given_back_in_row: 0,
                noisy_audits_compared: 0,
                noisy_own_events: 0,
                noisy_partner_events: 0,
                noisy_evidence: None,
                test_pairs_compared: 0,
                test_own_events: 0,
                test_partner_events: 0,
                test_evidence: None,
            })
            .collect();
        list.sort_by(|a, b| a.last_seen_seconds.total_cmp(&b.last_seen_seconds));
        list
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request(worker: &str, threads: u32, offers: &[&str]) -> LeaseRequest {
        LeaseRequest {
            worker: worker.into(),
            threads,
            include_tests: false,
            offers: offers.iter().map(|o| o.to_string()).collect(),
            unhealthy: Vec::new(),
            max_tests: None,
            wait_seconds: None,
            audits_only: false,
            noisy: Vec::new(),
        }
    }

    #[test]
    fn the_fleet_counts_a_worker_that_joins_or_changes_at_once() {
        let registry = WorkerRegistry::default();
        registry.seen(&request("a", 4, &["p:cut-in:episode"]));
        let fleet = registry.fleet();
        assert_eq!(fleet.serving(None), 4);
        assert_eq!(fleet.serving(Some("p:cut-in:episode")), 4);
        assert_eq!(fleet.serving(Some("q:cut-in:episode")), 0);
        // Kept while nothing changes.
        registry.seen(&request("a", 4, &["p:cut-in:episode"]));
        assert!(Arc::ptr_eq(&fleet, &registry.fleet()));
        // A worker joining, or one changing its offers, is counted at the
        // next claim, within the second the count is otherwise kept.
        registry.seen(&request("b", 2, &["p:cut-in:episode"]));
        assert_eq!(registry.fleet().serving(Some("p:cut-in:episode")), 6);
        registry.seen(&request("a", 4, &["q:cut-in:episode"]));
        let fleet = registry.fleet();
        assert_eq!(fleet.serving(Some("p:cut-in:episode")), 2);
        assert_eq!(fleet.serving(Some("q:cut-in:episode")), 4);
        assert_eq!(fleet.serving(None), 6);
    }

    #[test]
    fn a_worker_that_left_is_listed_as_left_then_forgotten() {
        let registry = WorkerRegistry::default();
        registry.seen(&request("a", 4, &[]));
        registry.seen(&request("b", 2, &[]));
        registry.left("a");
        let list = registry.list(&[]);
        let a = list.iter().find(|w| w.name == "a").unwrap();
        assert!(a.left && !a.live, "{a:?}");
        let b = list.iter().find(|w| w.name == "b").unwrap();
        assert!(!b.left && b.live, "{b:?}");
        // Ten minutes after it left, it is gone from the list; a worker
        // still working is not, however long its test.
        let long_ago = Instant::now().checked_sub(LEFT_LISTED).unwrap();
        {
            let mut workers = registry.workers.lock().unwrap();
            workers.get_mut("a").unwrap().last_seen = long_ago;
            workers.get_mut("b").unwrap().last_seen = long_ago;
        }
        let names: Vec<String> = registry.list(&[]).into_iter().map(|w| w.name).collect();
        assert_eq!(names, ["b"]);
        // Asking for work again brings it back, live.
        registry.seen(&request("a", 4, &[]));
        assert!(registry
            .list(&[])
            .iter()
            .any(|w| w.name == "a" && w.live && !w.left));
    }
}
