use super::*;
use crate::outside::OutsideMass;
use crate::sampling::stratified_explores;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const EPSILON: f64 = 0.5;
/// A library stratum's own terms lie in `[0, INSIDE]`, mean `0.9 · INSIDE/2`.
const INSIDE: f64 = 2e-3;
/// The exploring stratum fails with this chance, term `P(X \ Φ) = 1`.
const OUTSIDE_RATE: f64 = 1e-4;

fn rule(max_tests: u64) -> StoppingRule {
    StoppingRule {
        interval: crate::estimator::Interval::Anytime,
        n_min: 30,
        ..StoppingRule::new(0.2, max_tests)
    }
}

/// Test `i` of a stratified campaign: its sparse outcome (wire weights,
/// `own/(1 − ε)` inside and `own/ε` outside), some of them invalid.
fn outcomes(seed: u64, len: u64) -> Vec<(u64, SparseOutcome)> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..len)
        .filter_map(|i| {
            let u: f64 = rng.random();
            if u < 0.002 {
                return Some((i, SparseOutcome::Invalid));
            }
            let event = if stratified_explores(EPSILON, i) {
                (rng.random::<f64>() < OUTSIDE_RATE).then_some(1.0 / EPSILON)
            } else {
                (rng.random::<f64>() < 0.9).then(|| INSIDE * rng.random::<f64>() / (1.0 - EPSILON))
            };
            event.map(|w| (i, SparseOutcome::Event(w)))
        })
        .collect()
}

fn explored(from: u64, to: u64) -> Vec<u64> {
    (from..to)
        .filter(|&i| stratified_explores(EPSILON, i))
        .collect()
}

fn fresh(rule: &StoppingRule) -> AnytimeFold {
    AnytimeFold::new(
        rule,
        Some(EPSILON),
        TermBounds::Stratified {
            inside: INSIDE,
            outside: 1.0,
        },
    )
}

/// Folds `from..to` of `all` onto `fold`.
fn advance(
    fold: &mut AnytimeFold,
    rule: &StoppingRule,
    all: &[(u64, SparseOutcome)],
    to: u64,
    mass: &OutsideMass,
) -> Option<Decision> {
    let from = fold.fold.indices;
    let span: Vec<_> = all
        .iter()
        .copied()
        .filter(|o| from <= o.0 && o.0 < to)
        .collect();
    let explored = explored(from, to);
    let misses = |_| false;
    fold.advance(
        rule,
        to,
        &span,
        Some(Exploration {
            explored: &explored,
            mass,
            surrogate_misses: &misses,
        }),
    )
    .unwrap()
}

#[test]
fn folds_in_any_chunking_stop_at_the_same_index_with_the_same_interval() {
    let mass = OutsideMass::Proportional { total: 1.0 };
    let rule = rule(400_000);
    let all = outcomes(3, 400_000);
    let mut whole = fresh(&rule);
    let decision = advance(&mut whole, &rule, &all, 400_000, &mass);
    assert_eq!(decision, Some(Decision::Converged));
    for seed in 0..4 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut pieces = fresh(&rule);
        let mut decision = None;
        while decision.is_none() {
            let to = pieces.fold.indices + rng.random_range(1..5_000);
            decision = advance(&mut pieces, &rule, &all, to, &mass);
        }
        assert_eq!(decision, Some(Decision::Converged));
        assert_eq!(pieces.fold, whole.fold);
        assert_eq!(pieces.bounds(), whole.bounds());
    }
    // The stop: the interval's half-width within β of the estimate, the
    // exploring stratum's upper end included.
    let b = whole.bounds();
    assert!((b.high - b.low) / 2.0 <= 0.2 * whole.fold.estimate());
    assert!(whole.outside_upper().unwrap() < 0.2 * whole.fold.estimate() * 2.0);
}

#[test]
fn a_stratified_interval_holds_at_every_settlement_in_most_runs() {
    // μ = 0.9 · INSIDE/2 + OUTSIDE_RATE · 1 = 1e-3.
    let mu = 0.9 * INSIDE / 2.0 + OUTSIDE_RATE;
    let mass = OutsideMass::Proportional { total: 1.0 };
    let rule = rule(2_000_000);
    let runs = 100;
    let mut held = 0;
    let mut stopped = 0;
    for seed in 0..runs {
        let all = outcomes(100 + seed, 200_000);
        let mut fold = fresh(&rule);
        let mut ok = true;
        let mut decision = None;
        while decision.is_none() && fold.fold.indices < 200_000 {
            let to = next_settlement(fold.fold.indices).min(200_000);
            decision = advance(&mut fold, &rule, &all, to, &mass);
            let b = fold.bounds();
            ok &= b.low <= mu && mu <= b.high;
        }
        held += u32::from(ok);
        stopped += u32::from(decision == Some(Decision::Converged));
    }
    assert!(
        stopped >= 95,
        "{stopped} of {runs} stopped within 200,000 tests"
    );
    // Nominal 0.9 at every n at once: 82 of 100 is 2.7 standard deviations below.
    assert!(held >= 82, "held in {held} of {runs}");
}

#[test]
fn an_ndd_campaign_reads_one_sequence_and_stops_on_it() {
    let rule = StoppingRule {
        interval: crate::estimator::Interval::Anytime,
        ..StoppingRule::new(0.2, 10_000_000)
    };
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let all: Vec<_> = (0..3_000_000u64)
        .filter(|_| rng.random::<f64>() < 1e-3)
        .map(|i| (i, SparseOutcome::Event(1.0)))
        .collect();
    let mut fold = AnytimeFold::new(&rule, None, TermBounds::Single(1.0));
    let decision = fold.advance(&rule, 3_000_000, &all, None).unwrap();
    assert_eq!(decision, Some(Decision::Converged));
    let b = fold.bounds();
    let estimate = fold.fold.estimate();
    assert!((b.high - b.low) / 2.0 <= 0.2 * estimate && b.low < 1e-3 && 1e-3 < b.high);
    // Wald would have stopped near 68,000 tests; the sequence several times later.
    assert!(fold.fold.indices > 100_000, "{}", fold.fold.indices);
    assert_eq!(fold.outside_upper(), None);
}

#[test]
fn bad_input_is_refused_before_anything_is_folded() {
    let rule = rule(1_000);
    let mut fold = AnytimeFold::new(&rule, None, TermBounds::Single(1.0));
    let bad = [(5, SparseOutcome::Event(f64::NAN))];
    assert!(fold.advance(&rule, 10, &bad, None).is_err());
    let unordered = [(5, SparseOutcome::Invalid), (3, SparseOutcome::Invalid)];
    assert!(fold.advance(&rule, 10, &unordered, None).is_err());
    assert_eq!(fold.fold.indices, 0);
    // The budget: exhausted at max_tests without events.
    assert_eq!(
        fold.advance(&rule, 5_000, &[], None).unwrap(),
        Some(Decision::Exhausted)
    );
    assert_eq!(fold.fold.indices, 1_000);
}
