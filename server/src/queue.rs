//! How many workers the running campaigns want (`GET /api/v1/queue`, the
//! gauge `tslg_workers_wanted`): what an autoscaler scales a fleet by.
//!
//! Per program (`NAME:case:mode`, or `builtin` for the built-in vehicles,
//! which every worker runs), the running campaigns' predicted remaining
//! tests cost `S = Σ (predicted − tests) · c` worker-thread seconds, `c` the
//! measured cost of one test on one thread. Workers of `t` threads each
//! finish it within the target `T` when there are `⌈S / (T t)⌉` of them.
//! A campaign without a prediction yet (fewer events than its rule's
//! `min_events`) still needs at least the largest of: as many tests again
//! as it has run (its work so far is no more than half of it), the tests
//! to its `n_min`, and, once it has events, the tests its event rate says
//! it takes to reach `min_events`, `(min_events − events) · n / events`.
//! Those count as its tests needed (`· c` worker-thread seconds, once `c`
//! is measured), so while its work cannot be sized the fleet grows with it:
//! an autoscaler polling every few seconds doubles it about every `T ln 2`
//! seconds where a rule of "the workers it has" would keep the first
//! worker until the prediction comes (measured in docs/benchmarks.md,
//! "Autoscaling"). It also wants at least the workers serving it now, or
//! one: an autoscaler must not scale down a fleet whose work it cannot yet
//! size, nor leave a campaign nobody serves. No running campaign: 0, so a
//! fleet can scale to zero.

use crate::store::campaigns::CampaignRow;
use crate::workers::Fleet;
use std::collections::BTreeMap;
use tslg_api::{ProgramDemand, QueueView};

/// The key of the built-in vehicles' demand.
pub const BUILTIN: &str = "builtin";

/// What the queue needs of one running campaign.
#[derive(Debug, Clone, PartialEq)]
pub struct RunningCampaign {
    /// Its program, `None` for a built-in vehicle.
    pub requires: Option<String>,
    /// Tests still predicted to be needed, when predicted.
    pub tests_needed: Option<u64>,
    /// The fewest tests it still needs while it has no prediction (see
    /// the module).
    pub at_least: u64,
    /// Seconds one test takes on one thread, when measured.
    pub cost_per_test: Option<f64>,
}

impl RunningCampaign {
    /// The queue's view of a running campaign `row`, whose prediction is
    /// `predicted_tests` (total tests, as the campaign's view says).
    pub fn of(row: &CampaignRow, predicted_tests: Option<u64>) -> Self {
        Self {
            requires: row.requires.clone(),
            tests_needed: predicted_tests.map(|p| p.saturating_sub(row.tests.max(0) as u64)),
            at_least: tests_at_least(row),
            cost_per_test: row.cost_per_test.filter(|c| c.is_finite() && *c > 0.0),
        }
    }
}

/// The fewest tests a running campaign without a prediction still needs
/// (see the module).
fn tests_at_least(row: &CampaignRow) -> u64 {
    // The campaign's own rule: a campaign of a pair never reaches its
    // fold's `min_events` (its pair stops it), which would be no bound.
    let rule = row.rule();
    let tests = row.tests.max(0) as u64;
    least_tests(tests, row.events.max(0) as u64, rule.n_min, rule.min_events)
        .min(rule.max_tests.saturating_sub(tests))
}

/// [`tests_at_least`] of a campaign with `tests` valid tests and `events`
/// events under a rule of `n_min` and `min_events` (a prediction needs at
/// least 2 events).
fn least_tests(tests: u64, events: u64, n_min: u64, min_events: u64) -> u64 {
    let to_min_events = if events > 0 {
        let missing = min_events.max(2).saturating_sub(events) as f64;
        (missing * tests as f64 / events as f64).ceil() as u64
    } else {
        0
    };
    tests.max(n_min.saturating_sub(tests)).max(to_min_events)
}

