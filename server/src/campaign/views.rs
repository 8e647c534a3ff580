//! What the API and the dashboard show of a campaign: its row as a view
//! (estimate, interval, prediction, warnings), with what the coordinator
//! knows live (rate, time left, why it waits for workers, its audits and
//! its pair); and of a pair and a library.

use crate::campaign::history;
use crate::error::ServiceError;
use crate::leasing::size::tests_to_beta;
use crate::state::AppState;
use crate::store::audits::{self, AuditState};
use crate::store::campaigns::{self, CampaignRow};
use crate::store::error::StoreError;
use crate::store::libraries::LibraryRow;
use crate::store::pairs::{self, PairRow};
use rusqlite::Connection;
use tslg_api::{
    AdaptiveView, AuditCounts, CampaignStatus, CampaignView, HistoryPoint, LibraryView, PairStop,
    PairView, PairedInterval, RunningStage,
};
use tslg_method::campaign::CampaignResult;
use tslg_method::estimator::{Decision, StoppingRule};
use tslg_method::paired::PairedStop;
use tslg_method::warnings::{warnings, Dialect, WarningContext};

/// How the warnings' advice to rerun with the guard reads for a campaign of
/// a pair.
const PAIRED_RERUN: &str =
    "Rerun each vehicle as a campaign of its own (a pair takes no guard) with ";

/// `n (rₙ/β)²` valid tests, at least `n_min`, once the prefix has
/// `min_events` events (and at least 2); see [`crate::leasing::size`].
/// A guarded campaign needs as many more as its guard does
/// ([`tslg_method::prefix::PrefixFold::tests_to_guard`]), which is most of
/// them once the library stratum is known.
fn predicted_tests(rule: &StoppingRule, point: &HistoryPoint, row: &CampaignRow) -> Option<u64> {
    let r = point.relative_half_width?;
    let needed = tests_to_beta(point.tests, point.events, rule.min_events, r, rule.beta)?;
    let fold = row.fold();
    // Campaigns that switch (guarded Wald ones that track the strata,
    // anytime ones, guarded adaptive ones) explore nearly every test from
    // the switch on.
    let switches = fold.within_strata
        || (fold.strata.is_some() && row.interval() == tslg_method::estimator::Interval::Anytime)
        || (row.method.in_stages() && row.guard_outside);
    let share = if switches {
        tslg_method::sampling::LATE_SHARE
    } else {
        row.epsilon
    };
    let guard = row
        .outside_upper
        .and_then(|upper| fold.tests_to_guard(rule, upper, share));
    Some(
        needed
            .max(guard.unwrap_or(0))
            .max(rule.n_min)
            .max(point.tests),
    )
}

