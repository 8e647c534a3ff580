//! The failure mass an adaptive campaign's support leaves out (issue 52),
//! bounded from its exploring tests as a library campaign bounds what its
//! library leaves out ([`crate::outside`]).
//!
//! An estimation stage `s` on support `K_s` draws its exploring tests from
//! the exposure restricted to `O_s = X ∖ K_s`, of mass `m_s = P(O_s)`. Let
//! `F` be where the vehicle fails and `K` the final support. A failing cell
//! of `K_s` is a failure found or a library cell not yet tested, and either
//! stays in the support (a failure never leaves it; an untested cell leaves
//! only when a test passes there), so `F ∖ K ⊆ O_s` and the mass left out,
//! `μ_out = P(F ∖ K)`, is at most `P(F ∩ O_s)`. An exploring test of stage
//! `s` fails with probability `P(F ∩ O_s)/m_s ≥ μ_out/m_max`, where `m_max`
//! is the largest `m_s` among the stages that explored. The count of
//! failing exploring tests then stochastically dominates a binomial of
//! that rate, and with `k` of `m` failing the one-sided Clopper–Pearson
//! bound gives
//!
//! `U = min(m_min, m_max · p_U(k, m, c))`,
//!
//! with `m_min` the smallest `m_s` (no more than the exposure a stage left
//! unsampled can fail outside `K`). Every exploring failure counts in `k`,
//! also the ones the search then added to `K`: the bound stays valid, and
//! pays for them in width. Like the library's bound it holds at a fixed
//! number of tests and is approximate at the random stop (and here at a
//! support that the exploring tests themselves moved);
//! `docs/statistics.md` measures it. With no estimation stage, nothing is
//! ruled out: `U = 1`.

use crate::estimator::StoppingRule;
use crate::outside::{clopper_pearson_upper, OutsideTally};
use crate::prefix::PrefixFold;
use crate::sampling::TestDistribution;

/// An adaptive campaign's exploring tests so far.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Explored {
    /// The estimation stages' exploring tests, their events and those
    /// events' terms `S₁,out` (their part of the estimate's `S₁`).
    pub tally: OutsideTally,
    /// `m_max`: the largest exposure off the support among the stages
    /// whose tests explored (0 before any did).
    pub mass_max: f64,
    /// `m_min`: the smallest exposure off the support of any estimation
    /// stage (1 before the first).
    pub mass_min: f64,
}

impl Default for Explored {
    fn default() -> Self {
        Self {
            tally: OutsideTally::default(),
            mass_max: 0.0,
            mass_min: 1.0,
        }
    }
}

impl Explored {
    /// Counts an estimation stage drawn from `distribution` (its support's
    /// exposure off it, whether or not a test explored).
    pub fn stage(&mut self, distribution: &TestDistribution) {
        self.mass_min = self.mass_min.min(exposure_off_support(distribution));
    }

    /// Counts test `index` of an estimation stage drawn from
    /// `distribution` under `seed`, valid, with or without the event, when
    /// it explored.
    pub fn test(&mut self, distribution: &TestDistribution, seed: u64, index: u64, event: bool) {
        let explores = match distribution {
            TestDistribution::Ndd(_) => true,
            d => d.explores(seed, index),
        };
        if !explores {
            return;
        }
        self.mass_max = self.mass_max.max(exposure_off_support(distribution));
        if event {
            self.tally
                .add(distribution.draw(seed, index).weight, || false);
        } else {
            self.tally.tests += 1;
        }
    }

    /// `fold` (the estimation tests') with these exploring tests as its
    /// outside tally, so that its summary subtracts their part of the
    /// estimate where the bound replaces it
    /// ([`crate::campaign::CampaignResult::with_outside_upper`]).
    pub fn on(&self, fold: &PrefixFold) -> PrefixFold {
        PrefixFold {
            outside: self.tally,
            ..*fold
        }
    }

    /// The guard of a guarded adaptive campaign, as a library campaign's
    /// ([`crate::outside::OutsideTally::guarded`]): `U ≤ β μ̂ + μ̂_out`,
    /// `μ̂_out = S₁,out/n` the exploring tests' part of the estimate `fold`.
    pub fn guard_holds(&self, fold: &PrefixFold, rule: &StoppingRule) -> bool {
        let n = fold.estimator.tests();
        n > 0
            && self.upper(rule.confidence) <= rule.beta * fold.estimate() + self.tally.s1 / n as f64
    }

    /// `U` at `confidence` (see the module documentation).
    pub fn upper(&self, confidence: f64) -> f64 {
        let t = &self.tally;
        let fill = self.mass_max * clopper_pearson_upper(t.events, t.tests, confidence);
        let upper = if t.tests == 0 { 1.0 } else { fill };
        upper.min(self.mass_min).clamp(0.0, 1.0)
    }
}

/// The exposure an estimation stage's exploring tests sample: `P(X ∖ K)`,
/// all of it when the support is empty (the stage is the NDD).
fn exposure_off_support(distribution: &TestDistribution) -> f64 {
    match distribution {
        TestDistribution::Support(d) => d.outside_exposure(),
        _ => 1.0,
    }
}
