//! Campaigns: start requests, their state and history, and the plan a
//! worker needs to run their tests.

use crate::campaign_kind::{CampaignStatus, Outside, Split};
use crate::library::ExposureRequest;
use crate::method::Method;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

/// Where an adaptive campaign stands. Only its estimation tests enter the
/// estimate (`tests`, `events`); `indices` counts every test.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct AdaptiveView {
    /// Tests of the library stage.
    pub library_tests: u64,
    /// Tests spent searching around failures and near misses.
    pub search_tests: u64,
    /// Stages resolved.
    pub stages: u64,
    /// The running stage (`library`, `search` or `estimate`) and its tests
    /// `[start, end)`; absent once the campaign stopped.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub running: Option<RunningStage>,
    /// Cells the estimation samples besides its exploring share: the
    /// failures found and the library's cells not yet tested.
    pub support: u64,
    /// How it searches (`grid` or `lattice`).
    #[serde(default)]
    pub search: crate::AdaptiveSearch,
    /// Tests of each of its estimation stages.
    #[serde(default = "default_stage_tests")]
    pub stage_tests: u64,
}

/// What a campaign's method means for a page (from [`crate::MethodSpec`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct MethodFacts {
    /// Whether it estimates a failure rate: false for a library build's
    /// surrogate runs (methods `enumerate` and `build`).
    pub estimates: bool,
    /// Whether it draws from its library (an NDD campaign's `library_id`
    /// names only the exposure it samples).
    pub uses_library: bool,
    /// Whether ε of its tests explore outside the library, drawn afresh
    /// (the library method; an adaptive campaign's stages say their own).
    pub splits_by_epsilon: bool,
    /// What its estimate's tests are called (`tests`, `estimation tests`).
    pub tests_axis: String,
}

impl Default for MethodFacts {
    /// A coordinator from before the field: its campaigns estimate.
    fn default() -> Self {
        Method::Library.into()
    }
}

impl From<Method> for MethodFacts {
    fn from(method: Method) -> Self {
        MethodFacts {
            estimates: !method.builds_library(),
            uses_library: method.uses_library(),
            splits_by_epsilon: method.folds_by_redrawing(),
            tests_axis: method.spec().tests_axis.to_owned(),
        }
    }
}

/// Estimation stages' length of campaigns before it was chosen.
fn default_stage_tests() -> u64 {
    100
}

/// An adaptive campaign's running stage.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct RunningStage {
    /// `library`, `search` or `estimate`.
    pub kind: String,
    /// Its first test index.
    pub start: u64,
    /// One past its last test index.
    pub end: u64,
}