/// A campaign as the API shows it, from its row alone (no rate, audits or
/// pair: [`live_view`] adds them).
pub fn campaign_view(row: &CampaignRow) -> CampaignView {
    let rule = row.rule();
    let fold = row.fold();
    let point = history::point_of(&fold, rule.z(), row.sequence());
    let has_events = row.events > 0;
    let started = row.indices > 0;
    let summary =
        CampaignResult::with_outside_upper(Decision::Continue, &fold, rule.z(), row.outside_upper);
    // An anytime campaign's stored sequence, whose upper end holds the
    // exploring stratum's own bound where it has strata.
    let summary = match row.sequence() {
        Some(sequence) => summary.on_sequence(&fold, sequence, fold.strata.is_some()),
        None => summary,
    };
    let vut: serde_json::Value = serde_json::from_str(&row.vut).unwrap_or_default();
    let noisy = row.vehicle_noise || tslg_method::noise::spec_is_noisy(&vut);
    let answer = tslg_method::campaign::answer(
        &summary,
        tslg_method::campaign::AnswerContext {
            guard_outside: row.guard_outside,
            noisy,
            adaptive: row.method.in_stages(),
        },
    );
    CampaignView {
        id: row.id,
        case: row.case_name.clone(),
        method: row.method,
        method_facts: row.method.into(),
        library_id: row.library_id,
        vut_label: tslg_method::cases::vehicle_label(&vut, &row.case_name),
        vut,
        parameters_inert: row.parameters_inert,
        epsilon: row.epsilon,
        outside: row.outside,
        split: row.split,
        beta: row.beta,
        confidence: row.confidence,
        n_min: rule.n_min,
        min_events: rule.min_events,
        max_tests: rule.max_tests,
        seed: row.seed(),
        status: row.status,
        status_detail: row.status_detail.clone(),
        tests: row.tests as u64,
        events: row.events as u64,
        invalid: row.invalid as u64,
        indices: row.indices as u64,
        leased: row.next_index as u64,
        worker_seconds: row.worker_seconds,
        estimate: started.then_some(point.estimate),
        half_width: (row.tests > 1).then_some(point.half_width),
        relative_half_width: point.relative_half_width,
        ci_low: (row.tests > 1).then_some(point.ci_low),
        ci_high: (row.tests > 1).then_some(point.ci_high),
        // A campaign of a pair stops with its pair, not at its own β.
        predicted_tests: predicted_tests(&row.fold_rule(), &point, row),
        effective_events: has_events.then(|| fold.estimator.effective_events()),
        largest_weight_share: fold.estimator.largest_share(),
        guard_outside: row.guard_outside,
        interval: tslg_client::wire::wire_interval(rule.interval),
        explore_from: row.explore_from(),
        vehicle_noise: row.vehicle_noise,
        outside_tests: summary.outside_tests,
        outside_events: summary.outside_events,
        mismatched_events: summary.mismatched_events,
        outside_share: summary.outside_share,
        outside_upper: summary.outside_upper,
        guarded_ci_high: summary.guarded_ci_high.filter(|_| row.tests > 1),
        // Not before its upper end is known (a campaign whose outside
        // tally is being counted again has none yet).
        answer: (row.tests > 1 && answer.low.is_finite() && answer.high.is_finite()).then(|| {
            tslg_api::AnswerView {
                interval: match answer.interval {
                    tslg_method::campaign::AnswerInterval::Plain => tslg_api::AnswerInterval::Plain,
                    tslg_method::campaign::AnswerInterval::Guarded => {
                        tslg_api::AnswerInterval::Guarded
                    }
                },
                low: answer.low,
                high: answer.high,
                reason: answer.reason.text().to_owned(),
            }
        }),
        // Set once the view is whole ([`live_view`]).
        verdict: String::new(),
        exact_probability: row.exact_probability,
        adaptive: (row.method.in_stages()).then(|| AdaptiveView {
            library_tests: row.library_tests as u64,
            search_tests: row.search_tests as u64,
            stages: row.stages as u64,
            running: match (row.stage_start, row.stage_end, &row.stage_kind) {
                (Some(start), Some(end), Some(kind)) if !row.status.is_final() => {
                    Some(RunningStage {
                        kind: kind.clone(),
                        start: start as u64,
                        end: end as u64,
                    })
                }
                _ => None,
            },
            support: row.support as u64,
            search: row.adaptive_search,
            stage_tests: row.stage_tests.max(0) as u64,
        }),
        warnings: if row.tests > 1 {
            let found = warnings(
                &summary,
                WarningContext {
                    beta: row.beta,
                    guard_outside: row.guard_outside,
                    dialect: Dialect::Api,
                    unexplored: row.method.spec().waits_for_explorers && row.epsilon == 0.0,
                    uniform_spread: row.outside == tslg_api::Outside::Uniform,
                    adaptive: row.method.in_stages(),
                    noisy,
                },
            );
            match row.paired_with {
                // The guard is the remedy the warnings give, and a
                // pair takes none.
                Some(_) => found
                    .into_iter()
                    .map(|w| w.replace("Rerun with ", PAIRED_RERUN))
                    .collect(),
                None => found,
            }
        } else {
            Vec::new()
        },
        tests_per_second: None,
        seconds_left: None,
        audits: None,
        pair: None,
        created_at: row.created_at.clone(),
        updated_at: row.updated_at.clone(),
    }
}