/// The demand of the running campaigns `rows` (each predicted as its view
/// predicts it) on `fleet`, for the target `target_seconds`, of the
/// program `only` when given ([`demand_of`]).
pub fn of_rows(
    rows: &[CampaignRow],
    fleet: &Fleet,
    target_seconds: f64,
    only: Option<&str>,
) -> QueueView {
    let running: Vec<RunningCampaign> = rows
        .iter()
        .map(|row| {
            RunningCampaign::of(
                row,
                crate::campaign::views::campaign_view(row).predicted_tests,
            )
        })
        .collect();
    demand_of(&running, fleet, target_seconds, only)
}

/// The demand of `campaigns` on `fleet`, for the target `target_seconds`;
/// of the program `only` alone when given (`NAME`, every case and mode of
/// it, a whole `NAME:case:mode`, or `builtin`): its entries and their
/// total, what one Deployment or job name that runs that program scales by
/// (`GET /api/v1/queue?program=NAME`).
pub fn demand_of(
    campaigns: &[RunningCampaign],
    fleet: &Fleet,
    target_seconds: f64,
    only: Option<&str>,
) -> QueueView {
    let mut programs: BTreeMap<String, ProgramDemand> = BTreeMap::new();
    let entry = |programs: &mut BTreeMap<String, ProgramDemand>, key: &str| {
        let (workers, threads) = match key {
            BUILTIN => (fleet.workers, fleet.threads),
            program => (
                fleet.serving_workers(Some(program)),
                fleet.serving(Some(program)),
            ),
        };
        programs
            .entry(key.to_owned())
            .or_insert_with(|| ProgramDemand {
                program: key.to_owned(),
                campaigns: 0,
                tests_needed: 0,
                worker_seconds: None,
                unpredicted: 0,
                workers,
                threads,
                workers_wanted: 0,
            });
    };
    for offer in fleet.offering.keys() {
        entry(&mut programs, offer);
    }
    if fleet.workers > 0 {
        entry(&mut programs, BUILTIN);
    }
    for campaign in campaigns {
        let key = campaign.requires.as_deref().unwrap_or(BUILTIN);
        entry(&mut programs, key);
        let d = programs.get_mut(key).expect("just entered");
        d.campaigns += 1;
        match (campaign.tests_needed, campaign.cost_per_test) {
            (Some(tests), Some(cost)) => {
                d.tests_needed = d.tests_needed.saturating_add(tests);
                d.worker_seconds = Some(d.worker_seconds.unwrap_or(0.0) + tests as f64 * cost);
            }
            (Some(tests), None) => {
                d.tests_needed = d.tests_needed.saturating_add(tests);
                d.unpredicted += 1;
            }
            // The least it still needs (see the module).
            (None, Some(cost)) => {
                d.tests_needed = d.tests_needed.saturating_add(campaign.at_least);
                d.worker_seconds =
                    Some(d.worker_seconds.unwrap_or(0.0) + campaign.at_least as f64 * cost);
                d.unpredicted += 1;
            }
            (None, None) => d.unpredicted += 1,
        }
    }
    // Threads a new worker brings: the fleet's average, 1 with no fleet.
    let fleet_threads_per_worker = if fleet.workers > 0 {
        f64::from(fleet.threads) / f64::from(fleet.workers)
    } else {
        1.0
    };
    let wants: Vec<(ProgramDemand, Want)> = programs
        .into_values()
        .map(|mut d| {
            let want = wanted(&d, fleet_threads_per_worker, target_seconds);
            d.workers_wanted = want.workers();
            (d, want)
        })
        .filter(|(d, _)| only.is_none_or(|name| is_program(&d.program, name)))
        .collect();
    // The programs' work adds up; their floors (the workers serving a
    // campaign not yet sized) are the same workers when one fleet serves
    // several programs, so they do not.
    let work = wants
        .iter()
        .map(|(_, w)| w.work)
        .fold(0u32, u32::saturating_add);
    let largest = wants
        .iter()
        .map(|(d, _)| d.workers_wanted)
        .max()
        .unwrap_or(0);
    QueueView {
        target_seconds,
        workers_wanted: work.max(largest),
        programs: wants.into_iter().map(|(d, _)| d).collect(),
    }
}