/// `POST /api/v1/campaigns`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CreateCampaign {
    /// `cut-in`, `highway-exit` or `car-following`.
    pub case: String,
    /// How tests are drawn: from the library (importance sampling) or the NDD.
    pub method: Method,
    /// The library to sample from (`method: library`). For `ndd` it is
    /// optional and names the exposure to sample (the built-in one otherwise).
    #[serde(default)]
    pub library_id: Option<i64>,
    /// The vehicle under test: `{"model": "fvdm"}` (a built-in model, any
    /// parameter may be given), its name alone (`"fvdm"`), or `{"external":
    /// "NAME"}` (a program workers offer).
    #[schema(value_type = Object)]
    pub vut: serde_json::Value,
    /// Share ε of tests drawn outside the library, in [0, 1).
    #[serde(default = "default_epsilon")]
    pub epsilon: f64,
    /// How ε is spread outside the library; the case's default when absent
    /// (`uniform` for grid cases, `ndd` for car-following).
    #[serde(default)]
    pub outside: Option<Outside>,
    /// How tests are split between the library and the outside (grid
    /// cases); `stratified` when absent. Car-following explores in each
    /// decision and ignores it.
    #[serde(default)]
    pub split: Option<Split>,
    /// Target relative half-width β, in (0, 1).
    #[serde(default = "default_beta")]
    pub beta: f64,
    /// Confidence level of the interval, in (0, 1).
    #[serde(default = "default_confidence")]
    pub confidence: f64,
    /// Budget of test indices; the campaign is `exhausted` when it is used
    /// up (default 10,000,000, as `tslg campaign start`).
    #[serde(default = "default_max_tests")]
    pub max_tests: u64,
    /// Seed of the campaign's counter-based random streams.
    #[serde(default)]
    pub seed: u64,
    /// Fewest valid tests before the rule may stop. Default: 30; for a
    /// library campaign of a grid case max(30, ⌈10/ε⌉) (capped at
    /// max_tests), so that about ten exploring tests are expected first.
    #[serde(default)]
    pub n_min: Option<u64>,
    /// Fewest events before the rule may stop (default 10).
    #[serde(default)]
    pub min_events: Option<u64>,
    /// Also stop only when the failure mass the library's exploring tests
    /// could still be missing, `outside_upper`, exceeds what they already
    /// contributed to the estimate by at most β times the estimate
    /// (docs/statistics.md). Library and adaptive campaigns of grid cases.
    /// It costs about `ln(1/(1 − c))/(β P(A))` tests with `outside: ndd`.
    /// When absent: on for a noisy vehicle (`vehicle_noise`, or a built-in
    /// model with `noise`) where it applies (not paired, not `anytime`),
    /// off otherwise; `false` turns it off for a noisy vehicle too, whose
    /// answer is still the guarded interval (docs/statistics.md, "Noisy
    /// vehicles").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub guard_outside: Option<bool>,
    /// The interval the campaign stops on and reports: `wald` (the
    /// default; valid at the stop) or `anytime` (a confidence sequence,
    /// valid at every number of tests, so that watching, stopping early
    /// and gating keep its promise; about three times the tests). Library
    /// and NDD campaigns of grid cases; a library campaign's anytime
    /// interval bounds the failure mass outside the library too, and its
    /// `outside` defaults to `ndd`.
    #[serde(default)]
    pub interval: crate::IntervalKind,
    /// A paired regression campaign: a second vehicle (as `vut`) tested on
    /// the same tests, and the difference of the rates (`vut`'s minus this
    /// one's) estimated from the same draws. It stops when the difference
    /// is known to within β of the larger rate, or when its interval
    /// excludes zero at a look (`n_min·2ᵏ` tests; docs/statistics.md). Methods `library` and `ndd`; not with
    /// `guard_outside`. The answer is vehicle a's campaign, with `pair`.
    #[serde(default)]
    #[schema(value_type = Option<Object>)]
    pub paired_with: Option<serde_json::Value>,
    /// The vehicle under test is an external program whose runs of one
    /// test may differ (thread timing, sensor noise, learned parts). Its
    /// audits then compare workers by statistics instead of outcome by
    /// outcome: a single disagreement flags nobody (docs/statistics.md,
    /// "Noisy vehicles"). A program that says so itself, with
    /// `"deterministic": false` in its `hello`, makes a campaign without
    /// this field warn; the workers' word does not set it.
    #[serde(default)]
    pub vehicle_noise: bool,
    /// For `method: adaptive`: how it searches, `grid` (the default) or
    /// `lattice` (a fine grid's coarser lattice, whole blocks into the
    /// support: cheaper on a 4-D grid where failures form solid regions,
    /// blind to failures in sheets thinner than a block;
    /// docs/adaptive-design.md, "Fine grids"). Refused for other methods.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adaptive_search: Option<crate::AdaptiveSearch>,
    /// Tests of an adaptive campaign's estimation stages: a multiple of 20,
    /// from 20 to 100,000. By default 100, or, when the live workers that
    /// offer its vehicle have more than 20 threads `T` at its creation,
    /// `20 ⌈5 T / 20⌉` (at most 2,000): about five rounds of them, so that a stage keeps
    /// them busy (an adaptive campaign plans each stage from the results
    /// of the one before). Refused for other methods.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stage_tests: Option<u64>,
}

