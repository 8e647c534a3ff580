//! The failure mass an adaptive campaign's support leaves out (issue 52),
//! bounded from its exploring tests as a library campaign bounds what its
//! library leaves out ([`crate::outside`]).
//!
//! An estimation stage `s` on support `K_s` draws its exploring tests from
//! the exposure restricted to `O_s = X ∖ K_s`, of mass `m_s = P(O_s)`, with
//! `F` where the vehicle fails. The estimate's exploring part, `S₁,out/n`,
//! estimates `μ_O = Σ_s (n_s/n) P(F ∩ O_s)` over the stages' `n_s` valid
//! tests, and the guarded upper end replaces it by a bound `U ≥ μ_O`.
//!
//! An exploring test `i` of stage `s` fails with probability
//! `q_i = P(F ∩ O_s)/m_s` given the stages before it. The count of failing
//! exploring tests is then a Poisson binomial of mean `m q̄`, more
//! concentrated than the binomial of that mean (Hoeffding 1956), so the
//! one-sided Clopper–Pearson bound `p_U(k, m, c)` on `k` of `m` holds `q̄`
//! at confidence `c`. Every stage explores the same share of its tests
//! (`1/explore_every`; the guard's stages all the guard's share,
//! [`super::AllocationInputs::guard_share`], and a guarded campaign's
//! estimate starts again with them), so the
//! average over exploring tests is the average over tests, and
//! `μ_O ≤ m_max q̄`, `m_max` the largest `m_s` that explored. With `m̄` the
//! tests' average `m_s` (no stage can fail off its support more than its
//! mass there):
//!
//! `U = min(m̄, m_max · p_U(k, m, c))`.
//!
//! A failing cell of `K_s` is a failure found or an untested library cell
//! and stays in the support, so `F ∖ K ⊆ O_s` for the final support `K`
//! and `U` bounds the mass `P(F ∖ K)` that `K` leaves out as well. Every
//! exploring failure counts in `k`, also the ones the search then added to
//! `K`: they are in `μ_O`. Like the library's bound it holds at a fixed
//! number of tests and is approximate at the random stop;
//! `docs/statistics.md` measures it. Before any estimation test nothing is
//! ruled out: `U = 1`.

use crate::estimator::StoppingRule;
use crate::outside::{clopper_pearson_upper, OutsideTally};
use crate::prefix::PrefixFold;
use crate::sampling::TestDistribution;

/// An adaptive campaign's estimation tests as its outside bound reads them.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Explored {
    /// The estimation stages' exploring tests, their events and those
    /// events' terms `S₁,out` (their part of the estimate's `S₁`).
    pub tally: OutsideTally,
    /// `m_max`: the largest exposure off the support among the stages
    /// whose tests explored (0 before any did).
    pub mass_max: f64,
    /// `Σ m_s` over the valid estimation tests (`m̄ = mass_sum/tests`).
    pub mass_sum: f64,
    /// The valid estimation tests.
    pub tests: u64,
}

impl Explored {
    /// Counts valid test `index` of an estimation stage drawn from
    /// `distribution` under `seed`, with or without the event.
    pub fn test(&mut self, distribution: &TestDistribution, seed: u64, index: u64, event: bool) {
        let mass = exposure_off_support(distribution);
        self.tests += 1;
        self.mass_sum += mass;
        let explores = match distribution {
            TestDistribution::Ndd(_) => true,
            d => d.explores(seed, index),
        };
        if !explores {
            return;
        }
        self.mass_max = self.mass_max.max(mass);
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
        if self.tests == 0 {
            return 1.0;
        }
        let average = self.mass_sum / self.tests as f64;
        let t = &self.tally;
        let fill = if t.tests == 0 {
            1.0
        } else {
            self.mass_max * clopper_pearson_upper(t.events, t.tests, confidence)
        };
        fill.min(average).clamp(0.0, 1.0)
    }
}

/// The exposure an estimation stage's exploring tests sample: `P(X ∖ K)`,
/// all of it when the support is empty (the stage is the NDD).
pub(crate) fn exposure_off_support(distribution: &TestDistribution) -> f64 {
    match distribution {
        TestDistribution::Support(d) => d.outside_exposure(),
        _ => 1.0,
    }
}
