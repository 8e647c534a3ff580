//! Sampling and estimation checked against exact answers on the grid.

use crate::common::{library, paper_q, vehicle};
use std::collections::HashMap;
use tslg_method::campaign::run_campaign;
use tslg_method::case::Case;
use tslg_method::cases::cutin::{CutIn, CutInPreset};
use tslg_method::estimator::{z_for_confidence, ImportanceEstimator, StoppingRule};
use tslg_method::exact::{
    event_cells, event_probability, library_variance, stratified_library_variance,
    stratum_variances,
};
use tslg_method::library::{Library, SearchMethod};
use tslg_method::prefix::PrefixFold;
use tslg_method::sampling::{
    LibraryDistribution, NddDistribution, OutsideSpread, Split, TestDistribution,
};

fn setup() -> (CutIn, Library) {
    let case = CutIn::builtin(CutInPreset::PaperCode);
    let lib = library(&case, "idm", SearchMethod::Exhaustive);
    (case, lib)
}

#[test]
fn q_is_a_distribution_with_epsilon_outside_the_library() {
    let (case, lib) = setup();
    for spread in [OutsideSpread::Uniform, OutsideSpread::Ndd] {
        let q =
            LibraryDistribution::new(&lib, case.exposure(), 0.1, spread, Split::Random).unwrap();
        let total: f64 = (0..case.grid().len()).map(|c| q.q(c)).sum();
        let outside: f64 = (0..case.grid().len())
            .filter(|&c| !q.contains(c))
            .map(|c| q.q(c))
            .sum();
        assert!((total - 1.0).abs() < 1e-12, "{spread:?}: Σq = {total}");
        assert!(
            (outside - 0.1).abs() < 1e-12,
            "{spread:?}: outside mass {outside}"
        );
    }
    // Uniform: every outside cell gets ε/(N − N(Φ)).
    let q = paper_q(&case, &lib, 0.1);
    let outside_cell = (0..case.grid().len()).find(|&c| !q.contains(c)).unwrap();
    assert_eq!(q.q(outside_cell), 0.1 / (3420 - lib.size()) as f64);
}

/// Pearson's χ² of observed draws against `q`, over the cells with q > 0.
fn chi_square(
    counts: &HashMap<usize, u64>,
    q: impl Fn(usize) -> f64,
    cells: usize,
    draws: u64,
) -> (f64, usize) {
    let mut stat = 0.0;
    let mut df = 0;
    for c in 0..cells {
        let expected = q(c) * draws as f64;
        if expected > 0.0 {
            let observed = *counts.get(&c).unwrap_or(&0) as f64;
            stat += (observed - expected).powi(2) / expected;
            df += 1;
        }
    }
    (stat, df - 1)
}

#[test]
fn draws_follow_q_exactly() {
    let (case, lib) = setup();
    let draws = 400_000u64;
    for (spread, split) in [
        (OutsideSpread::Uniform, Split::Random),
        (OutsideSpread::Ndd, Split::Random),
        (OutsideSpread::Uniform, Split::Stratified),
    ] {
        let q = LibraryDistribution::new(&lib, case.exposure(), 0.3, spread, split).unwrap();
        let mut counts = HashMap::new();
        for i in 0..draws {
            *counts.entry(q.draw(11, i).cell).or_insert(0u64) += 1;
        }
        let (stat, df) = chi_square(&counts, |c| q.q(c), case.grid().len(), draws);
        // χ² with df degrees of freedom has mean df and sd √(2df); 5 sd is far in the tail.
        let bound = df as f64 + 5.0 * (2.0 * df as f64).sqrt();
        assert!(stat < bound, "{spread:?}: χ² = {stat:.0} with {df} df");
        // And a distribution that is wrong by a little must fail the same test.
        let (wrong, _) = chi_square(
            &counts,
            |c| {
                if q.contains(c) {
                    q.q(c) * 0.98
                } else {
                    q.q(c) * 1.18
                }
            },
            case.grid().len(),
            draws,
        );
        assert!(
            wrong > bound,
            "{spread:?}: the test cannot tell q from a perturbed q ({wrong:.0})"
        );
    }
}

#[test]
fn uniform_outside_sampling_picks_the_kth_outside_cell() {
    let (case, lib) = setup();
    let q = paper_q(&case, &lib, 0.999);
    let outside: Vec<usize> = (0..case.grid().len()).filter(|&c| !q.contains(c)).collect();
    let mut seen = std::collections::HashSet::new();
    for i in 0..200_000 {
        let cell = q.draw(3, i).cell;
        if !q.contains(cell) {
            seen.insert(cell);
        }
    }
    // Every outside cell is reachable and no library cell is drawn as "outside".
    assert_eq!(seen.len(), outside.len());
}