impl CreateCampaign {
    /// A request with the API's defaults, as a JSON body naming only
    /// `case`, `method` and `vut` gets them: ε 0.1, β 0.2, confidence 0.9,
    /// [`DEFAULT_MAX_TESTS`], seed 0, no library, every option unset.
    /// Other fields by struct update:
    /// `CreateCampaign { beta: 0.3, ..CreateCampaign::new(case, method, vut) }`,
    /// so that a new field is written here once.
    pub fn new(case: impl Into<String>, method: Method, vut: serde_json::Value) -> Self {
        Self {
            case: case.into(),
            method,
            library_id: None,
            vut,
            epsilon: default_epsilon(),
            outside: None,
            split: None,
            beta: default_beta(),
            confidence: default_confidence(),
            max_tests: default_max_tests(),
            seed: 0,
            n_min: None,
            min_events: None,
            guard_outside: None,
            interval: crate::IntervalKind::default(),
            paired_with: None,
            vehicle_noise: false,
            adaptive_search: None,
            stage_tests: None,
        }
    }
}

fn default_epsilon() -> f64 {
    0.1
}
fn default_beta() -> f64 {
    0.2
}
fn default_confidence() -> f64 {
    0.9
}
/// The test budget of a campaign that does not name one.
pub const DEFAULT_MAX_TESTS: u64 = 10_000_000;
fn default_max_tests() -> u64 {
    DEFAULT_MAX_TESTS
}

/// A vehicle as the API takes it: a JSON object (`{"model": …}`,
/// `{"external": …}`), or a built-in model's name alone, which stands for
/// `{"model": NAME}`.
pub fn vehicle_spec(value: &serde_json::Value) -> serde_json::Value {
    match value {
        serde_json::Value::String(name) => serde_json::json!({ "model": name }),
        other => other.clone(),
    }
}

/// The largest grid on which the coordinator computes a campaign's exact
/// `P(A)` when it is created (one simulation per scenario: about 60 ms on
/// highway-exit `coarse`, 10 s on its 1.6 × 10⁶-scenario `paper` grid).
pub const EXACT_MAX_SCENARIOS: usize = 100_000;

