//! Folding a campaign's newly resolved prefix: a pure step over the
//! outcomes ([`fold_step`]) and the code that reads its inputs and writes
//! its result ([`fold_prefix`]), inside the report's transaction.
//!
//! The frontier is the smallest `resume_at` of the campaign's active
//! leases, or its `next_index` when none is active: every index below it
//! has a recorded outcome (listed, or no event). The fold walks the
//! outcomes in index order and checks the stopping rule at every index
//! (SPEC §7), so the stop index does not depend on who reported what when.

use crate::campaign::history;
use crate::error::ServiceError;
use crate::report::anytime::{self, AnytimeSpan};
use crate::report::check::CheckedReport;
use crate::report::evidence;
use crate::report::explored::Explored;
use crate::report::explored::{exploring_in, ExploredRanges};
use crate::report::flag::flag_worker;
use crate::store::campaigns::{self, CampaignRow};
use crate::store::prefix::{self, Charge};
use crate::store::reports;
use rusqlite::Connection;
use std::sync::Arc;
use tslg_api::CampaignStatus;
use tslg_method::anytime::outside_bound;
use tslg_method::estimator::{Decision, Interval, StoppingRule};
use tslg_method::outside::OutsideMass;
use tslg_method::prefix::{outside_tally, Exploration, FoldError, PrefixFold, SparseOutcome};
use tslg_method::registry::CampaignTests;

/// What one fold gave.
pub struct Folded {
    /// The state after the fold.
    pub fold: PrefixFold,
    /// History points inside the fold worth storing, then the last one
    /// when it is worth storing or the campaign stopped; with an anytime
    /// campaign's interval there.
    pub course: Vec<(PrefixFold, Option<(f64, f64)>)>,
    /// `Some` when the rule stopped the campaign.
    pub decision: Option<Decision>,
}

/// Folds `outcomes` (sorted, inside `fold.indices..frontier`) onto `fold`
/// under `rule`: pure, so the same inputs give the same stop anywhere.
/// `last_stored` is the campaign's last stored history point.
pub fn fold_step(
    mut fold: PrefixFold,
    rule: &StoppingRule,
    frontier: u64,
    outcomes: &[(u64, SparseOutcome)],
    exploration: Option<Exploration<'_>>,
    last_stored: Option<u64>,
) -> Result<Folded, FoldError> {
    let mut last_stored = last_stored;
    let mut course = Vec::new();
    let decision = fold.advance_observed(
        rule,
        rule.z(),
        frontier,
        outcomes,
        exploration,
        &mut |state| {
            if history::worth_storing(last_stored, state.indices) {
                last_stored = Some(state.indices);
                course.push((*state, None));
            }
        },
    )?;
    if decision.is_some() || history::worth_storing(last_stored, fold.indices) {
        course.push((fold, None));
    }
    Ok(Folded {
        fold,
        course,
        decision,
    })
}

/// Draws below which [`explored_tests`] runs on the writer's own thread.
const SERIAL_DRAWS: u64 = 1 << 16;

/// The tests of `from..to` that draw outside the library (one random
/// number each, about 0.1 µs), on rayon's threads when there are many:
/// the writer waits for them, as for any of its statements.
fn explored_tests(tests: &Arc<dyn CampaignTests>, from: u64, to: u64) -> Vec<u64> {
    use rayon::prelude::*;
    if to.saturating_sub(from) <= SERIAL_DRAWS {
        return (from..to).filter(|&i| tests.explores(i)).collect();
    }
    (from..to)
        .into_par_iter()
        .filter(|&i| tests.explores(i))
        .collect()
}

/// What the coordinator knows already of which tests explore, so that a
/// fold does not draw them again: the report just replayed whole
/// (`replayed`), and the sets kept from earlier reports (`kept`).
#[derive(Clone, Default)]
pub struct KnownExplored<'a> {
    pub replayed: Option<Arc<Explored>>,
    pub kept: Option<&'a ExploredRanges>,
}

impl KnownExplored<'_> {
    /// The exploring tests of campaign `campaign`'s `from..to`: the known
    /// sets where they cover it, drawn again (`explored_tests`) between
    /// them.
    fn exploring(
        &self,
        campaign: i64,
        tests: &Arc<dyn CampaignTests>,
        from: u64,
        to: u64,
    ) -> Vec<u64> {
        let kept = self
            .kept
            .map(|k| k.meeting(campaign, from, to))
            .unwrap_or_default();
        let mut known: Vec<&Explored> = kept.iter().map(Arc::as_ref).collect();
        known.extend(self.replayed.as_deref());
        exploring_in(from, to, &known, |a, b| {
            if let Some(kept) = self.kept {
                kept.note_drawn(b - a);
            }
            explored_tests(tests, a, b)
        })
    }

    /// After a fold that left campaign `campaign`'s prefix at `prefix`:
    /// the kept sets it passed go, and the report's own set is kept when
    /// it reaches past the prefix (a later fold passes it).
    fn settle(&self, campaign: i64, prefix: u64) {
        let Some(kept) = self.kept else {
            return;
        };
        kept.passed(campaign, prefix);
        if let Some(replayed) = self.replayed.as_ref().filter(|r| r.to > prefix) {
            kept.remember(campaign, Arc::clone(replayed));
        }
    }
}

