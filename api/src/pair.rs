//! Paired regression campaigns on the wire: two vehicles tested on the same
//! test stream, and the difference of their rates from the same draws
//! (docs/statistics.md, "Paired regression campaigns").

use crate::CampaignStatus;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

/// A rate or a difference with its interval at the campaign's confidence.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct PairedInterval {
    /// The estimate.
    pub estimate: f64,
    /// Lower end of the normal interval.
    pub ci_low: f64,
    /// Upper end of the normal interval.
    pub ci_high: f64,
}

/// Why a paired campaign stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "kebab-case")]
pub enum PairStop {
    /// The difference's half-width reached β times the larger rate.
    Precision,
    /// The difference's interval excluded zero at a look (`n_min·2ᵏ` tests,
    /// at `look_confidence`).
    Significant,
    /// `max_tests` used up first.
    Exhausted,
    /// Cancelled by a user.
    Cancelled,
}

/// `pair` of a campaign view: a paired regression campaign is two
/// campaigns, `campaign_a` (the `vut` of the request) and `campaign_b` (its
/// `paired_with`), drawing the same tests (same seed, library and ε). Each
/// folds its own estimate as any campaign; the pair folds the difference
/// `dᵢ = aᵢ − bᵢ` over the tests both have resolved, and stops both.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct PairView {
    /// The campaign of vehicle a (the request's `vut`).
    pub campaign_a: i64,
    /// The campaign of vehicle b (the request's `paired_with`).
    pub campaign_b: i64,
    /// `running` until the pair's rule holds; then both campaigns stop.
    pub status: CampaignStatus,
    /// Why the pair stopped.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stop: Option<PairStop>,
    /// Test indices both campaigns resolved that the pair folded.
    pub indices: u64,
    /// Of those, the tests both vehicles ran (`n`).
    pub tests: u64,
    /// Tests where vehicle a had the event.
    pub events_a: u64,
    /// Tests where vehicle b had the event.
    pub events_b: u64,
    /// Tests where exactly one of them had it: the difference's interval
    /// rests on these.
    pub discordant: u64,
    /// Vehicle a's rate over the pair's tests; absent before 2 tests.
    pub rate_a: Option<PairedInterval>,
    /// Vehicle b's rate over the pair's tests; absent before 2 tests.
    pub rate_b: Option<PairedInterval>,
    /// `P(A)` of a minus that of b, with the paired interval; absent
    /// before 2 tests.
    pub difference: Option<PairedInterval>,
    /// For a stop at a look, the confidence the look spent (its interval
    /// excludes zero).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub look_confidence: Option<f64>,
    /// Tests two independent campaigns would each need for the difference's
    /// half-width: `n (Var a + Var b) / Var d`, estimated.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub independent_tests: Option<f64>,
    /// The exact difference by enumeration, where both campaigns have
    /// their exact `P(A)`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exact_difference: Option<f64>,
}
