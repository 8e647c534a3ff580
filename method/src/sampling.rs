//! Test distributions: the ε-greedy library distribution and the NDD
//! baseline, with exact sampling by alias tables and importance weights.
//!
//! Randomness is counter-based: test `i` of a campaign with seed `s` draws
//! from a ChaCha8 stream keyed by `s` and positioned at stream `i`, so the
//! scenario of test `i` depends on `(s, i)` alone, not on who runs it or when.

use crate::alias::AliasTable;
use crate::library::Library;
use crate::mass::GridMass;
use crate::outside::OutsideMass;
pub use crate::test_stream::{long_test_rng, test_rng, TestRng, TestStreams};
use crate::tolerance::PROBABILITY_FLOOR;
use rand::Rng;
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

/// One drawn test: the scenario and its importance weight `P(x)/q(x)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Draw {
    /// The scenario's grid cell.
    pub cell: usize,
    /// Importance weight `P(x)/q(x)`.
    pub weight: f64,
}

/// The ε-greedy library distribution (SPEC §2.4):
/// `q(x) = (1 − ε) V(x)/W` on the library, and `ε` spread outside it.
#[derive(Debug, Clone)]
pub struct LibraryDistribution {
    exposure: GridMass,
    cells: Vec<usize>,
    inside: AliasTable,
    /// Position in `cells` of each grid cell in the library.
    in_library: Vec<Option<u32>>,
    inside_q: Vec<f64>,
    epsilon: f64,
    outside: OutsideSpread,
    split: Split,
    outside_cells: usize,
    /// For the NDD spread: alias over the outside cells with positive exposure.
    outside_ndd: Option<(Vec<usize>, AliasTable, f64)>,
    /// The worst-case fill of the outside cells, built when first asked for
    /// (only the coordinator and in-process runs need it).
    outside_mass: std::sync::OnceLock<OutsideMass>,
}

impl LibraryDistribution {
    /// The ε-greedy distribution of `library` on `exposure`, with ε spread
    /// outside as `outside` says and tests split between the library and
    /// the outside as `split` says.
    pub fn new(
        library: &Library,
        exposure: &GridMass,
        epsilon: f64,
        outside: OutsideSpread,
        split: Split,
    ) -> Result<Self, SamplingError> {
        check_epsilon(epsilon)?;
        let n = exposure.grid().len();
        if library.total_scenarios() != n {
            return Err(SamplingError::GridMismatch {
                library: library.total_scenarios(),
                exposure: n,
            });
        }
        if library.cells.is_empty() {
            return Err(SamplingError::EmptyLibrary);
        }
        let cells: Vec<usize> = library.cells.iter().map(|c| c.cell).collect();
        let mut in_library = vec![None; n];
        for (k, &c) in cells.iter().enumerate() {
            in_library[c] = Some(k as u32);
        }
        let outside_cells = n - cells.len();
        // With nothing outside, all mass stays in the library.
        let epsilon = if outside_cells == 0 { 0.0 } else { epsilon };
        let weights: Vec<f64> = library.cells.iter().map(|c| c.criticality).collect();
        let inside = AliasTable::new(weights).map_err(|_| SamplingError::EmptyLibrary)?;
        let inside_q = library
            .cells
            .iter()
            .map(|c| (1.0 - epsilon) * c.criticality / library.w)
            .collect();
        let outside_ndd = match outside {
            OutsideSpread::Uniform => None,
            OutsideSpread::Ndd => {
                let out: Vec<usize> = (0..n)
                    .filter(|&c| in_library[c].is_none() && exposure.p(c) > 0.0)
                    .collect();
                let mass: Vec<f64> = out.iter().map(|&c| exposure.p(c)).collect();
                let total: f64 = mass.iter().sum();
                AliasTable::new(mass).ok().map(|alias| (out, alias, total))
            }
        };
        let epsilon = match (outside, &outside_ndd) {
            (OutsideSpread::Ndd, None) => 0.0,
            _ => epsilon,
        };
        Ok(Self {
            exposure: exposure.clone(),
            cells,
            inside,
            in_library,
            inside_q,
            epsilon,
            outside,
            split,
            outside_cells,
            outside_ndd,
            outside_mass: Default::default(),
        })
    }

    /// The worst-case fill `F` of the scenarios outside the library
    /// ([`crate::outside`]): proportional to `P(X \ Φ)` under the NDD
    /// spread, the most exposed cells first under the uniform one.
    pub fn outside_mass(&self) -> &OutsideMass {
        self.outside_mass.get_or_init(|| {
            let outside = (0..self.in_library.len()).filter(|&c| self.in_library[c].is_none());
            match (&self.outside, &self.outside_ndd) {
                (OutsideSpread::Uniform, _) if self.outside_cells > 0 => {
                    OutsideMass::uniform(outside.map(|c| self.exposure.p(c)).collect())
                }
                (OutsideSpread::Uniform, _) => OutsideMass::Proportional { total: 0.0 },
                (OutsideSpread::Ndd, _) => OutsideMass::Proportional {
                    total: outside.map(|c| self.exposure.p(c)).sum(),
                },
            }
        })
    }

