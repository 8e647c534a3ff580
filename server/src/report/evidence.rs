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
//! workers over their whole life (Ville's inequality).
//!
//! Adaptive campaigns are left to the audits: their stages change the
//! proposal as they go, so a stratum would be a stage's support, and the
//! results of a flagged worker fail them anyway (`report/flag.rs`).

use crate::error::ServiceError;
use crate::store::audits;
use crate::store::campaign_row::CampaignRow;
use crate::store::discordance::{self, Pairs};
use crate::store::prefix;
use crate::store::reports;
use crate::store::test_pairing_walks;
use rusqlite::Connection;
use std::collections::BTreeSet;
use std::sync::Arc;
use tslg_api::Method;
use tslg_method::discordance::{worker_evidence, FLAG_AT};
use tslg_method::prefix::SparseOutcome;
use tslg_method::registry::CampaignTests;
use tslg_method::test_pairing::{score, PairCounts, ResolvedRun, Walk};

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
    if campaign.method == Method::Adaptive {
        return Ok(None);
    }
    let frontier = prefix::bounds(conn, campaign)?.frontier;
    let (walked_to, mut walk) = match test_pairing_walks::get(conn, campaign.id)? {
        Some((to, waiting)) => {
            let walk: Walk = serde_json::from_str(&waiting).map_err(|e| {
                anyhow::anyhow!("stored test pairing of campaign {}: {e}", campaign.id)
            })?;
            (to, walk)
        }
        None => (0, Walk::default()),
    };
    if frontier <= walked_to {
        return Ok(None);
    }
    let flagged: BTreeSet<String> = audits::flagged(conn)?.into_iter().map(|f| f.0).collect();
    for worker in &flagged {
        walk.forget(worker);
    }
    let strata = tests.filter(|t| t.outside_mass().is_some());
    let stratum = |i: u64| u8::from(strata.is_some_and(|t| t.explores(i)));
    let events: Vec<u64> = reports::outcomes(conn, campaign.id, walked_to, frontier)?
        .into_iter()
        .filter(|(_, outcome)| matches!(outcome, SparseOutcome::Event(_)))
        .map(|(i, _)| i)
        .collect();
    let mut pairs = PairCounts::new();
    let mut next_event = events.iter().peekable();
    for (from, to, worker) in reports::workers_between(conn, campaign.id, walked_to, frontier)? {
        if flagged.contains(&worker) {
            continue;
        }
        // Runs of one stratum and one score: an event, or a stretch
        // without one.
        let mut start = from;
        while start < to {
            while next_event.next_if(|&&e| e < start).is_some() {}
            let event = next_event.peek().is_some_and(|&&e| e == start);
            let kind = stratum(start);
            let mut end = start + 1;
            if !event {
                let next = next_event.peek().map_or(to, |&&e| e.min(to));
                if strata.is_none() {
                    end = next;
                }
                while end < next && stratum(end) == kind {
                    end += 1;
                }
            }
            let run = ResolvedRun {
                worker: &worker,
                stratum: kind,
                score: score(event, None),
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
        discordance::record(conn, Pairs::Tests, &first, &second, tally)?;
        if tally.first_closer + tally.second_closer > 0 {
            suspects.extend([first, second]);
        }
    }
    let mut strongest: Option<(f64, Convicted)> = None;
    for suspect in suspects {
        let (partners, compared) = discordance::partners_of(conn, Pairs::Tests, &suspect)?;
        let evidence = worker_evidence(&partners);
        if evidence < FLAG_AT || strongest.as_ref().is_some_and(|s| s.0 >= evidence) {
            continue;
        }
        let own: u64 = partners.iter().map(|p| p.own_event).sum();
        let theirs: u64 = partners.iter().map(|p| p.partner_event).sum();
        let detail = format!(
            "worker `{suspect}` runs a program that behaves unlike the other workers': of \
             {compared} of its tests paired with tests of {} other workers (same campaign, same \
             stratum), {} differed in whether the event occurred, and its test found the event \
             in {own} of them, its partners' in {theirs} (evidence {evidence:.3e} ≥ {FLAG_AT:e}: \
             a false flag at most once in 10⁴ honest workers; docs/statistics.md, \"Every test \
             as evidence\")",
            partners.len(),
            own + theirs
        );
        strongest = Some((
            evidence,
            Convicted {
                worker: suspect,
                detail,
                index: frontier - 1,
            },
        ));
    }
    Ok(strongest.map(|s| s.1))
}