/// A campaign's audit counts from `(state, count)` rows, with what they
/// mean for its user in words.
pub fn audit_counts(row: &CampaignRow, states: &[(AuditState, i64)]) -> (AuditCounts, Vec<String>) {
    let count = |state: AuditState| {
        states
            .iter()
            .filter(|(s, _)| *s == state)
            .map(|(_, n)| *n as u64)
            .sum::<u64>()
    };
    let counts = AuditCounts {
        open: count(AuditState::Replica) + count(AuditState::Tiebreak),
        agreed: count(AuditState::Agreed),
        settled: count(AuditState::Settled),
        undecided: count(AuditState::Undecided),
        void: count(AuditState::Void),
        waived: row.audits_waived as u64,
    };
    let program = row
        .requires
        .as_deref()
        .and_then(|r| r.split(':').next())
        .unwrap_or("the program");
    let handed = (row.next_index as u64, row.indices as u64);
    let warnings = audit_warnings(
        &counts,
        program,
        (row.vehicle_noise, row.status.is_final()),
        handed,
    );
    (counts, warnings)
}

/// What a campaign's audit `counts` mean for its user, in words: `program`
/// is its program's name, `vehicle_noise` whether its audits compare by
/// statistics, `stopped` whether it has stopped, `handed` the tests handed
/// out to workers and those its estimate used. Audits are chosen among
/// every test a worker ran, also those past the stop, so a short campaign
/// can have more chosen than it used: the warning says of how many.
fn audit_warnings(
    counts: &AuditCounts,
    program: &str,
    (vehicle_noise, stopped): (bool, bool),
    (handed_out, used): (u64, u64),
) -> Vec<String> {
    let mut warnings = Vec::new();
    if counts.waived > 0 {
        let past = if stopped && handed_out > used && used > 0 {
            format!(", {used} of them before the stop,")
        } else {
            String::new()
        };
        warnings.push(format!(
            "{} of the {handed_out} tests handed out to workers{past} were chosen for an audit \
             and not run again: no other worker offering `{program}` was live; run two or more \
             workers offering it to have them checked",
            counts.waived
        ));
    }
    if counts.open > 0 && !stopped {
        warnings.push(format!(
            "{} tests wait to be run again by another worker offering `{program}`; {}",
            counts.open,
            if vehicle_noise {
                // Only an audit a worker owes holds a noisy program's prefix.
                "their first runs stand, so the estimate waits only for those a worker owes for \
                 giving audit runs back"
            } else {
                "the estimate stops at the first of them until they are"
            }
        ));
    }
    if counts.settled >= 2 && !vehicle_noise {
        // One liar is flagged once; repeated verdicts against workers are
        // what a program whose runs differ produces in a fleet of honest
        // workers. Only the campaign's owner can say which it is.
        warnings.push(format!(
            "{} audited tests of `{program}` were decided against a worker by a third run: if \
             its runs of one test may differ (thread timing, sensor noise), those workers were \
             honest; start its campaigns with vehicle_noise (docs/statistics.md, \"Noisy \
             vehicles\")",
            counts.settled
        ));
    }
    if counts.undecided > 0 && vehicle_noise {
        warnings.push(format!(
            "{} of {} audited tests gave another outcome when run again, as a noisy program's \
             may; each first run stands, and workers are compared by statistics \
             (GET /api/v1/workers)",
            counts.undecided,
            counts.undecided + counts.agreed
        ));
    } else if counts.undecided > 0 {
        warnings.push(format!(
            "{} audited tests got three different outcomes from three workers: is `{program}` \
             deterministic for a given test? If not, start its campaigns with vehicle_noise",
            counts.undecided
        ));
    }
    warnings
}

