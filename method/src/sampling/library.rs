//! The ε-greedy library distribution.

use super::draw::Draw;
use super::share::{
    allocated_explores, check_epsilon, OutsideSpread, SamplingError, Split, SwitchCell,
};
use crate::alias::AliasTable;
use crate::anytime::TermBounds;
use crate::library::Library;
use crate::mass::GridMass;
use crate::outside::OutsideMass;
use crate::test_stream::{test_rng, TestRng};
use crate::tolerance::PROBABILITY_FLOOR;
use rand::Rng;

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
    /// The largest terms of an anytime campaign's sequences, likewise.
    term_bounds: std::sync::OnceLock<TermBounds>,
    /// The test from which nearly every test explores
    /// ([`allocated_explores`]); stratified split only.
    switch: SwitchCell,
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
            term_bounds: Default::default(),
            switch: SwitchCell::default(),
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

    /// The largest term each sequence of an anytime campaign can see
    /// ([`crate::anytime`]): under the stratified split a library test's
    /// `(1 − ε) w` and an exploring test's `ε w` (`P(X \ Φ)` under the NDD
    /// spread, `P(x) N_out` at most under the uniform one), each the
    /// largest over its cells of the weight [`Self::draw`] computes; under
    /// the random split the largest weight `w` of all.
    pub fn term_bounds(&self) -> TermBounds {
        *self.term_bounds.get_or_init(|| {
            let weight = |cell: usize| self.exposure.p(cell) / self.q(cell).max(PROBABILITY_FLOOR);
            let largest =
                |cells: &mut dyn Iterator<Item = usize>| cells.map(weight).fold(0.0f64, f64::max);
            let inside = largest(&mut self.cells.iter().copied());
            let outside = largest(&mut (0..self.in_library.len()).filter(|&c| !self.contains(c)));
            match self.strata() {
                Some(epsilon) => TermBounds::Stratified {
                    inside: ((1.0 - epsilon) * inside).max(f64::MIN_POSITIVE),
                    outside: (epsilon * outside).max(f64::MIN_POSITIVE),
                },
                None if self.epsilon > 0.0 => {
                    TermBounds::Single(inside.max(outside).max(f64::MIN_POSITIVE))
                }
                None => TermBounds::Single(inside.max(f64::MIN_POSITIVE)),
            }
        })
    }

    /// Whether test `index` of a campaign with seed `seed` explores: draws
    /// its scenario outside the library. Under the random split the first
    /// number of its stream falls below ε; under the stratified split the
    /// index and the switch decide ([`allocated_explores`]).
    pub fn explores(&self, seed: u64, index: u64) -> bool {
        match self.split {
            Split::Random => self.explore(&mut test_rng(seed, index)),
            Split::Stratified => allocated_explores(self.epsilon, self.switch.get(), index),
        }
    }

    /// The test from which nearly every test explores, once switched.
    pub fn explore_from(&self) -> Option<u64> {
        self.switch.get()
    }

    /// Sets the switch ([`allocated_explores`]): tests from `from` on
    /// explore with [`super::share::LATE_SHARE`]. Tests before it draw as
    /// they did. Only a stratified campaign with an outside switches;
    /// `false` (and nothing set) otherwise.
    pub fn set_explore_from(&self, from: Option<u64>) -> bool {
        if self.strata().is_none() {
            return from.is_none();
        }
        self.switch.set(from);
        true
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
            Split::Stratified => self.sample_stratum(
                rng,
                allocated_explores(self.epsilon, self.switch.get(), index),
            ),
        };
        Draw {
            cell,
            weight: self.exposure.p(cell) / self.q(cell).max(PROBABILITY_FLOOR),
        }
    }
}