#[test]
fn test_i_depends_on_seed_and_index_alone() {
    let (case, lib) = setup();
    let q = paper_q(&case, &lib, 0.1);
    let forward: Vec<_> = (0..1000).map(|i| q.draw(5, i)).collect();
    let backward: Vec<_> = (0..1000).rev().map(|i| q.draw(5, i)).collect();
    assert!(forward.iter().eq(backward.iter().rev()));
    let other_seed: Vec<_> = (0..1000).map(|i| q.draw(6, i)).collect();
    assert_ne!(forward, other_seed);
    // Value stability: this exact stream must not change between releases,
    // or recorded campaigns could not be reproduced.
    let first: Vec<usize> = forward.iter().take(5).map(|d| d.cell).collect();
    assert_eq!(first, STABLE_FIRST_CELLS);
}

/// The first five cells of seed 5 with the built-in IDM library, ε = 0.1.
/// The stream is pinned for a given library; the library itself changed on
/// 2026-11-25 (286 cells, was 287) when the paper-code preset took the
/// authors' speed update (`SpeedBound::ClipsSpeed`), and with it the cells.
const STABLE_FIRST_CELLS: [usize; 5] = [1979, 624, 1827, 1830, 930];

#[test]
fn the_estimator_is_unbiased_and_its_variance_matches_the_analytic_one() {
    let (case, lib) = setup();
    let vut = vehicle("fvdm");
    let q = paper_q(&case, &lib, 0.1);
    let events = event_cells(&case, &vut);
    let is_event: std::collections::HashSet<usize> = events.iter().copied().collect();
    let mu = event_probability(&case, &events);
    let sigma2 = library_variance(&case, &events, &q);
    // Exact expectations of w·y under q by enumeration: E[w y] = μ.
    let enumerated: f64 = events
        .iter()
        .map(|&c| q.q(c) * case.exposure().p(c) / q.q(c))
        .sum();
    assert!((enumerated - mu).abs() < 1e-15);
    // Across seeds, the mean of independent estimates is within 4 standard errors of μ,
    // and the pooled sample variance is near σ².
    let mut means = Vec::new();
    let mut variances = Vec::new();
    for seed in 0..40 {
        let mut e = ImportanceEstimator::default();
        for i in 0..20_000 {
            let d = q.draw(seed, i);
            e.push(d.weight, is_event.contains(&d.cell));
        }
        means.push(e.estimate());
        variances.push(e.variance());
    }
    let grand = means.iter().sum::<f64>() / means.len() as f64;
    let se = (sigma2 / (20_000.0 * 40.0)).sqrt();
    assert!(
        (grand - mu).abs() < 4.0 * se,
        "mean {grand:e} vs μ {mu:e} (se {se:e})"
    );
    let pooled = variances.iter().sum::<f64>() / variances.len() as f64;
    assert!(
        (pooled / sigma2 - 1.0).abs() < 0.35,
        "pooled variance {pooled:e} vs σ² {sigma2:e}"
    );
}

#[test]
fn campaigns_do_not_depend_on_the_number_of_threads() {
    let (case, lib) = setup();
    let q = paper_q(&case, &lib, 0.1);
    let dist = TestDistribution::library(q);
    let rule = StoppingRule::new(0.2, 100_000);
    let vut = vehicle("acc-aeb");
    let many = run_campaign(&case, &vut, None, &dist, &rule, 42);
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| run_campaign(&case, &vut, None, &dist, &rule, 42));
    assert_eq!(many, one);
    let ndd = TestDistribution::Ndd(NddDistribution::new(case.exposure()));
    let rule = StoppingRule {
        max_tests: 5_000,
        ..rule
    };
    let exhausted = run_campaign(&case, &vut, None, &ndd, &rule, 1);
    assert_eq!(exhausted.tests, 5_000);
    assert!((z_for_confidence(0.9) - rule.z()).abs() < 1e-15);
}

/// The library's distribution at ε 0.1 under the stratified split.
fn stratified_q(case: &CutIn, lib: &Library) -> LibraryDistribution {
    LibraryDistribution::new(
        lib,
        case.exposure(),
        0.1,
        OutsideSpread::Uniform,
        Split::Stratified,
    )
    .unwrap()
}