/// Folds the newly resolved prefix of `campaign` and persists the
/// estimate (an adaptive campaign resolves its stages instead,
/// [`crate::report::stages`]), and
/// estimate, its history points and, when the rule stops the campaign, its
/// final status. `tests` are a library campaign's tests, which say which
/// tests explored outside the library; `None` for the NDD. `known` are the
/// exploring tests the coordinator found itself ([`KnownExplored`]); `fresh` the
/// report just recorded in this transaction, whose outcomes the fold takes
/// as they are instead of reading them back.
///
/// `charge` is what the report just recorded adds to the campaign's row
/// ([`Charge`]): written with the fold's update of the row, or on its own
/// where the fold writes none.
pub fn fold_prefix(
    conn: &Connection,
    campaign: &CampaignRow,
    tests: Option<Arc<dyn CampaignTests>>,
    known: KnownExplored<'_>,
    fresh: Option<&CheckedReport>,
    charge: Option<Charge>,
) -> Result<Option<CampaignStatus>, ServiceError> {
    // Every test is evidence: a worker its tests convict is flagged before
    // the fold, which then folds what honest workers reported.
    let convicted = evidence::weigh(conn, campaign, tests.as_ref())?;
    let reread;
    let (campaign, fresh) = match convicted {
        Some(convicted) => {
            flag_worker(
                conn,
                &convicted.worker,
                &convicted.detail,
                campaign.id,
                convicted.index,
            )?;
            reread = campaigns::get(conn, campaign.id)?;
            (&reread, None)
        }
        None => (campaign, fresh),
    };
    let mut pending = charge;
    let folded = fold_charging(conn, campaign, tests, known, fresh, &mut pending)?;
    if let Some(charge) = pending {
        prefix::charge(conn, campaign.id, &charge)?;
    }
    Ok(folded)
}

/// [`fold_prefix`], leaving `charge` for the caller where it does not
/// write it.
fn fold_charging(
    conn: &Connection,
    campaign: &CampaignRow,
    tests: Option<Arc<dyn CampaignTests>>,
    known: KnownExplored<'_>,
    fresh: Option<&CheckedReport>,
    charge: &mut Option<Charge>,
) -> Result<Option<CampaignStatus>, ServiceError> {
    if campaign.method.in_stages() {
        // Resolving stages reads the campaign's row: charged first.
        if let Some(charge) = charge.take() {
            prefix::charge(conn, campaign.id, &charge)?;
        }
        let tests = tests.ok_or_else(|| {
            anyhow::anyhow!(
                "adaptive campaign {} folded without its stages",
                campaign.id
            )
        })?;
        return crate::report::stages::resolve_stages(conn, campaign, &tests);
    }
    let prefix::Bounds {
        frontier,
        last_stored,
    } = prefix::bounds(conn, campaign)?;
    let mut fold = campaign.fold();
    if frontier <= fold.indices {
        known.settle(campaign.id, fold.indices);
        return Ok(None);
    }
    let from = fold.indices;
    let outcomes = outcomes_to_fold(conn, campaign.id, from, frontier, fresh)?;
    let all_tests = tests.clone();
    let tests = tests.filter(|t| t.outside_mass().is_some());
    // A library campaign's tests say whether its estimate stratifies (ε in
    // force under the stratified split); persisted with the sums.
    if let Some(tests) = &tests {
        fold.strata = tests.strata();
        fold.within_strata = fold.strata.is_some() && campaign.tracks_within_strata();
    }
    let mut explored = Vec::new();
    if let Some(tests) = &tests {
        if campaign.outside_upper.is_none() && from > 0 {
            // Started before the outside bound existed: count its exploring
            // tests from the start, as the fold would have.
            let earlier = reports::outcomes(conn, campaign.id, 0, from)?;
            let before = explored_tests(tests, 0, from);
            fold.outside = outside_tally(&before, &earlier, &|i| tests.surrogate_misses(i));
        }
        explored = known.exploring(campaign.id, tests, from, frontier);
    }
    let mass: Option<&OutsideMass> = tests.as_ref().and_then(|t| t.outside_mass());
    let misses = |i| tests.as_ref().is_some_and(|t| t.surrogate_misses(i));
    let exploration = mass.map(|mass| Exploration {
        explored: &explored,
        mass,
        surrogate_misses: &misses,
    });
    let rule = campaign.fold_rule();
    let (mut folded, anytime) = if rule.interval == Interval::Anytime {
        let span = AnytimeSpan {
            frontier,
            outcomes: &outcomes,
            explored: &explored,
            mass,
            misses: &misses,
            last_stored,
            draw_explored: &explored_tests,
        };
        let kept = known.kept.map(|k| &k.anytime);
        let folded = anytime::fold(conn, campaign, &rule, all_tests.as_ref(), kept, span)?;
        (
            Folded {
                fold: folded.anytime.fold,
                course: folded.course,
                decision: folded.decision,
            },
            Some(folded.anytime),
        )
    } else {
        let folded = fold_step(fold, &rule, frontier, &outcomes, exploration, last_stored)
            .map_err(|e| {
                anyhow::anyhow!("stored outcomes of campaign {} rejected: {e}", campaign.id)
            })?;
        (folded, None)
    };
    if campaign.paired_with.is_some() {
        // A campaign of a pair stops with its pair (`store/pairs.rs`), even
        // at max_tests: until the other campaign has resolved as many
        // tests it stays running, and gets no more leases.
        folded.decision = None;
    }
    match (known.kept, folded.decision) {
        // All of a campaign the fold stops (here, in case the request that
        // stopped it goes no further).
        (Some(kept), Some(_)) => kept.forget(campaign.id),
        _ => known.settle(campaign.id, folded.fold.indices),
    }
    // An anytime campaign's exploring stratum bounds its own mean at every
    // n; the others keep the Clopper–Pearson bound.
    let upper = outside_bound(anytime.as_ref(), &folded.fold, mass, campaign.confidence);
    // An anytime or guarded library campaign switches once its library
    // stratum is known (issue 49): from the first test not yet handed out
    // on, nearly every test explores. The tests handed out keep their strata.
    let switch_due = match anytime.as_ref() {
        Some(a) => a.switch_due(&rule),
        None => folded.fold.switch_due(&rule, rule.z()),
    };
    if folded.decision.is_none() && campaign.explore_from.is_none() && switch_due {
        prefix::set_explore_from(conn, campaign.id, folded.fold.indices)?;
    }
    let sequence = anytime.map(|a| {
        let bounds = a.bounds();
        (bounds.low, bounds.high)
    });
    write(
        conn,
        campaign,
        &rule,
        &folded,
        (upper, sequence),
        charge.take(),
    )
}