/// Whether the demand key `key` (`NAME:case:mode`, or `builtin`) is the
/// program `name`: that key itself, or any case and mode of `NAME`.
fn is_program(key: &str, name: &str) -> bool {
    key == name || key.split(':').next() == Some(name)
}

/// What one program's campaigns want.
struct Want {
    /// Workers for its work: the (least) predicted work within the
    /// target, at least 1 while it has a campaign.
    work: u32,
    /// The workers serving a campaign not yet sized, kept.
    floor: u32,
}

impl Want {
    fn workers(&self) -> u32 {
        self.work.max(self.floor)
    }
}

/// The workers `d` wants (see the module).
fn wanted(d: &ProgramDemand, fleet_threads_per_worker: f64, target_seconds: f64) -> Want {
    if d.campaigns == 0 {
        return Want { work: 0, floor: 0 };
    }
    let per_worker = if d.workers > 0 {
        f64::from(d.threads) / f64::from(d.workers)
    } else {
        fleet_threads_per_worker
    }
    .max(1.0);
    let predicted = d.worker_seconds.map_or(0.0, |s| {
        (s / (target_seconds * per_worker))
            .ceil()
            .min(f64::from(u32::MAX))
    }) as u32;
    let floor = if d.unpredicted > 0 { d.workers } else { 0 };
    Want {
        work: predicted.max(1),
        floor,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The whole queue's demand.
    fn demand(campaigns: &[RunningCampaign], fleet: &Fleet, target_seconds: f64) -> QueueView {
        demand_of(campaigns, fleet, target_seconds, None)
    }

    fn fleet(workers: &[(u32, &[&str])]) -> Fleet {
        let mut fleet = Fleet::default();
        for &(threads, offers) in workers {
            fleet.add(threads, offers.iter().map(|o| o.to_string()));
        }
        fleet
    }

    fn running(requires: Option<&str>, tests: Option<u64>, cost: Option<f64>) -> RunningCampaign {
        RunningCampaign {
            requires: requires.map(str::to_owned),
            tests_needed: tests,
            at_least: 0,
            cost_per_test: cost,
        }
    }

    fn wanted_for<'a>(view: &'a QueueView, program: &str) -> &'a ProgramDemand {
        view.programs
            .iter()
            .find(|d| d.program == program)
            .unwrap_or_else(|| panic!("no {program} in {view:?}"))
    }

    #[test]
    fn nothing_running_wants_nobody_even_with_a_fleet() {
        let view = demand(&[], &fleet(&[(4, &["py:cut-in:step"])]), 300.0);
        assert_eq!(view.workers_wanted, 0);
        assert_eq!(wanted_for(&view, "py:cut-in:step").workers_wanted, 0);
        assert_eq!(wanted_for(&view, BUILTIN).workers, 1);
        assert_eq!(demand(&[], &Fleet::default(), 300.0).programs, Vec::new());
    }

    #[test]
    fn predicted_work_is_sized_by_the_target_and_the_workers_threads() {
        // 12,000 tests of 0.5 s on one thread: 6,000 thread-seconds. With
        // 4-thread workers and 300 s: ⌈6000 / 1200⌉ = 5.
        let campaigns = [running(Some("py:cut-in:step"), Some(12_000), Some(0.5))];
        let view = demand(&campaigns, &fleet(&[(4, &["py:cut-in:step"])]), 300.0);
        let d = wanted_for(&view, "py:cut-in:step");
        assert_eq!(
            (d.campaigns, d.tests_needed, d.workers, d.threads),
            (1, 12_000, 1, 4)
        );
        assert_eq!(d.worker_seconds, Some(6_000.0));
        assert_eq!(d.workers_wanted, 5);
        // A longer target, fewer workers; never fewer than one.
        assert_eq!(
            demand(&campaigns, &fleet(&[(4, &["py:cut-in:step"])]), 600.0).workers_wanted,
            3
        );
        let tiny = [running(None, Some(10), Some(1e-6))];
        assert_eq!(demand(&tiny, &Fleet::default(), 300.0).workers_wanted, 1);
    }

    #[test]
    fn a_campaign_nobody_serves_or_not_yet_sized_wants_at_least_one_or_the_current_workers() {
        // Nobody offers the program: one is wanted, with the fleet's threads
        // per worker as a new worker's.
        let campaigns = [running(Some("rig:cut-in:episode"), None, None)];
        let view = demand(&campaigns, &fleet(&[(8, &[])]), 300.0);
        let d = wanted_for(&view, "rig:cut-in:episode");
        assert_eq!((d.workers, d.unpredicted, d.workers_wanted), (0, 1, 1));
        // Three workers serve a campaign not yet predicted: keep them.
        let rig: &[&str] = &["rig:cut-in:episode"];
        let three = fleet(&[(2, rig); 3]);
        assert_eq!(demand(&campaigns, &three, 300.0).workers_wanted, 3);
        // Built-in vehicles are served by every worker.
        let builtin = [running(None, Some(100_000), Some(0.001))];
        let view = demand(&builtin, &three, 300.0);
        let d = wanted_for(&view, BUILTIN);
        assert_eq!((d.workers, d.threads, d.workers_wanted), (3, 6, 1));
        assert_eq!(view.workers_wanted, 1, "{view:?}");
    }

    #[test]
    fn a_campaign_not_yet_predicted_wants_workers_for_the_least_work_it_still_has() {
        // At least 600 tests of 0.5 s left: 300 thread-seconds; with
        // 1-thread workers and a 60 s target, 5.
        let rig: &[&str] = &["rig:cut-in:episode"];
        let campaign = RunningCampaign {
            at_least: 600,
            ..running(Some("rig:cut-in:episode"), None, Some(0.5))
        };
        let view = demand(std::slice::from_ref(&campaign), &fleet(&[(1, rig)]), 60.0);
        let d = wanted_for(&view, "rig:cut-in:episode");
        assert_eq!(
            (
                d.unpredicted,
                d.tests_needed,
                d.worker_seconds,
                d.workers_wanted
            ),
            (1, 600, Some(300.0), 5)
        );
        // As it runs on, the want grows with it: twice the least work,
        // twice the workers.
        let further = RunningCampaign {
            at_least: 1_200,
            ..campaign.clone()
        };
        let view = demand(&[further], &fleet(&[(1, rig); 5]), 60.0);
        assert_eq!(wanted_for(&view, "rig:cut-in:episode").workers_wanted, 10);
        // Never below the workers serving it while it cannot be sized.
        let view = demand(&[campaign], &fleet(&[(1, rig); 7]), 60.0);
        assert_eq!(wanted_for(&view, "rig:cut-in:episode").workers_wanted, 7);
    }

    #[test]
    fn the_least_work_of_an_unpredicted_campaign_is_its_tests_its_floor_or_its_way_to_min_events() {
        // No test yet: the floor n_min.
        assert_eq!(least_tests(0, 0, 30, 10), 30);
        // No event in 500 tests: as many again.
        assert_eq!(least_tests(500, 0, 30, 10), 500);
        // 3 events in 100 tests: 7 more at 3 per 100 is 234 tests.
        assert_eq!(least_tests(100, 3, 30, 10), 234);
        // 9 events in 4,000: 445 to the tenth, fewer than as many again.
        assert_eq!(least_tests(4_000, 9, 30, 10), 4_000);
        // min_events below 2 still needs 2 events for a prediction.
        assert_eq!(least_tests(10, 1, 0, 0), 10);
        assert_eq!(least_tests(40, 1, 0, 1), 40);
    }

    #[test]
    fn workers_kept_for_unsized_campaigns_count_once_but_work_adds_up() {
        // Four workers run the built-in vehicles and the program x: an
        // unsized campaign of each keeps the four, not eight.
        let x: &[&str] = &["x:cut-in:step"];
        let four = fleet(&[(1, x); 4]);
        let unsized_both = [
            running(None, None, None),
            running(Some("x:cut-in:step"), None, None),
        ];
        let view = demand(&unsized_both, &four, 60.0);
        assert_eq!(wanted_for(&view, BUILTIN).workers_wanted, 4);
        assert_eq!(wanted_for(&view, "x:cut-in:step").workers_wanted, 4);
        assert_eq!(view.workers_wanted, 4, "{view:?}");
        // Predicted work of both adds up: 600 and 300 thread-seconds in
        // 60 s on 1-thread workers are 10 and 5 workers.
        let sized_both = [
            running(None, Some(6_000), Some(0.1)),
            running(Some("x:cut-in:step"), Some(3_000), Some(0.1)),
        ];
        assert_eq!(demand(&sized_both, &four, 60.0).workers_wanted, 15);
        // A campaign of a pair never predicts, and its fold's min_events
        // is unbounded: its least work stays bounded by its max_tests.
        assert_eq!(least_tests(1_000, 3, 30, u64::MAX), u64::MAX);
        let paired = RunningCampaign {
            at_least: u64::MAX,
            ..running(Some("x:cut-in:step"), None, Some(0.1))
        };
        let view = demand(&[paired.clone(), paired], &four, 60.0);
        assert_eq!(wanted_for(&view, "x:cut-in:step").tests_needed, u64::MAX);
    }

    #[test]
    fn one_programs_demand_is_its_entries_of_every_case_and_mode() {
        let campaigns = [
            running(Some("av:cut-in:step"), Some(600), Some(1.0)),
            running(Some("av:highway-exit:episode"), Some(600), Some(1.0)),
            running(Some("other:cut-in:step"), Some(6_000), Some(1.0)),
            running(None, Some(60_000), Some(0.001)),
        ];
        let none = Fleet::default();
        // 600 s each in 60 s on 1-thread workers: 10 + 10.
        let av = demand_of(&campaigns, &none, 60.0, Some("av"));
        assert_eq!(av.programs.len(), 2, "{av:?}");
        assert_eq!(av.workers_wanted, 20);
        let one = demand_of(&campaigns, &none, 60.0, Some("av:cut-in:step"));
        assert_eq!((one.programs.len(), one.workers_wanted), (1, 10));
        let builtin = demand_of(&campaigns, &none, 60.0, Some(BUILTIN));
        assert_eq!((builtin.programs.len(), builtin.workers_wanted), (1, 1));
        // A program with nothing running and nobody offering it: nothing,
        // and 0 for an autoscaler to read.
        let absent = demand_of(&campaigns, &none, 60.0, Some("nobody"));
        assert_eq!((absent.programs.len(), absent.workers_wanted), (0, 0));
        // The whole queue: 10 + 10 + 100 + 1.
        assert_eq!(demand(&campaigns, &none, 60.0).workers_wanted, 121);
    }

    #[test]
    fn joining_workers_do_not_change_the_predicted_demand() {
        // The want is the work's, not the fleet's: as workers join, what
        // is wanted stays, and the gap (wanted − workers) closes.
        let campaigns = [running(Some("py:cut-in:step"), Some(36_000), Some(0.1))];
        for n in 0..6u32 {
            let workers: Vec<(u32, &[&str])> =
                (0..n).map(|_| (2, &["py:cut-in:step"][..])).collect();
            let view = demand(&campaigns, &fleet(&workers), 300.0);
            // 3,600 thread-seconds over 2-thread workers in 300 s: 6
            // (1-thread workers while none is there: 12).
            let expected = if n == 0 { 12 } else { 6 };
            assert_eq!(
                wanted_for(&view, "py:cut-in:step").workers_wanted,
                expected,
                "{n}"
            );
        }
    }
}