#[test]
fn the_stratified_estimate_is_unbiased_with_the_within_strata_variance() {
    // The IDM (the library's own surrogate: the split between the strata
    // is nearly all of the mixture's variance) and the FVDM (part of its
    // failure mass outside the library, where the weights are large).
    let (case, lib) = setup();
    let q = stratified_q(&case, &lib);
    let (n, seeds) = (2_000u64, 400u64);
    for (name, gain) in [("idm", 0.5), ("fvdm", 0.97)] {
        let events = event_cells(&case, &vehicle(name));
        let is_event: std::collections::HashSet<usize> = events.iter().copied().collect();
        let mu = event_probability(&case, &events);
        let within = stratified_library_variance(&case, &events, &q);
        let mixture = library_variance(&case, &events, &q);
        assert!(within < gain * mixture, "{name}: {within:e} vs {mixture:e}");
        let estimates: Vec<f64> = (0..seeds)
            .map(|seed| {
                let mut fold = PrefixFold::with_strata(q.strata());
                for i in 0..n {
                    let d = q.draw(seed, i);
                    fold.push(d.weight, is_event.contains(&d.cell), q.explores(seed, i));
                }
                assert_eq!(fold.outside.tests, n / 10);
                fold.estimate()
            })
            .collect();
        let mean = estimates.iter().sum::<f64>() / seeds as f64;
        let var = estimates.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (seeds - 1) as f64;
        let se = (within / n as f64 / seeds as f64).sqrt();
        assert!(
            (mean - mu).abs() < 4.0 * se,
            "{name}: mean {mean:e} vs μ {mu:e} (se {se:e})"
        );
        // The spread of the estimates across seeds is the exact
        // within-strata variance (a sample variance of 400 has a relative
        // s.e. near 0.1 for normal data; these are heavier-tailed).
        let ratio = var / (within / n as f64);
        assert!(
            (0.7..1.4).contains(&ratio),
            "{name}: variance ratio {ratio}"
        );
    }
}

#[test]
fn the_pooled_variance_covers_where_the_within_strata_one_collapses() {
    // The IDM's own library on the built-in exposure leaves 1.3 % of its
    // failure mass outside, where an exploring test rarely meets it. Until
    // one does, the exploring stratum has no variance and the library
    // stratum almost none (its events share one weight): the within-strata
    // interval is nearly a point below P(A). The pooled variance keeps the
    // between-strata part and covers (docs/statistics.md, "Strata").
    let (case, lib) = setup();
    let q = stratified_q(&case, &lib);
    let events = event_cells(&case, &vehicle("idm"));
    let is_event: std::collections::HashSet<usize> = events.iter().copied().collect();
    let mu = event_probability(&case, &events);
    let z = z_for_confidence(0.9);
    let (n, seeds) = (100u64, 1_000u64);
    let (mut pooled, mut within) = (0, 0);
    for seed in 0..seeds {
        let mut fold = PrefixFold::with_strata(q.strata());
        // Per stratum: tests, Σx, Σx² of the stratum's own terms.
        let mut strata = [(0.0f64, 0.0f64, 0.0f64); 2];
        for i in 0..n {
            let d = q.draw(seed, i);
            let event = is_event.contains(&d.cell);
            let explores = q.explores(seed, i);
            fold.push(d.weight, event, explores);
            let x = if event { d.weight } else { 0.0 };
            let (share, h) = if explores { (0.1, 1) } else { (0.9, 0) };
            let own = share * x;
            strata[h].0 += 1.0;
            strata[h].1 += own;
            strata[h].2 += own * own;
        }
        let (low, high) = fold.interval(z);
        pooled += u64::from(low <= mu && mu <= high);
        // Var(μ̂) = Σ_h s_h²/n_h with each stratum's own sample variance.
        let var: f64 = strata
            .iter()
            .map(|&(m, s1, s2)| ((s2 - s1 * s1 / m) / (m - 1.0)).max(0.0) / m)
            .sum();
        let half = z * var.sqrt();
        within += u64::from((fold.estimate() - mu).abs() <= half);
    }
    let (pooled, within) = (pooled as f64 / seeds as f64, within as f64 / seeds as f64);
    assert!(pooled >= 0.95, "pooled coverage {pooled}");
    assert!(within < 0.6, "within-strata coverage {within}");
    eprintln!("coverage at n = {n}: pooled {pooled}, within strata {within}");
}

/// The library's distribution at ε 0.1, spread by exposure outside it
/// (the spread of guarded and anytime campaigns), stratified.
fn ndd_spread_q(case: &CutIn, lib: &Library) -> LibraryDistribution {
    LibraryDistribution::new(
        lib,
        case.exposure(),
        0.1,
        OutsideSpread::Ndd,
        Split::Stratified,
    )
    .unwrap()
}