/// `GET /api/v1/campaigns/{id}`. Numbers describe the resolved prefix:
/// the tests `0..indices`, folded in index order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct CampaignView {
    /// The campaign's id.
    pub id: i64,
    /// The case: `cut-in`, `highway-exit` or `car-following`.
    pub case: String,
    /// How tests are drawn.
    pub method: Method,
    /// What its method means for a page, from the method's spec
    /// ([`crate::MethodSpec`]), so a client need not know every method.
    #[serde(default)]
    pub method_facts: MethodFacts,
    /// The library sampled from (or whose exposure an NDD campaign samples).
    pub library_id: Option<i64>,
    /// The vehicle under test as given at creation (`{"model": …}` or `{"external": …}`).
    #[schema(value_type = Object)]
    pub vut: serde_json::Value,
    /// The vehicle under test named for people: its model or program and
    /// the parameters that differ from the model's defaults
    /// (`idm (v0 25)`); `vut` holds every parameter.
    #[serde(default)]
    pub vut_label: String,
    /// `true` when the parameters that differ from the model's defaults
    /// change no accident of the preset: the exact `P(A)` equals the
    /// defaults', to the bit (`{"model": "idm", "v0": 25}` on cut-in's
    /// paper-code preset); `null` where it was not checked.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub parameters_inert: Option<bool>,
    /// Exploration share ε: the probability mass of tests drawn outside the library.
    pub epsilon: f64,
    /// How the ε share is spread outside the library.
    pub outside: Outside,
    /// How the tests are split between the library and the outside.
    pub split: Split,
    /// Target relative half-width β: the campaign stops once `rₙ ≤ β`.
    pub beta: f64,
    /// Confidence level c of the interval (z is its two-sided normal quantile).
    pub confidence: f64,
    /// Fewest valid tests before the stopping rule may hold.
    pub n_min: u64,
    /// Fewest events before the stopping rule may hold.
    pub min_events: u64,
    /// Test indices after which the campaign stops as `exhausted`.
    pub max_tests: u64,
    /// Seed of the test streams: test `i` draws from the stream `(seed, i)`.
    pub seed: u64,
    /// Where the campaign stands.
    pub status: CampaignStatus,
    /// Why the campaign failed or how it ended, in words.
    pub status_detail: Option<String>,
    /// Valid tests in the resolved prefix (`n`).
    pub tests: u64,
    /// Tests in the resolved prefix with the event (accident or task failure).
    pub events: u64,
    /// Tests in the resolved prefix that could not be run; they do not count in `n`.
    pub invalid: u64,
    /// Test indices resolved in order (valid and invalid); once stopped,
    /// the exact stop index.
    pub indices: u64,
    /// Test indices handed out to workers so far.
    pub leased: u64,
    /// Thread-seconds workers spent on this campaign's accepted results:
    /// the measure by which running campaigns share the workers.
    pub worker_seconds: f64,
    /// `μ̂ₙ`; absent before the first test.
    pub estimate: Option<f64>,
    /// Half-width `z σ̂/√n` of the normal interval; absent before the first test.
    pub half_width: Option<f64>,
    /// Absent while the estimate is 0.
    pub relative_half_width: Option<f64>,
    /// Lower end of the interval `μ̂ₙ − half_width` (at least 0).
    pub ci_low: Option<f64>,
    /// Upper end of the interval `μ̂ₙ + half_width`.
    pub ci_high: Option<f64>,
    /// Valid tests predicted to reach β from the current prefix:
    /// `n (rₙ/β)²`, since the half-width shrinks as `1/√n`; absent before
    /// `min_events` events (and at least 2).
    pub predicted_tests: Option<u64>,
    /// Importance-sampling health: Kish's effective number of events
    /// `S₁²/S₂`, with `S₁ = Σ wᵢyᵢ`, `S₂ = Σ (wᵢyᵢ)²`. Equal to `events`
    /// when all event weights are equal; near 1 when one weight dominates,
    /// and then the interval cannot be trusted. Absent before the first
    /// event.
    #[serde(default)]
    pub effective_events: Option<f64>,
    /// The largest single weighted outcome's share of the estimate,
    /// `max wᵢyᵢ / S₁`; absent before the first event.
    #[serde(default)]
    pub largest_weight_share: Option<f64>,
    /// Whether the campaign stops only under the outside guard.
    #[serde(default)]
    pub guard_outside: bool,
    /// Which interval `ci_low..ci_high` is: `wald`, valid at the stop, or
    /// `anytime`, a confidence sequence valid at every number of tests
    /// (its `half_width` is `(ci_high − ci_low)/2`).
    #[serde(default)]
    pub interval: crate::IntervalKind,
    /// The test from which nearly every test explores outside the library:
    /// an anytime library campaign switches there once its library stratum
    /// is known to half of β (docs/statistics.md, "The allocation"). Absent
    /// until it switches.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub explore_from: Option<u64>,
    /// Whether its program's runs may differ, so that its audits compare
    /// by statistics (see `CreateCampaign::vehicle_noise`).
    #[serde(default)]
    pub vehicle_noise: bool,
    /// Valid tests drawn outside the library (the ε share), and their
    /// events: the vehicle failing where its surrogate found nothing
    /// critical. Zero for the NDD and car-following.
    #[serde(default)]
    pub outside_tests: u64,
    /// Of those exploring tests, the ones with the event.
    #[serde(default)]
    pub outside_events: u64,
    /// Those events in scenarios where the library's surrogate has no
    /// event: the vehicle fails where the surrogate does not (a mismatch).
    #[serde(default)]
    pub mismatched_events: u64,
    /// The share of the estimate the events outside the library carry.
    #[serde(default)]
    pub outside_share: Option<f64>,
    /// Upper confidence bound (at `confidence`) on the failure mass outside
    /// the library, from its exploring tests: the worst-case exposure of the
    /// scenarios their Clopper–Pearson bound allows to fail; for an adaptive
    /// campaign, outside its final support K. Absent for the NDD, for
    /// car-following and before the first results.
    #[serde(default)]
    pub outside_upper: Option<f64>,
    /// `ci_high` with the outside part of the estimate replaced by
    /// `outside_upper`: the upper end of the guarded interval.
    #[serde(default)]
    pub guarded_ci_high: Option<f64>,
    /// The interval to report, and why: the guarded one for a guarded
    /// campaign and for any campaign of a noisy vehicle, the plain one
    /// otherwise. Absent before two valid tests.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub answer: Option<AnswerView>,
    /// The verdict in one line: which interval to report and why, or why
    /// there is none yet (a running, cancelled or failed campaign, a
    /// build's surrogate runs).
    #[serde(default)]
    pub verdict: String,
    /// `P(A)` by enumeration of the grid: present for a built-in vehicle on
    /// a grid case of at most [`EXACT_MAX_SCENARIOS`] scenarios (cut-in,
    /// highway-exit `coarse`), computed when the campaign was created; for
    /// a noisy built-in vehicle a seeded Monte Carlo of 1,000 runs a cell
    /// (grids of at most 10,000 scenarios). It lets a user check the
    /// campaign's interval against the truth.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exact_probability: Option<f64>,
    /// An adaptive campaign's stages so far; `None` for other methods.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adaptive: Option<AdaptiveView>,
    /// What the numbers cannot show on their own, in words (surrogate
    /// mismatch, an interval the outside bound does not support).
    #[serde(default)]
    pub warnings: Vec<String>,
    /// Tests accepted per second over the last minute, while running.
    pub tests_per_second: Option<f64>,
    /// `(predicted_tests − tests) / tests_per_second`, while running.
    pub seconds_left: Option<f64>,
    /// The replication audits of an external program's tests; absent for
    /// built-in vehicles (which the coordinator runs again itself).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub audits: Option<AuditCounts>,
    /// For a campaign of a paired regression campaign: the pair, and the
    /// difference of the two vehicles' rates.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pair: Option<crate::PairView>,
    /// When the campaign was created (UTC, RFC 3339 with milliseconds).
    pub created_at: String,
    /// When the campaign's row last changed (UTC, RFC 3339 with milliseconds).
    pub updated_at: String,
}

