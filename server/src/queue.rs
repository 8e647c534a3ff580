//! How many workers the running campaigns want (`GET /api/v1/queue`, the
//! gauge `tslg_workers_wanted`): what an autoscaler scales a fleet by.
//!
//! Per program (`NAME:case:mode`, or `builtin` for the built-in vehicles,
//! which every worker runs), the running campaigns' predicted remaining
//! tests cost `S = Σ (predicted − tests) · c` worker-thread seconds, `c` the
//! measured cost of one test on one thread. Workers of `t` threads each
//! finish it within the target `T` when there are `⌈S / (T t)⌉` of them.
//! A campaign without a prediction yet (its first tests, or no cost
//! measured) wants at least the workers serving it now, or one: an
//! autoscaler must not scale down a fleet whose work it cannot yet size,
//! nor leave a campaign nobody serves. No running campaign: 0, so a fleet
//! can scale to zero.

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
            cost_per_test: row.cost_per_test.filter(|c| c.is_finite() && *c > 0.0),
        }
    }
}

/// The demand of the running campaigns `rows` (each predicted as its view
/// predicts it) on `fleet`, for the target `target_seconds`.
pub fn of_rows(rows: &[CampaignRow], fleet: &Fleet, target_seconds: f64) -> QueueView {
    let running: Vec<RunningCampaign> = rows
        .iter()
        .map(|row| {
            RunningCampaign::of(
                row,
                crate::campaign::views::campaign_view(row).predicted_tests,
            )
        })
        .collect();
    demand(&running, fleet, target_seconds)
}

/// The demand of `campaigns` on `fleet`, for the target `target_seconds`.
pub fn demand(campaigns: &[RunningCampaign], fleet: &Fleet, target_seconds: f64) -> QueueView {
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
                d.tests_needed += tests;
                d.worker_seconds = Some(d.worker_seconds.unwrap_or(0.0) + tests as f64 * cost);
            }
            (Some(tests), None) => {
                d.tests_needed += tests;
                d.unpredicted += 1;
            }
            (None, _) => d.unpredicted += 1,
        }
    }
    // Threads a new worker brings: the fleet's average, 1 with no fleet.
    let fleet_threads_per_worker = if fleet.workers > 0 {
        f64::from(fleet.threads) / f64::from(fleet.workers)
    } else {
        1.0
    };
    for d in programs.values_mut() {
        d.workers_wanted = wanted(d, fleet_threads_per_worker, target_seconds);
    }
    let programs: Vec<ProgramDemand> = programs.into_values().collect();
    QueueView {
        target_seconds,
        workers_wanted: programs
            .iter()
            .map(|d| d.workers_wanted)
            .fold(0u32, u32::saturating_add),
        programs,
    }
}

/// The workers `d` wants (see the module).
fn wanted(d: &ProgramDemand, fleet_threads_per_worker: f64, target_seconds: f64) -> u32 {
    if d.campaigns == 0 {
        return 0;
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
    let not_sized = if d.unpredicted > 0 {
        d.workers.max(1)
    } else {
        0
    };
    predicted.max(not_sized).max(1)
}

#[cfg(test)]
mod tests {
    use super::*;

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