/// The allocation (issue 49): a switch leaves every test before it as it
/// was, and from it on nearly every test explores, with the weight `P/q`
/// of the nominal ε, so each stratum's own terms keep their meaning.
#[test]
fn a_switch_keeps_the_tests_before_it_and_explores_nearly_every_test_after() {
    let (case, lib) = setup();
    let q = ndd_spread_q(&case, &lib);
    let before: Vec<_> = (0..3000)
        .map(|i| (q.draw(7, i), q.explores(7, i)))
        .collect();
    assert!(q.set_explore_from(Some(1000)));
    for (i, (draw, explores)) in before.iter().enumerate().take(1000) {
        let i = i as u64;
        assert_eq!(
            (q.draw(7, i), q.explores(7, i)),
            (*draw, *explores),
            "test {i}"
        );
    }
    let exploring = (1000..3000).filter(|&i| q.explores(7, i)).count();
    assert_eq!(
        exploring, 1900,
        "⌊2000 · 0.95⌋ tests explore after the switch"
    );
    for i in 1000..3000 {
        let draw = q.draw(7, i);
        assert_eq!(!q.contains(draw.cell), q.explores(7, i), "test {i}");
        // The weight is P/q of the nominal mixture, whichever stratum drew it.
        assert_eq!(
            draw.weight.to_bits(),
            (case.exposure().p(draw.cell) / q.q(draw.cell)).to_bits()
        );
    }
    // A random split has no switch to set.
    let random = LibraryDistribution::new(
        &lib,
        case.exposure(),
        0.1,
        OutsideSpread::Ndd,
        Split::Random,
    )
    .unwrap();
    assert!(!random.set_explore_from(Some(5)));
    assert_eq!(random.explore_from(), None);
}

/// The guard's allocation (issue 49) keeps the estimate unbiased: after a
/// switch nearly every test explores, the strata are far from
/// proportional, and each is still weighted by its own mass. The spread of
/// the estimates across seeds is the exact `(1 − ε)² Var_in/n_in +
/// ε² Var_out/n_out` (enumerated on the grid), and the within-strata
/// half-width a guarded campaign reads estimates it. The pooled one,
/// conservative under the proportional split, is far off: for the IDM it
/// is nearly all between-strata variance.
#[test]
fn after_a_switch_the_estimate_is_unbiased_and_the_within_strata_variance_is_exact() {
    let (case, lib) = setup();
    let (n, switch, seeds) = (4_000u64, 1_000u64, 400u64);
    let z = z_for_confidence(0.9);
    for name in ["idm", "fvdm"] {
        let q = ndd_spread_q(&case, &lib);
        assert!(q.set_explore_from(Some(switch)));
        let events = event_cells(&case, &vehicle(name));
        let is_event: std::collections::HashSet<usize> = events.iter().copied().collect();
        let mu = event_probability(&case, &events);
        let [v_in, v_out] = stratum_variances(&case, &events, &q);
        let n_out = (0..n).filter(|&i| q.explores(0, i)).count() as f64;
        let n_in = n as f64 - n_out;
        assert_eq!(n_out, 100.0 + 2850.0, "⌊1000 ε⌋ + ⌊3000 · 0.95⌋");
        let exact = 0.81 * v_in / n_in + 0.01 * v_out / n_out;
        let (mut estimates, mut within, mut pooled) = (Vec::new(), 0.0, 0.0);
        for seed in 0..seeds {
            let mut fold = PrefixFold {
                within_strata: true,
                ..PrefixFold::with_strata(q.strata())
            };
            for i in 0..n {
                let d = q.draw(seed, i);
                fold.push(d.weight, is_event.contains(&d.cell), q.explores(seed, i));
            }
            estimates.push(fold.estimate());
            within += (fold.half_width(z) / z).powi(2) / seeds as f64;
            pooled += (fold.estimator.half_width(z) / z).powi(2) / seeds as f64;
        }
        let mean = estimates.iter().sum::<f64>() / seeds as f64;
        let var = estimates.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (seeds - 1) as f64;
        let se = (exact / seeds as f64).sqrt();
        assert!(
            (mean - mu).abs() < 4.0 * se,
            "{name}: mean {mean:e} vs μ {mu:e} (se {se:e})"
        );
        for (what, ratio) in [
            ("across seeds", var / exact),
            ("within strata", within / exact),
        ] {
            assert!(
                (0.7..1.4).contains(&ratio),
                "{name}: {what} / exact variance = {ratio}"
            );
        }
        eprintln!("{name}: pooled / exact variance {:.3}", pooled / exact);
        if name == "idm" {
            // Nearly all of the pooled variance is between the strata: read
            // on it, the campaign would wait for nothing.
            assert!(
                pooled > 10.0 * exact,
                "idm: pooled {pooled:e} vs exact {exact:e}"
            );
        }
    }
}