    /// Whether test `index` of a campaign with seed `seed` explores: draws
    /// its scenario outside the library. Under the random split the first
    /// number of its stream falls below ε; under the stratified split the
    /// index alone decides ([`stratified_explores`]).
    pub fn explores(&self, seed: u64, index: u64) -> bool {
        match self.split {
            Split::Random => self.explore(&mut test_rng(seed, index)),
            Split::Stratified => stratified_explores(self.epsilon, index),
        }
    }

    fn explore<R: Rng + ?Sized>(&self, rng: &mut R) -> bool {
        self.epsilon > 0.0 && rng.random::<f64>() < self.epsilon
    }

    /// The ε actually in force (0 when nothing lies outside the library).
    pub fn epsilon(&self) -> f64 {
        self.epsilon
    }

    /// The split of the tests between the library and the outside.
    pub fn split(&self) -> Split {
        self.split
    }

    /// The exploring share the estimate stratifies on: ε in force under the
    /// stratified split, `None` under the random one or when nothing is
    /// explored ([`crate::prefix::PrefixFold::strata`]).
    pub fn strata(&self) -> Option<f64> {
        (self.split == Split::Stratified && self.epsilon > 0.0).then_some(self.epsilon)
    }

    /// `q(x)`.
    pub fn q(&self, cell: usize) -> f64 {
        if let Some(k) = self.in_library[cell] {
            return self.inside_q[k as usize];
        }
        match (&self.outside, &self.outside_ndd) {
            (OutsideSpread::Uniform, _) => self.epsilon / self.outside_cells as f64,
            (OutsideSpread::Ndd, Some((_, _, total))) => {
                self.epsilon * self.exposure.p(cell) / total
            }
            (OutsideSpread::Ndd, None) => 0.0,
        }
    }

    /// Whether `cell` is in the library.
    pub fn contains(&self, cell: usize) -> bool {
        self.in_library[cell].is_some()
    }

    /// Draws one scenario by the random split (each draw explores with
    /// probability ε).
    pub fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> usize {
        let explore = self.explore(rng);
        self.sample_stratum(rng, explore)
    }

    /// Draws one scenario of the library (`q_in = V/W`) or, when `explore`,
    /// of the outside (`q_out`, spread as the distribution says).
    fn sample_stratum<R: Rng + ?Sized>(&self, rng: &mut R, explore: bool) -> usize {
        if !explore {
            return self.cells[self.inside.sample(rng)];
        }
        match (&self.outside, &self.outside_ndd) {
            (OutsideSpread::Ndd, Some((out, alias, _))) => out[alias.sample(rng)],
            _ => self.sample_uniform_outside(rng),
        }
    }

    /// Uniform over the cells outside the library: the k-th outside cell for
    /// a uniform k, found by skipping library cells (which are sorted).
    fn sample_uniform_outside<R: Rng + ?Sized>(&self, rng: &mut R) -> usize {
        let k = rng.random_range(0..self.outside_cells);
        // The k-th cell not in `cells`: the answer is k + (number of library
        // cells ≤ answer); binary search on the sorted library cells.
        let (mut lo, mut hi) = (0usize, self.cells.len());
        while lo < hi {
            let mid = (lo + hi) / 2;
            // Library cells before position mid leave cells[mid] − mid outside cells below it.
            if self.cells[mid] - mid <= k {
                lo = mid + 1;
            } else {
                hi = mid;
            }
        }
        k + lo
    }

    /// A test's scenario and weight `P(x)/q(x)`, `q` being the mixture
    /// `(1 − ε) q_in + ε q_out` under either split: a stratum's own weight
    /// `P/q_in` or `P/q_out` is this times `1 − ε` or `ε`.
    pub fn draw(&self, seed: u64, index: u64) -> Draw {
        self.draw_from(&mut test_rng(seed, index), index)
    }

    /// [`Self::draw`] from test `index`'s stream `rng`.
    pub fn draw_from(&self, rng: &mut TestRng, index: u64) -> Draw {
        let cell = match self.split {
            Split::Random => self.sample(rng),
            Split::Stratified => self.sample_stratum(rng, stratified_explores(self.epsilon, index)),
        };
        Draw {
            cell,
            weight: self.exposure.p(cell) / self.q(cell).max(PROBABILITY_FLOOR),
        }
    }
}

/// The NDD baseline: `q = P`, every weight 1.
#[derive(Debug, Clone)]
pub struct NddDistribution {
    alias: AliasTable,
}

impl NddDistribution {
    /// Tests drawn from the exposure itself.
    pub fn new(exposure: &GridMass) -> Self {
        let alias = AliasTable::new(exposure.masses().to_vec())
            .expect("a mass function has positive total weight");
        Self { alias }
    }

    /// Test `index` of the campaign seeded `seed`: a cell drawn from `P`, weight 1.
    pub fn draw(&self, seed: u64, index: u64) -> Draw {
        self.draw_from(&mut test_rng(seed, index))
    }