/// A campaign's view with its current rate, the time left and, for an
/// external program, its audits.
pub async fn live_view(state: &AppState, row: &CampaignRow) -> Result<CampaignView, ServiceError> {
    let mut view = campaign_view(row);
    // What the live workers able to run it can do: their threads over the
    // cost of one test on one thread.
    let serving = state.workers.fleet().serving(row.requires.as_deref());
    let capacity = row
        .cost_per_test
        .filter(|c| *c > 0.0)
        .map(|c| f64::from(serving) / c);
    state.throughput.fill(&mut view, capacity);
    if let Some(waiting) = waiting_for_workers(state, row) {
        view.warnings.push(waiting);
    }
    if let Some(program) = &row.requires {
        let id = row.id;
        let states = state.db.read(move |conn| audits::counts(conn, id)).await?;
        let (counts, warnings) = audit_counts(row, &states);
        view.audits = Some(counts);
        view.warnings.extend(warnings);
        let saying = state.workers.saying_noisy(program);
        if !row.vehicle_noise && !saying.is_empty() && !row.status.is_final() {
            view.warnings.push(format!(
                "`{program}` says its runs of one test may differ (\"deterministic\": false, on \
                 {}): its audits here compare outcome by outcome, so honest workers may be \
                 flagged where runs differ; start its campaigns with vehicle_noise \
                 (docs/statistics.md, \"Noisy vehicles\")",
                saying.join(", ")
            ));
        }
    }
    if let Some(partner) = row.paired_with {
        // The pair and the other campaign as one read sees them.
        let row = row.clone();
        let (pair, other) = state
            .db
            .read(move |conn| {
                Ok::<_, ServiceError>((pair_view_of(conn, &row)?, campaigns::get(conn, partner)?))
            })
            .await?;
        view.pair = pair;
        // The pair waits for the slower campaign: say why it waits.
        if let Some(waiting) = waiting_for_workers(state, &other) {
            view.warnings
                .push(format!("its pair's campaign {partner}: {waiting}"));
        }
    }
    view.verdict = crate::campaign::verdict::verdict(&view);
    Ok(view)
}

/// Why a running campaign gets no tests, when no live worker (one seen
/// within a minute) can run them: none at all, or none offering its
/// external program.
fn waiting_for_workers(state: &AppState, row: &CampaignRow) -> Option<String> {
    if row.status != tslg_api::CampaignStatus::Running {
        return None;
    }
    match &row.requires {
        Some(requirement) if state.workers.live_offering(requirement).is_empty() => Some(format!(
            "no worker: no live worker offers the program `{requirement}` this campaign's \
             tests need (start one with `tslg-worker --vut-exec NAME=COMMAND`; GET \
             /api/v1/workers lists what each offers); its tests wait"
        )),
        None if state.workers.counts().0 == 0 => Some(
            "no worker: no worker has asked for work in the last minute; the campaign's tests \
             wait for one (`tslg-worker --server URL`)"
                .to_owned(),
        ),
        _ => None,
    }
}

/// The pair as the API shows it; `a` and `b` are its campaigns.
pub fn pair_view(pair: &PairRow, a: &CampaignRow, b: &CampaignRow) -> PairView {
    let sums = pair.sums();
    let rule = a.rule();
    let stop = pair.stop();
    let result = sums.stopped(
        &rule,
        PairedStop::parse(pair.stop.as_deref().unwrap_or_default())
            .unwrap_or(PairedStop::Exhausted),
        pair.look_confidence,
    );
    let interval = |(estimate, ci_low, ci_high): (f64, f64, f64)| {
        (sums.n > 1).then_some(PairedInterval {
            estimate,
            ci_low,
            ci_high,
        })
    };
    PairView {
        campaign_a: pair.campaign_a,
        campaign_b: pair.campaign_b,
        status: match stop {
            // Before its rule holds the pair stands as its campaigns:
            // waiting for its library, or failed with it.
            None if [a.status, b.status].contains(&CampaignStatus::Failed) => {
                CampaignStatus::Failed
            }
            None if [a.status, b.status].contains(&CampaignStatus::Cancelled) => {
                CampaignStatus::Cancelled
            }
            None if a.status == CampaignStatus::Pending => CampaignStatus::Pending,
            None => CampaignStatus::Running,
            Some(PairStop::Precision | PairStop::Significant) => CampaignStatus::Converged,
            Some(PairStop::Exhausted) => CampaignStatus::Exhausted,
            Some(PairStop::Cancelled) => CampaignStatus::Cancelled,
        },
        stop,
        indices: pair.indices as u64,
        tests: sums.n,
        events_a: sums.events.0,
        events_b: sums.events.1,
        discordant: sums.events.2,
        rate_a: interval(result.rate_a),
        rate_b: interval(result.rate_b),
        difference: interval(result.difference),
        look_confidence: pair.look_confidence,
        independent_tests: result.independent_tests,
        exact_difference: a
            .exact_probability
            .zip(b.exact_probability)
            .map(|(pa, pb)| pa - pb),
    }
}