/// Which interval a campaign answers with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "kebab-case")]
pub enum AnswerInterval {
    /// `[ci_low, ci_high]`.
    Plain,
    /// `[ci_low, guarded_ci_high]`.
    Guarded,
}

impl AnswerInterval {
    /// Its name on the wire: `plain`, `guarded`.
    pub fn as_str(self) -> &'static str {
        match self {
            AnswerInterval::Plain => "plain",
            AnswerInterval::Guarded => "guarded",
        }
    }
}

/// The interval a campaign answers with (`CampaignView::answer`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct AnswerView {
    /// Which interval.
    pub interval: AnswerInterval,
    /// Its lower end.
    pub low: f64,
    /// Its upper end.
    pub high: f64,
    /// Why this interval, in words.
    pub reason: String,
}

/// How a campaign's audited tests stand: each is run again by a different
/// worker, and a third decides when two disagree (docs/operations.md).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
pub struct AuditCounts {
    /// Waiting for a second or a third run; the prefix stops at the first.
    pub open: u64,
    /// Two workers agreed.
    pub agreed: u64,
    /// Two disagreed and a third decided: the worker in the minority was
    /// flagged and its results taken back.
    pub settled: u64,
    /// Three runs, three outcomes; the first stands.
    pub undecided: u64,
    /// Taken back with the worker that ran them first.
    pub void: u64,
    /// Chosen, but no other live worker offered the program to run them.
    pub waived: u64,
}

