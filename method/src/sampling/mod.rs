//! Test distributions: the ε-greedy library distribution and the NDD
//! baseline, with exact sampling by alias tables and importance weights.
//!
//! Randomness is counter-based: test `i` of a campaign with seed `s` draws
//! from a ChaCha8 stream keyed by `s` and positioned at stream `i`, so the
//! scenario of test `i` depends on `(s, i)` alone, not on who runs it or when.

mod draw;
mod library;
mod ndd;
mod share;
pub mod support;

pub use draw::Draw;
pub use library::LibraryDistribution;
pub use ndd::NddDistribution;
pub use share::{
    allocated_explores, check_epsilon, default_outside, stratified_explores, OutsideSpread,
    SamplingError, Split, LATE_SHARE, MAX_EPSILON, MIN_EPSILON,
};
pub use support::SupportDistribution;

use crate::anytime::TermBounds;
use crate::outside::OutsideMass;
pub use crate::test_stream::{long_test_rng, test_rng, TestRng, TestStreams};

/// Either test distribution.
#[derive(Debug, Clone)]
pub enum TestDistribution {
    /// From a library, ε-greedy.
    Library(Box<LibraryDistribution>),
    /// From the naturalistic exposure (the baseline).
    Ndd(NddDistribution),
    /// An adaptive campaign's estimation stage on its support.
    Support(Box<SupportDistribution>),
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

    /// The test from which nearly every test explores, once a library
    /// campaign switched ([`LibraryDistribution::set_explore_from`]).
    pub fn explore_from(&self) -> Option<u64> {
        match self {
            TestDistribution::Library(d) => d.explore_from(),
            _ => None,
        }
    }

    /// Sets the switch of a stratified library campaign; `false` where
    /// there is none to set (and `from` is not `None`).
    pub fn set_explore_from(&self, from: Option<u64>) -> bool {
        match self {
            TestDistribution::Library(d) => d.set_explore_from(from),
            _ => from.is_none(),
        }
    }

    /// The largest terms of an anytime campaign's sequences
    /// ([`crate::anytime`]): 1 for the NDD, the library's per stratum;
    /// `None` for an adaptive stage or an enumeration.
    pub fn term_bounds(&self) -> Option<TermBounds> {
        match self {
            TestDistribution::Library(d) => Some(d.term_bounds()),
            TestDistribution::Ndd(_) => Some(TermBounds::Single(1.0)),
            TestDistribution::Support(_) | TestDistribution::Enumeration(_) => None,
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
