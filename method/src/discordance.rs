//! Does one worker's program behave like the others'? A sequential test
//! for vehicles that are not bit-reproducible.
//!
//! When a program's runs of one test may differ, an audit's two runs
//! disagreeing proves nothing. What does carry evidence is the direction
//! of the disagreements. Take the audits chosen by the secret sample (their
//! choice depends on no outcome) on which a worker `W` and a partner both
//! ran the test, and keep the *discordant* ones: one run found an event
//! and the other none. If `W` runs the same program as its partners, the
//! two runs of a test are exchangeable given the scenario, so each
//! discordant pair is `W`'s event with probability ½, whatever the
//! scenario and however noisy the program. A `W` whose program brakes
//! harder, or hides events, lands on one side far more often.
//!
//! With `h` discordant pairs where `W` found the event and `g` where its
//! partner did, the Krichevsky–Trofimov mixture of the likelihood ratio
//! of Bernoulli(θ) against Bernoulli(½),
//!
//! `E(h, g) = ∫ θ^h (1 − θ)^g dBeta(½, ½)(θ) / 2^{−(h+g)}
//!          = 2^{h+g} B(h + ½, g + ½) / B(½, ½)`,
//!
//! is a nonnegative martingale with mean 1 under "same program" (each
//! pair multiplies it by `2θ̂` or `2(1 − θ̂)` with the running KT estimate
//! `θ̂ = (h + ½)/(h + g + 1)`, whose two values average to 1). Ville's
//! inequality bounds the chance that it *ever* reaches `1/α` by α, so a
//! worker can be checked after every audit, for ever, and is flagged at
//! [`FLAG_AT`] = 10⁴: an honest worker is falsely flagged at most once in
//! 10⁴, over its whole life, not per campaign.
//!
//! One lying partner must not make an honest worker look different: a
//! worker's evidence ([`worker_evidence`]) is the smallest, over its
//! partners, of the e-value of its pairs with all *other* partners. With at
//! most one liar in the fleet, that is at most the e-value of an honest
//! worker against honest workers only, which Ville's bound covers. A worker
//! with a single partner is never flagged: two workers cannot tell which
//! of them differs.

use statrs::function::beta::ln_beta;

/// The evidence at which a worker is flagged: a false flag at most once
/// in 10⁴ honest workers (Ville's inequality).
pub const FLAG_AT: f64 = 1e4;

/// The discordant pairs of one worker with one partner.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Discordant {
    /// The worker found an event and the partner none.
    pub own_event: u64,
    /// The partner found an event and the worker none.
    pub partner_event: u64,
}

/// `E(h, g) = 2^{h+g} B(h + ½, g + ½) / B(½, ½)` (see the module), in logs
/// so that thousands of pairs neither overflow nor underflow.
pub fn kt_e_value(own_event: u64, partner_event: u64) -> f64 {
    let (h, g) = (own_event as f64, partner_event as f64);
    let ln =
        (h + g) * std::f64::consts::LN_2 + ln_beta(h + 0.5, g + 0.5) - std::f64::consts::PI.ln();
    ln.exp()
}