/// The outcomes of `from..to`: those of the report just recorded, `fresh`
/// (its range was checked against what was stored, and its new part stored
/// as it is), and the stored ones of the rest of the range, in index order.
fn outcomes_to_fold(
    conn: &Connection,
    campaign: i64,
    from: u64,
    to: u64,
    fresh: Option<&CheckedReport>,
) -> Result<Vec<(u64, SparseOutcome)>, ServiceError> {
    let Some(fresh) = fresh.filter(|f| f.from < to && f.to > from) else {
        return Ok(reports::outcomes(conn, campaign, from, to)?);
    };
    let mut outcomes = if from < fresh.from {
        reports::outcomes(conn, campaign, from, fresh.from)?
    } else {
        Vec::new()
    };
    outcomes.extend(fresh.outcomes.iter().filter(|o| (from..to).contains(&o.0)));
    if fresh.to < to {
        outcomes.extend(reports::outcomes(conn, campaign, fresh.to, to)?);
    }
    Ok(outcomes)
}

/// The status a decision gives, with the sentence that explains it.
fn outcome(
    decision: Option<Decision>,
    rule: &StoppingRule,
    fold: &PrefixFold,
) -> (CampaignStatus, Option<String>) {
    match decision {
        None => (CampaignStatus::Running, None),
        Some(Decision::Converged) => (
            CampaignStatus::Converged,
            Some(format!(
                "relative half-width ≤ β = {} after {} tests{}",
                rule.beta,
                fold.indices,
                if rule.guard_outside {
                    ", with the failure mass outside the library bounded"
                } else {
                    ""
                }
            )),
        ),
        Some(Decision::Exhausted) | Some(Decision::Continue) => (
            CampaignStatus::Exhausted,
            Some(format!(
                "max_tests = {} used up before the relative half-width reached β = {}",
                rule.max_tests, rule.beta
            )),
        ),
    }
}

/// Writes a fold's state, history and, on a stop, the final status (its
/// active leases cancelled).
fn write(
    conn: &Connection,
    campaign: &CampaignRow,
    rule: &StoppingRule,
    folded: &Folded,
    (upper, sequence): (Option<f64>, Option<(f64, f64)>),
    charge: Option<Charge>,
) -> Result<Option<CampaignStatus>, ServiceError> {
    let fold = &folded.fold;
    let (status, detail) = outcome(folded.decision, rule, fold);
    prefix::store_fold(
        conn,
        campaign.id,
        &prefix::FoldState {
            fold,
            upper,
            sequence,
            status,
            detail: detail.as_deref(),
        },
        charge,
    )?;
    prefix::store_history(conn, campaign.id, &folded.course)?;
    if folded.decision.is_none() {
        return Ok(None);
    }
    prefix::close_stopped(conn, campaign.id, fold.indices)?;
    tracing::info!(
        campaign = campaign.id,
        status = status.as_str(),
        stop_index = fold.indices,
        "campaign stopped"
    );
    Ok(Some(status))
}