/// `GET /api/v1/campaigns`: every campaign, newest first.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct CampaignList {
    /// The campaigns, newest first.
    pub campaigns: Vec<CampaignView>,
}

/// One point of a campaign's history.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct HistoryPoint {
    /// Valid tests in the prefix at this point (`n`).
    pub tests: u64,
    /// Test indices resolved at this point (valid and invalid).
    pub indices: u64,
    /// Events among those tests.
    pub events: u64,
    /// The estimate `μ̂ₙ` at this point.
    pub estimate: f64,
    /// The half-width `z σ̂/√n` at this point.
    pub half_width: f64,
    /// `half_width / estimate`; absent while the estimate is 0.
    pub relative_half_width: Option<f64>,
    /// Lower end of the interval at this point.
    pub ci_low: f64,
    /// Upper end of the interval at this point.
    pub ci_high: f64,
}

/// `GET /api/v1/campaigns/{id}/history`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct History {
    /// The campaign the history belongs to.
    pub campaign_id: i64,
    /// The points, in increasing `tests`.
    pub points: Vec<HistoryPoint>,
}

/// `GET /api/v1/campaigns/{id}/plan`: what a worker needs to reproduce any
/// test of the campaign from its index (SPEC §7): test `i` draws its
/// scenario from the stream `(seed, i)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct CampaignPlan {
    /// The campaign the plan belongs to.
    pub campaign_id: i64,
    /// The case whose scenarios the tests draw.
    pub case: String,
    /// The case's simulation preset (e.g. `paper-code`).
    pub preset: String,
    /// The exposure the weights use: the built-in model or a named table.
    pub exposure: ExposureRequest,
    /// The exposure's fingerprint, to check the worker's copy.
    pub exposure_fingerprint: String,
    /// How tests are drawn.
    pub method: Method,
    /// For `method: library`, the library file is at
    /// `/api/v1/libraries/{library_id}/file`.
    pub library_id: Option<i64>,
    /// Exploration share ε outside the library.
    pub epsilon: f64,
    /// How the ε share is spread outside the library.
    #[serde(default)]
    pub outside: Outside,
    /// How the tests are split between the library and the outside
    /// (`random` from a coordinator that does not say).
    #[serde(default)]
    pub split: Split,
    /// Seed of the test streams.
    pub seed: u64,
    /// The vehicle under test, as given at creation.
    #[schema(value_type = Object)]
    pub vut: serde_json::Value,
    /// For `method: adaptive`: report the criticality of every test at or
    /// below this (`near_misses` in a result report). Each test's cell and
    /// weight come with its lease (`tests`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub near_miss: Option<f64>,
    /// For other campaigns of an external program: report the criticality
    /// of every test at or below this too (`near_misses`), as evidence that
    /// the workers run the same program (docs/statistics.md, "Every test as
    /// evidence"). A worker that sends none only weakens that evidence.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub criticality_below: Option<f64>,
    /// For a user-defined case: its definition, which the worker registers
    /// before it opens the case.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub user_case: Option<crate::UserCaseDefinition>,
    /// For `method: build`: the library's search (the case's default when
    /// absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub build_search: Option<crate::SearchRequest>,
    /// For `method: build`: the library's threshold (the case's default
    /// when absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub build_threshold: Option<crate::ThresholdRequest>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_new_request_has_the_defaults_a_json_body_gets() {
        let parsed: CreateCampaign = serde_json::from_value(serde_json::json!({
            "case": "cut-in", "method": "library", "library_id": null, "vut": {"model": "idm"}
        }))
        .unwrap();
        assert_eq!(
            CreateCampaign::new(
                "cut-in",
                Method::Library,
                serde_json::json!({"model": "idm"})
            ),
            parsed
        );
    }
}