    /// [`Self::draw`] from the test's stream `rng`.
    pub fn draw_from(&self, rng: &mut TestRng) -> Draw {
        Draw {
            cell: self.sample(rng),
            weight: 1.0,
        }
    }

    /// A cell drawn from `P` with `rng`.
    pub fn sample<R: Rng + ?Sized>(&self, rng: &mut R) -> usize {
        self.alias.sample(rng)
    }
}

/// Either test distribution.
#[derive(Debug, Clone)]
pub enum TestDistribution {
    /// From a library, ε-greedy.
    Library(Box<LibraryDistribution>),
    /// From the naturalistic exposure (the baseline).
    Ndd(NddDistribution),
    /// An adaptive campaign's estimation stage on its support.
    Support(Box<crate::support_sampling::SupportDistribution>),
    /// Every cell with exposure once, in cell order, weight 1: a library
    /// build's surrogate runs leased to workers as tests (test `i` is the
    /// `i`-th cell; the seed plays no part).
    Enumeration(std::sync::Arc<[usize]>),
}

impl TestDistribution {
    /// The distribution of `distribution`, boxed.
    pub fn library(distribution: LibraryDistribution) -> Self {
        Self::Library(Box::new(distribution))
    }

    /// Test `index` of the campaign seeded `seed`: its cell and weight, from the stream `(seed, index)`.
    pub fn draw(&self, seed: u64, index: u64) -> Draw {
        match self {
            TestDistribution::Library(d) => d.draw(seed, index),
            TestDistribution::Ndd(d) => d.draw(seed, index),
            TestDistribution::Support(d) => d.draw(seed, index),
            TestDistribution::Enumeration(cells) => Self::enumerated(cells, index),
        }
    }

    /// `f(index, draw)` for each test of `indices`, in order: the same
    /// draws as [`Self::draw`], their streams' first blocks computed
    /// several at a time ([`TestStreams::each`]).
    pub fn draw_each(
        &self,
        seed: u64,
        indices: impl IntoIterator<Item = u64>,
        mut f: impl FnMut(u64, Draw),
    ) {
        let streams = TestStreams::new(seed);
        match self {
            TestDistribution::Library(d) => {
                streams.each(indices, |i, mut rng| f(i, d.draw_from(&mut rng, i)))
            }
            TestDistribution::Ndd(d) => {
                streams.each(indices, |i, mut rng| f(i, d.draw_from(&mut rng)))
            }
            TestDistribution::Support(d) => {
                streams.each(indices, |i, mut rng| f(i, d.draw_from(&mut rng, i)))
            }
            TestDistribution::Enumeration(cells) => {
                for i in indices {
                    f(i, Self::enumerated(cells, i))
                }
            }
        }
    }

    /// The draws of tests `from..to`, in order ([`Self::draw_each`]).
    pub fn draws(&self, seed: u64, from: u64, to: u64) -> Vec<Draw> {
        let mut draws = Vec::with_capacity(to.saturating_sub(from) as usize);
        self.draw_each(seed, from..to, |_, draw| draws.push(draw));
        draws
    }

    /// Test `index` of an enumeration: the index-th cell.
    fn enumerated(cells: &[usize], index: u64) -> Draw {
        Draw {
            cell: cells[(index as usize).min(cells.len() - 1)],
            weight: 1.0,
        }
    }

    /// Whether a draw explored: its cell lies outside the library (the
    /// library's share draws only library cells, the exploring share only
    /// cells outside it), so this equals [`Self::explores`] of its test
    /// without drawing again. Never for the NDD.
    pub fn explored(&self, draw: &Draw) -> bool {
        match self {
            TestDistribution::Library(d) => !d.contains(draw.cell),
            TestDistribution::Ndd(_) | TestDistribution::Enumeration(_) => false,
            TestDistribution::Support(d) => !d.contains(draw.cell),
        }
    }

    /// Whether test `index` draws outside the library (never for the NDD).
    pub fn explores(&self, seed: u64, index: u64) -> bool {
        match self {
            TestDistribution::Library(d) => d.explores(seed, index),
            TestDistribution::Ndd(_) | TestDistribution::Enumeration(_) => false,
            TestDistribution::Support(d) => stratified_explores(d.epsilon(), index),
        }
    }

    /// The exploring share the estimate stratifies on
    /// ([`LibraryDistribution::strata`]); `None` for the NDD.
    pub fn strata(&self) -> Option<f64> {
        match self {
            TestDistribution::Library(d) => d.strata(),
            TestDistribution::Ndd(_) | TestDistribution::Enumeration(_) => None,
            TestDistribution::Support(d) => Some(d.epsilon()).filter(|&e| e > 0.0),
        }
    }

    /// The fill of the scenarios outside the library; `None` for the NDD,
    /// which samples every scenario by its exposure.
    pub fn outside_mass(&self) -> Option<&OutsideMass> {
        match self {
            TestDistribution::Library(d) => Some(d.outside_mass()),
            TestDistribution::Ndd(_)
            | TestDistribution::Support(_)
            | TestDistribution::Enumeration(_) => None,
        }
    }
}
