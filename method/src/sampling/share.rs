//! The ε share of a library campaign: its range, how the tests are split
//! between the library and the outside, and how it is spread outside.

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// How the ε share of the library distribution is spread outside the library.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum OutsideSpread {
    /// `q(x) = ε / (N(X) − N(Φ))` (the paper's form, the default).
    #[default]
    Uniform,
    /// `q(x) = ε P(x) / P(X \ Φ)`: never spends tests on impossible scenarios.
    Ndd,
}

impl std::str::FromStr for OutsideSpread {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "uniform" => Ok(OutsideSpread::Uniform),
            "ndd" => Ok(OutsideSpread::Ndd),
            other => Err(format!(
                "unknown outside spread `{other}`; spreads are uniform, ndd"
            )),
        }
    }
}

/// The spread a library campaign gets when none is asked for: the NDD
/// spread when its rule guards the outside or reads an anytime interval,
/// the case's default otherwise. The NDD spread is the only one whose
/// outside weights are bounded by `P(X \ Φ)`, so the only one under which
/// a bound on the outside failure mass reaches `βμ` in about
/// `ln(1/(1 − c))/(βμ)` exploring tests; under the uniform spread an
/// exploring test's weight is `P(x) N_out`, and the bound has to allow for
/// a failure in the most exposed outside cell (docs/statistics.md,
/// "The model-free floor" and "The guard's allocation").
pub fn default_outside(
    case_default: OutsideSpread,
    rule: &crate::estimator::StoppingRule,
) -> OutsideSpread {
    if rule.guard_outside || rule.interval == crate::estimator::Interval::Anytime {
        OutsideSpread::Ndd
    } else {
        case_default
    }
}

/// How a library campaign's tests are split between the library and the
/// scenarios outside it (docs/statistics.md, "Strata").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Split {
    /// Each test explores with probability ε (the paper's ε-greedy draw):
    /// the number of library tests in a prefix of `n` is Binomial(n, 1 − ε),
    /// and for a vehicle the library covers that split is nearly the whole
    /// variance of the estimate. Campaigns created before the stratified
    /// design keep it.
    Random,
    /// Test `i` explores exactly when `⌊(i + 1)ε⌋ > ⌊iε⌋`: every prefix of
    /// `n` tests holds `⌊nε⌋` exploring tests, and the estimate weights each
    /// stratum by its share, `μ̂ = (1 − ε) m̂_in + ε m̂_out`
    /// ([`crate::prefix::PrefixFold::estimate`]). The default.
    #[default]
    Stratified,
}

impl Split {
    /// The name on the command line and in the API.
    pub fn name(self) -> &'static str {
        match self {
            Split::Random => "random",
            Split::Stratified => "stratified",
        }
    }
}

impl std::str::FromStr for Split {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "random" => Ok(Split::Random),
            "stratified" => Ok(Split::Stratified),
            other => Err(format!(
                "unknown split `{other}`; splits are stratified, random"
            )),
        }
    }
}

/// Whether test `index` explores under the stratified split with share
/// `epsilon`: `⌊(i + 1)ε⌋ > ⌊iε⌋`, so tests `0..n` hold `⌊nε⌋` exploring
/// tests (in exact arithmetic; in `f64` the same on every machine).
pub fn stratified_explores(epsilon: f64, index: u64) -> bool {
    epsilon > 0.0 && ((index + 1) as f64 * epsilon).floor() > (index as f64 * epsilon).floor()
}

/// The exploring share of a library campaign from its switch on (issue 49,
/// docs/statistics.md "The allocation"): once the library stratum is known
/// to its share of β, nearly every further test explores, because the bound
/// on the failure mass outside the library is what the campaign still
/// waits for.
pub const LATE_SHARE: f64 = 0.95;

/// Whether test `index` explores under the stratified split with share ε
/// before the switch `from` and [`LATE_SHARE`] from it on:
/// [`stratified_explores`] on each side, counted from each side's start.
/// The stratum of every test is fixed by its index and the switch, and the
/// switch by what was folded before it, so it never depends on the test's
/// own outcome.
pub fn allocated_explores(epsilon: f64, from: Option<u64>, index: u64) -> bool {
    match from {
        Some(from) if index >= from => stratified_explores(LATE_SHARE, index - from),
        _ => stratified_explores(epsilon, index),
    }
}

/// A campaign's switch, set once: `None` until it is made. Shared by the
/// copies of a distribution that one campaign's readers hold, and copied
/// by value when a distribution is cloned.
#[derive(Debug)]
pub struct SwitchCell(std::sync::atomic::AtomicU64);

impl Default for SwitchCell {
    /// No switch made.
    fn default() -> Self {
        SwitchCell(std::sync::atomic::AtomicU64::new(Self::NONE))
    }
}

impl SwitchCell {
    const NONE: u64 = u64::MAX;

    /// The switch, if made.
    pub fn get(&self) -> Option<u64> {
        match self.0.load(std::sync::atomic::Ordering::Acquire) {
            Self::NONE => None,
            from => Some(from),
        }
    }

    /// Sets (or, with `None`, clears) the switch.
    pub fn set(&self, from: Option<u64>) {
        self.0.store(
            from.unwrap_or(Self::NONE),
            std::sync::atomic::Ordering::Release,
        );
    }
}

impl Clone for SwitchCell {
    fn clone(&self) -> Self {
        let cell = SwitchCell::default();
        cell.set(self.get());
        cell
    }
}

/// The smallest positive ε: a smaller share explores so rarely (one test
/// in a million) that no campaign sees it, and tiny values only make the
/// outside weights `P(x)/(ε/N)` overflow.
pub const MIN_EPSILON: f64 = 1e-6;
/// The largest ε: at least 0.1 % of the tests come from the library.
pub const MAX_EPSILON: f64 = 0.999;

/// Checks ε: 0 (no exploration) or in `[MIN_EPSILON, MAX_EPSILON]`.
pub fn check_epsilon(epsilon: f64) -> Result<(), SamplingError> {
    if epsilon == 0.0 || (MIN_EPSILON..=MAX_EPSILON).contains(&epsilon) {
        Ok(())
    } else {
        Err(SamplingError::Epsilon(epsilon))
    }
}

/// Why a test distribution cannot be built.
#[derive(Debug, Error, PartialEq)]
pub enum SamplingError {
    /// ε outside {0} ∪ [`MIN_EPSILON`, `MAX_EPSILON`].
    #[error("ε = {} must be 0 or in [{MIN_EPSILON}, {MAX_EPSILON}]", crate::number::Num(*.0))]
    Epsilon(f64),
    /// A library without cells.
    #[error("the library is empty: there is nothing to sample with weight 1 − ε")]
    EmptyLibrary,
    #[error(
        "ε = 0 gives the states and actions outside a car-following library probability 0, \
         and some accidents (even the surrogate's own, from states between grid points) lie \
         there: the estimate would be biased low; use ε > 0"
    )]
    /// ε = 0 on car-following, which would bias the estimate low.
    NoExploration,
    /// The library's grid and the exposure's differ.
    #[error("the library's grid has {library} cells but the exposure has {exposure}")]
    GridMismatch {
        /// Cells of the library's grid.
        library: usize,
        /// Cells of the exposure's grid.
        exposure: usize,
    },
}