/// A worker's evidence from its pairs with each partner: the smallest,
/// over the partners, of [`kt_e_value`] of the pairs with all the others
/// (one lying partner cannot make it look different); 1 with fewer than
/// two partners.
pub fn worker_evidence(partners: &[Discordant]) -> f64 {
    if partners.len() < 2 {
        return 1.0;
    }
    let h: u64 = partners.iter().map(|p| p.own_event).sum();
    let g: u64 = partners.iter().map(|p| p.partner_event).sum();
    partners
        .iter()
        .map(|p| kt_e_value(h - p.own_event, g - p.partner_event))
        .fold(f64::INFINITY, f64::min)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_e_value_matches_hand_computed_betas() {
        // B(½,½) = π, B(3/2,½) = π/2, B(5/2,½) = 3π/8, B(3/2,3/2) = π/8.
        assert!((kt_e_value(0, 0) - 1.0).abs() < 1e-12);
        assert!((kt_e_value(1, 0) - 1.0).abs() < 1e-12);
        assert!((kt_e_value(0, 1) - 1.0).abs() < 1e-12);
        assert!((kt_e_value(2, 0) - 1.5).abs() < 1e-12);
        assert!((kt_e_value(1, 1) - 0.5).abs() < 1e-12);
        // Symmetric, and huge counts stay finite.
        assert_eq!(kt_e_value(7, 3), kt_e_value(3, 7));
        assert!(kt_e_value(5000, 5000).is_finite());
        assert!(kt_e_value(5000, 0).is_infinite() || kt_e_value(5000, 0) > 1e300);
    }

    #[test]
    fn each_pair_keeps_its_mean_under_the_same_program() {
        // The martingale property, exactly: from (h, g) the next pair is
        // either side with probability ½.
        for h in 0..60 {
            for g in 0..60 {
                let next = (kt_e_value(h + 1, g) + kt_e_value(h, g + 1)) / 2.0;
                let now = kt_e_value(h, g);
                assert!((next - now).abs() <= 1e-9 * now, "({h}, {g})");
            }
        }
    }

    /// The exact chance that `E` reaches `level` within `n` pairs when each
    /// is the worker's with probability `p`: a walk on (h, g) absorbed at
    /// the level, by enumeration.
    fn crossing_probability(n: usize, p: f64, level: f64) -> f64 {
        let mut alive = vec![1.0f64]; // alive[h] after k pairs, g = k − h
        let mut crossed = 0.0;
        for k in 0..n {
            let mut next = vec![0.0f64; k + 2];
            for (h, &mass) in alive.iter().enumerate() {
                next[h + 1] += mass * p;
                next[h] += mass * (1.0 - p);
            }
            for (h, mass) in next.iter_mut().enumerate() {
                if kt_e_value(h as u64, (k + 1 - h) as u64) >= level {
                    crossed += *mass;
                    *mass = 0.0;
                }
            }
            alive = next;
        }
        crossed
    }

    #[test]
    fn an_honest_worker_is_flagged_less_often_than_the_level_promises() {
        // Ville: P(ever ≥ 1/α) ≤ α, checked exactly over 2,000 pairs at
        // the flag's level and at a level where the chance is measurable.
        let at_flag = crossing_probability(2000, 0.5, FLAG_AT);
        assert!(at_flag <= 1e-4, "{at_flag}");
        assert!(
            at_flag > 1e-6,
            "the bound should not be wildly loose: {at_flag}"
        );
        let at_20 = crossing_probability(2000, 0.5, 20.0);
        assert!(at_20 <= 0.05 && at_20 > 0.01, "{at_20}");
    }

    #[test]
    fn a_worker_on_one_side_is_flagged_within_a_few_dozen_pairs() {
        // A program on the other side of nine discordant pairs in ten:
        // flagged within 40 pairs with chance 0.84, within 60 with 0.995.
        let within = |n| crossing_probability(n, 0.1, FLAG_AT);
        assert!((within(40) - 0.843).abs() < 0.01, "{}", within(40));
        assert!(within(60) > 0.99);
        // All on one side: 17 pairs reach 10⁴ (2¹⁶ B(½, 16½)/π ≈ 9.2e3, 2¹⁷ B(½, 17½)/π ≈ 1.8e4).
        assert!(kt_e_value(0, 16) < FLAG_AT && kt_e_value(0, 17) >= FLAG_AT);
    }

    #[test]
    fn one_lying_partner_cannot_make_an_honest_worker_look_different() {
        let pair = |own_event, partner_event| Discordant {
            own_event,
            partner_event,
        };
        // Against the liar the honest worker found every event (30 of 30);
        // against an honest partner the pairs split evenly.
        let honest = [pair(30, 0), pair(6, 5)];
        assert!(kt_e_value(36, 5) > FLAG_AT);
        assert!((worker_evidence(&honest) - kt_e_value(6, 5)).abs() < 1e-12);
        // The liar is on the wrong side against both of its partners.
        let liar = [pair(0, 30), pair(0, 25)];
        assert!(worker_evidence(&liar) >= FLAG_AT);
        // A single partner proves nothing either way.
        assert_eq!(worker_evidence(&[pair(0, 50)]), 1.0);
        assert_eq!(worker_evidence(&[]), 1.0);
    }
}
