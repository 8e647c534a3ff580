//! Every test is evidence (issue 67): each worker's tests against the rest
//! of the fleet's, on all of a campaign's tests, not only the audited ones.
//!
//! Before a campaign's prefix is folded, [`weigh`] walks its newly
//! resolved tests in index order ([`tslg_method::test_pairing`]): each
//! test pairs with the oldest waiting test of another worker in the same
//! stratum (the library or the outside of a library campaign, the one
//! stratum of the NDD), and the pairs are counted per pair of workers
//! (`store/discordance.rs`, [`Pairs::Tests`]). A worker whose pairs lean
//! to one side against its partners beyond [`FLAG_AT`], leaving out any
//! one partner (so one liar cannot make an honest worker look different),
//! is flagged as a liar is: a false flag at most once in 10⁴ honest
//! worker-campaigns (Ville's inequality; one e-value a campaign, since
//! campaigns that reuse a seed draw the same tests again).
//!
//! Library and NDD campaigns of external programs only (a built-in
//! vehicle's tests the coordinator replays). Adaptive campaigns are left to the
//! audits: their stages change the proposal as they go, so a stratum would
//! be a stage's support, and the results of a flagged worker fail them
//! anyway (`report/flag.rs`). A library build's enumeration runs its cells
//! in order, each once: its tests are no draws of one distribution, and
//! workers taking consecutive cells would look different.
//!
//! **One vote per principal.** Tests are paired and counted by the
//! workers' principals (`credentials::principal_of`: the one a worker
//! enrolled under, else the worker itself): the names of one principal
//! never pair with each other, and count as one partner, so a holder of
//! the worker token with one enrolment cannot outvote the others with
//! names it registers.

use crate::error::ServiceError;
use crate::store::audits;
use crate::store::campaign_row::CampaignRow;
use crate::store::credentials;
use crate::store::discordance::{self, Pairs};
use crate::store::prefix;
use crate::store::reports;
use crate::store::test_pairing_walks;
use rusqlite::Connection;
use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;
use tslg_api::NearMiss;
use tslg_method::discordance::{worker_evidence, FLAG_AT};
use tslg_method::prefix::SparseOutcome;
use tslg_method::registry::CampaignTests;
use tslg_method::test_pairing::{
    cell_key, score, stratum_key, PairCounts, ResolvedRun, Walk, CRITICALITY_BELOW,
};

/// The criticality below which the workers of `campaign` report it for
/// every test (`CampaignPlan::criticality_below`): library and NDD
/// campaigns of an external program (a built-in vehicle's tests the
/// coordinator replays itself).
pub fn criticality_below(campaign: &CampaignRow) -> Option<f64> {
    weighed(campaign).then_some(CRITICALITY_BELOW)
}

/// Whether `campaign`'s tests are weighed: a library or NDD campaign (its
/// tests independent draws of one proposal: not an adaptive campaign's
/// stages, nor a library build's enumeration, its cells in order, each
/// once) of an external program (a built-in vehicle's tests the
/// coordinator replays itself, and they come by the million, where the
/// walk's microsecond a test would slow the writer).
fn weighed(campaign: &CampaignRow) -> bool {
    let external = serde_json::from_str::<serde_json::Value>(&campaign.vut)
        .is_ok_and(|vut| vut.get("external").is_some());
    external && campaign.method.draws_independently()
}

/// The criticalities of a report's tests from `new_from` on, rounded to
/// the thousandths the pairing scores them in (so that they pack small).
pub fn kept_criticalities(near_misses: &[NearMiss], new_from: u64) -> Vec<(u64, f64)> {
    near_misses
        .iter()
        .filter(|m| m.index >= new_from)
        .map(|m| (m.index, (m.criticality * 1000.0).round() / 1000.0))
        .collect()
}

/// A worker the evidence of its tests convicts.
#[derive(Debug, Clone, PartialEq)]
pub struct Convicted {
    pub worker: String,
    /// Why, for the flag.
    pub detail: String,
    /// The test up to which the walk had gone.
    pub index: u64,
}