/// The pair of `campaign` as the API shows it, if it has one.
pub fn pair_view_of(
    conn: &Connection,
    campaign: &CampaignRow,
) -> Result<Option<PairView>, StoreError> {
    let Some(pair) = pairs::of(conn, campaign)? else {
        return Ok(None);
    };
    let partner = campaigns::get(conn, pair.partner(campaign.id))?;
    Ok(Some(if campaign.id == pair.campaign_a {
        pair_view(&pair, campaign, &partner)
    } else {
        pair_view(&pair, &partner, campaign)
    }))
}

/// A library as the API shows it (its build's progress aside).
pub fn library_view(row: &LibraryRow) -> LibraryView {
    LibraryView {
        id: row.id,
        case: row.case_name.clone(),
        preset: row.preset.clone(),
        status: row.status,
        exposure: row.exposure_name.clone(),
        exposure_fingerprint: row.exposure_fingerprint.clone(),
        exposure_note: row.exposure_note.clone(),
        surrogate: serde_json::from_str(&row.surrogate).unwrap_or_default(),
        surrogate_label: tslg_method::cases::vehicle_label(
            &serde_json::from_str(&row.surrogate).unwrap_or_default(),
            &row.case_name,
        ),
        size: row.size.map(|v| v as u64),
        total_scenarios: row.total_scenarios as u64,
        sm_evaluations: row.sm_evaluations.map(|v| v as u64),
        mu_s: row.mu_s,
        w: row.w,
        build_seconds: row.build_seconds,
        error: row.error.clone(),
        status_detail: None,
        progress: None,
        created_at: row.created_at.clone(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn counts(agreed: u64, settled: u64, undecided: u64) -> AuditCounts {
        AuditCounts {
            open: 0,
            agreed,
            settled,
            undecided,
            void: 0,
            waived: 0,
        }
    }

    #[test]
    fn audits_that_differ_are_worded_for_noisy_and_exact_campaigns() {
        // A noisy program's differing runs are expected: said as a share.
        let noisy = audit_warnings(&counts(97, 0, 3), "py", (true, false), (1000, 1000));
        assert_eq!(noisy.len(), 1);
        assert!(noisy[0].starts_with("3 of 100 audited tests"), "{noisy:?}");
        // Under exact audits, one verdict against a worker is a liar
        // caught; two or more say the program may be noisy.
        assert!(audit_warnings(&counts(50, 1, 0), "py", (false, false), (1000, 1000)).is_empty());
        let repeated = audit_warnings(&counts(50, 2, 0), "py", (false, false), (1000, 1000));
        assert!(
            repeated[0].contains("start its campaigns with vehicle_noise"),
            "{repeated:?}"
        );
        assert!(audit_warnings(&counts(50, 2, 0), "py", (true, false), (1000, 1000)).is_empty());
        let three = audit_warnings(&counts(50, 0, 1), "py", (false, false), (1000, 1000));
        assert!(three[0].contains("three different outcomes"), "{three:?}");
    }

    /// A 100-test campaign whose workers ran 1,024 tests had 117 audits
    /// waived, and said "117 tests chosen for an audit": more than it had.
    #[test]
    fn waived_audits_are_counted_against_the_tests_handed_out() {
        let waived = AuditCounts {
            waived: 117,
            ..counts(0, 0, 0)
        };
        let said = audit_warnings(&waived, "py", (false, true), (1024, 100));
        assert_eq!(said.len(), 1);
        assert!(
            said[0].starts_with(
                "117 of the 1024 tests handed out to workers, 100 of them before the stop, were \
                 chosen for an audit and not run again"
            ),
            "{said:?}"
        );
        let running = audit_warnings(&waived, "py", (false, false), (1024, 1024));
        assert!(running[0].starts_with("117 of the 1024 tests handed out to workers were"));
    }
}