/// Walks `campaign`'s tests resolved since the last walk (up to its
/// frontier), counts their pairs, and returns the worker whose evidence
/// reached [`FLAG_AT`], the strongest when several did. `tests` are a
/// library campaign's tests (their strata); `None` for the NDD.
pub fn weigh(
    conn: &Connection,
    campaign: &CampaignRow,
    tests: Option<&Arc<dyn CampaignTests>>,
) -> Result<Option<Convicted>, ServiceError> {
    if !weighed(campaign) {
        return Ok(None);
    }
    let frontier = prefix::bounds(conn, campaign)?.frontier;
    let stored = test_pairing_walks::get(conn, campaign.id)?;
    let walked_to = stored.as_ref().map_or(0, |(to, _)| *to);
    // A library campaign's tests give its cells; a fold without them (a
    // campaign read as stopped, running again since) leaves the walk for
    // the next.
    if frontier <= walked_to || (campaign.method.uses_library() && tests.is_none()) {
        return Ok(None);
    }
    let mut walk: Walk = match stored {
        Some((_, waiting)) => serde_json::from_str(&waiting)
            .map_err(|e| anyhow::anyhow!("stored test pairing of campaign {}: {e}", campaign.id))?,
        None => Walk::default(),
    };
    let flagged: BTreeSet<String> = audits::flagged(conn)?.into_iter().map(|f| f.0).collect();
    for worker in &flagged {
        walk.forget(&credentials::principal_of(conn, worker)?);
    }
    // Each worker's principal, and a worker of each principal to flag.
    let mut principals: BTreeMap<String, String> = BTreeMap::new();
    let mut named: BTreeMap<String, String> = BTreeMap::new();
    let near = reports::near_between(conn, campaign.id, walked_to, frontier)?;
    let events: Vec<u64> = reports::outcomes(conn, campaign.id, walked_to, frontier)?
        .into_iter()
        .filter(|(_, outcome)| matches!(outcome, SparseOutcome::Event(_)))
        .map(|(i, _)| i)
        .collect();
    // A test's key: its grid cell where the campaign draws from a grid,
    // else its stratum (the library's inside or outside, the NDD's one).
    let strata = tests.filter(|t| t.outside_mass().is_some());
    let key = |i: u64| match tests.and_then(|t| t.planned(i)) {
        Some(planned) => cell_key(planned.cell as u64),
        None => stratum_key(strata.is_some_and(|t| t.explores(i))),
    };
    let mut pairs = PairCounts::new();
    let mut next_event = events.iter().peekable();
    let mut next_near = near.iter().peekable();
    for (from, to, worker) in reports::workers_between(conn, campaign.id, walked_to, frontier)? {
        if flagged.contains(&worker) {
            continue;
        }
        if !principals.contains_key(&worker) {
            let principal = credentials::principal_of(conn, &worker)?;
            principals.insert(worker.clone(), principal);
        }
        let principal = principals[&worker].clone();
        named.insert(principal.clone(), worker.clone());
        // Runs of one key and one score: in a grid campaign each test, in
        // the NDD's stretches between events and criticalities.
        let mut start = from;
        while start < to {
            while next_event.next_if(|&&e| e < start).is_some() {}
            while next_near.next_if(|&&(n, _)| n < start).is_some() {}
            let event = next_event.peek().is_some_and(|&&e| e == start);
            let criticality = next_near
                .peek()
                .filter(|&&&(n, _)| n == start)
                .map(|&&(_, c)| c);
            let kind = key(start);
            let mut end = start + 1;
            if !event && criticality.is_none() {
                let next = [
                    next_event.peek().map(|&&e| e),
                    next_near.peek().map(|&&(n, _)| n),
                ]
                .into_iter()
                .flatten()
                .fold(to, u64::min);
                if tests.is_none() {
                    end = next;
                }
                while end < next && key(end) == kind {
                    end += 1;
                }
            }
            let run = ResolvedRun {
                worker: &principal,
                key: kind,
                score: score(event, criticality),
                index: start,
                tests: end - start,
            };
            walk.step(run, &mut pairs);
            start = end;
        }
    }
    let waiting = serde_json::to_string(&walk).map_err(anyhow::Error::from)?;
    test_pairing_walks::put(conn, campaign.id, frontier, &waiting)?;
    let mut suspects = BTreeSet::new();
    for ((first, second), tally) in pairs {
        discordance::record(conn, Pairs::Tests(campaign.id), &first, &second, tally)?;
        if tally.first_closer + tally.second_closer > 0 {
            suspects.extend([first, second]);
        }
    }
    let mut strongest: Option<(f64, Convicted)> = None;
    for suspect in suspects {
        let (partners, compared) =
            discordance::partners_of(conn, Pairs::Tests(campaign.id), &suspect)?;
        let evidence = worker_evidence(&partners);
        if evidence < FLAG_AT || strongest.as_ref().is_some_and(|s| s.0 >= evidence) {
            continue;
        }
        let worker = match named.get(&suspect) {
            Some(worker) => worker.clone(),
            None => credentials::names_of(conn, &suspect)?
                .pop()
                .unwrap_or_else(|| suspect.clone()),
        };
        let own: u64 = partners.iter().map(|p| p.own_event).sum();
        let theirs: u64 = partners.iter().map(|p| p.partner_event).sum();
        let detail = format!(
            "worker `{worker}`{} runs a program that behaves unlike the other workers': of \
             {compared} of its tests paired with tests of {} other workers (same campaign, same \
             cell or stratum), {} differed in how close they came to the event, and its test came \
             closer in {own} of them, its partners' in {theirs} (evidence {evidence:.3e} ≥ {FLAG_AT:e}: \
             a false flag at most once in 10⁴ honest worker-campaigns; docs/statistics.md, \"Every \
             test as evidence\")",
            if suspect == worker { String::new() } else { format!(" (principal `{suspect}`)") },
            partners.len(),
            own + theirs
        );
        strongest = Some((
            evidence,
            Convicted {
                worker: worker.clone(),
                detail,
                index: frontier - 1,
            },
        ));
    }
    Ok(strongest.map(|s| s.1))
}
