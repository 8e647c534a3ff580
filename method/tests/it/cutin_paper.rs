//! The cut-in case checked against the paper and against exact answers on
//! the grid. Tests that need the authors' table skip (and say why) when
//! `../shared/data` is absent; the built-in exposure always runs.

use crate::common::{library, median, paper_q, shared_table, vehicle};
use tslg_method::campaign::run_campaign;
use tslg_method::case::Case;
use tslg_method::cases::cutin::{CutIn, CutInExposureModel, CutInPreset};
use tslg_method::estimator::{Decision, StoppingRule};
use tslg_method::exact::{event_cells, event_probability, exact_report};
use tslg_method::library::SearchMethod;
use tslg_method::sampling::{NddDistribution, TestDistribution};

fn table_case() -> Option<CutIn> {
    let text = shared_table()?;
    Some(
        CutIn::from_table(&text, "spmd", CutInPreset::PaperCode)
            .expect("the shared table is valid")
            .0,
    )
}

#[test]
fn the_idm_library_on_the_authors_table_has_the_papers_184_cells() {
    let Some(case) = table_case() else { return };
    let lib = library(&case, "idm", SearchMethod::Exhaustive);
    assert_eq!(lib.size(), 184);
    assert_eq!(lib.total_scenarios(), 3420);
    // 2,863 cells of the table have positive exposure; only those are simulated.
    assert_eq!(lib.search.sm_evaluations, 2863);
    assert!((lib.mu_s - 8.662e-4).abs() < 1e-7, "μ_S = {}", lib.mu_s);
}

#[test]
fn the_switching_acc_on_the_authors_table_fails_at_their_rate() {
    // The authors' code gives the switching ACC P(A) = 9.417e-4 on their
    // table; it needs their first step (no 0.01 guard in the initial TTC)
    // and their speed update (the floor does not limit the acceleration).
    // Before both, this was 1.0609e-3.
    let Some(case) = table_case() else { return };
    let acc = vehicle("switching-acc");
    let p = event_probability(&case, &event_cells(&case, &acc));
    assert!((p - 9.417e-4).abs() < 5e-8, "P(A) = {p}");
}

#[test]
fn the_guard_stops_for_the_librarys_own_surrogate_under_the_uniform_spread() {
    // The authors' table leaves many of the IDM library's outside cells
    // without exposure, and the IDM fails in some of them. Those events
    // carry no mass; counted in the outside bound's k they kept U near
    // 0.62 and the guarded campaign never stopped (exhausted at 10⁶). Left
    // out, U falls as 1/m and the guard holds: near 1.8 × 10⁶ tests at
    // ε 0.1 and β 0.2, for any seed (the estimate is W from the start).
    let Some(case) = table_case() else { return };
    let lib = library(&case, "idm", SearchMethod::Exhaustive);
    let q = paper_q(&case, &lib, 0.1);
    let rule = StoppingRule {
        guard_outside: true,
        ..StoppingRule::new(0.2, 3_000_000)
    };
    let idm = vehicle("idm");
    let distribution = TestDistribution::library(q);
    for seed in [1, 2] {
        let r = run_campaign(&case, &idm, Some(&idm), &distribution, &rule, seed);
        assert_eq!(r.status, Decision::Converged, "seed {seed}: {r:?}");
        assert_eq!(r.outside_events, 0, "seed {seed}: {r:?}");
        let (upper, estimate) = (r.outside_upper.unwrap(), r.estimate);
        assert!(
            upper <= 0.2 * estimate,
            "seed {seed}: U {upper}, μ̂ {estimate}"
        );
    }
}

#[test]
fn the_paper_table_preset_gives_a_different_library() {
    let Some(case) = table_case() else { return };
    let text = shared_table().unwrap();
    let table_preset = CutIn::from_table(&text, "spmd", CutInPreset::PaperTable)
        .unwrap()
        .0;
    let code = library(&case, "idm", SearchMethod::Exhaustive);
    let table = library(&table_preset, "idm", SearchMethod::Exhaustive);
    assert_ne!(code.size(), table.size());
    assert!(table.size() > 0);
}

#[test]
fn the_builtin_exposure_fits_the_table_as_documented() {
    let Some(case) = table_case() else { return };
    let model = CutInExposureModel::default().mass_on(case.grid().clone());
    let tv = model.total_variation(case.exposure());
    // docs/models.md states TV 0.058.
    assert!((0.05..0.062).contains(&tv), "total variation {tv}");
}

fn check_multistart(case: &CutIn, surrogate: &str) {
    let exhaustive = library(case, surrogate, SearchMethod::Exhaustive);
    for seed in 0..5 {
        let ms = library(
            case,
            surrogate,
            SearchMethod::Multistart { starts: 50, seed },
        );
        let recall = ms.recall_against(&exhaustive);
        eprintln!(
            "{} {surrogate} seed {seed}: recall {recall:.4}, {} SM evaluations vs {} exhaustive",
            case.exposure_name(),
            ms.search.sm_evaluations,
            exhaustive.search.sm_evaluations
        );
        assert!(recall >= 0.95, "seed {seed}: recall {recall}");
        assert!(ms.search.sm_evaluations < exhaustive.search.sm_evaluations);
    }
}

#[test]
fn multistart_recovers_the_exhaustive_library_with_fewer_evaluations() {
    let builtin = CutIn::builtin(CutInPreset::PaperCode);
    check_multistart(&builtin, "idm");
    check_multistart(&builtin, "fvdm");
    if let Some(table) = table_case() {
        check_multistart(&table, "idm");
        check_multistart(&table, "fvdm");
    }
}

struct Coverage {
    covered: u64,
    coverage: f64,
    median_tests: f64,
    analytic_tests: f64,
}

/// `runs` seeded library campaigns of `vut` with a library of `surrogate`.
fn coverage(case: &CutIn, surrogate: &str, vut: &str, runs: u64) -> Coverage {
    let lib = library(case, surrogate, SearchMethod::Exhaustive);
    let q = paper_q(case, &lib, 0.1);
    let rule = StoppingRule::new(0.2, 1_000_000);
    let exact = exact_report(case, &vehicle(vut), &q, rule.beta, rule.confidence);
    let distribution = TestDistribution::library(q);
    let mut covered = 0;
    let mut tests = Vec::new();
    for seed in 0..runs {
        let r = run_campaign(
            case,
            &vehicle(vut),
            Some(&vehicle(surrogate)),
            &distribution,
            &rule,
            seed,
        );
        assert_eq!(
            r.status,
            Decision::Converged,
            "seed {seed} did not converge"
        );
        covered += u64::from(r.covers(exact.probability));
        tests.push(r.tests);
    }
    let c = Coverage {
        covered,
        coverage: covered as f64 / runs as f64,
        median_tests: median(&mut tests),
        analytic_tests: exact.library_tests,
    };
    eprintln!(
        "{} library of {surrogate} testing {vut}: P(A) = {:.4e}, coverage {:.3}, median tests {}, analytic {:.0}",
        case.exposure_name(),
        exact.probability,
        c.coverage,
        c.median_tests,
        c.analytic_tests
    );
    c
}

#[test]
fn fvdm_library_testing_idm_covers_the_exact_answer() {
    let mut cases = vec![CutIn::builtin(CutInPreset::PaperCode)];
    cases.extend(table_case());
    for case in &cases {
        // 200 seeds, floor 170: P(Bin(200, 0.90) < 170) ≤ 0.01, and
        // coverage 0.80 fails with probability 0.957.
        let check = tslg_testkit::CoverageCheck::new(200, 0.9, 0.01);
        let c = coverage(case, "fvdm", "idm", check.runs);
        check.assert_covers(c.covered, case.exposure_name());
        let ratio = c.median_tests / c.analytic_tests;
        assert!((0.5..=2.0).contains(&ratio), "median/analytic = {ratio}");
    }
}

/// The surrogate (IDM) misses much of FVDM's failure region, so the plain
/// stopping rule is confidently wrong: the known weakness that the guard
/// and adaptive campaigns address (docs/statistics.md: coverage 0.120 on
/// the built-in exposure, 0.145 on the authors' table). Held below half
/// the nominal 0.9: a change that made plain library campaigns cover here
/// would also change what the docs and the warnings say of them.
#[test]
fn reverse_pairing_idm_library_testing_fvdm_undercovers() {
    let mut cases = vec![CutIn::builtin(CutInPreset::PaperCode)];
    cases.extend(table_case());
    for case in &cases {
        let c = coverage(case, "idm", "fvdm", 200);
        assert!(
            c.coverage < 0.45,
            "{}: coverage {}",
            case.exposure_name(),
            c.coverage
        );
    }
}

#[test]
fn library_and_ndd_campaigns_agree() {
    let case = CutIn::builtin(CutInPreset::PaperCode);
    let lib = library(&case, "fvdm", SearchMethod::Exhaustive);
    let rule = StoppingRule::new(0.2, 2_000_000);
    let idm = vehicle("idm");
    let by_library = run_campaign(
        &case,
        &idm,
        Some(&vehicle("fvdm")),
        &TestDistribution::library(paper_q(&case, &lib, 0.1)),
        &rule,
        7,
    );
    let by_ndd = run_campaign(
        &case,
        &idm,
        None,
        &TestDistribution::Ndd(NddDistribution::new(case.exposure())),
        &rule,
        7,
    );
    eprintln!("library {by_library:?}\nndd {by_ndd:?}");
    assert_eq!(by_ndd.status, Decision::Converged);
    assert!(by_ndd.tests > 20 * by_library.tests);
    assert!(by_library.ci_low <= by_ndd.ci_high && by_ndd.ci_low <= by_library.ci_high);
}

/// Exact coverage, at a fixed number of tests `n`, of the normal interval
/// of a campaign whose every test is `c` with probability `1 − ε` (a
/// library test with the event) and 0 otherwise (an exploring test without
/// one): `μ̂ = cK/n` with `K ~ Binomial(n, 1 − ε)`, summed over `K`.
fn split_coverage(n: u64, epsilon: f64, z: f64, truth: f64, c: f64) -> f64 {
    let nf = n as f64;
    (0..=n)
        .map(|k| {
            let kf = k as f64;
            let probability = statrs::function::factorial::binomial(n, k)
                * (1.0 - epsilon).powi(k as i32)
                * epsilon.powi((n - k) as i32);
            let mean = c * kf / nf;
            let variance = ((c * c * kf - (c * kf).powi(2) / nf) / (nf - 1.0)).max(0.0);
            let half = z * (variance / nf).sqrt();
            if (mean - half..=mean + half).contains(&truth) {
                probability
            } else {
                0.0
            }
        })
        .sum()
}

#[test]
fn the_epsilon_greedy_split_makes_a_matched_pairs_coverage_ride_a_lattice() {
    // Issue 21 measured, from outside the project, the exact coverage of
    // the IDM testing its own library on the authors' table: 0.867 at
    // n = 20, 0.919 at 25, 0.790 at 30, 0.904 at 40, 0.862 at 100 (ε 0.1,
    // the default) and 0.8525 at 200 with ε 0.05 (the reproduction's). The
    // IDM fails in every library cell (weight W/(1 − ε)) and nowhere outside
    // with exposure, so the only noise is how many of the n tests drew from
    // the library: Binomial(n, 1 − ε).
    let Some(case) = table_case() else { return };
    let lib = library(&case, "idm", SearchMethod::Exhaustive);
    let idm = vehicle("idm");
    let z = StoppingRule::new(0.2, 1).z();
    let measured = [
        (0.1, 20, 0.867),
        (0.1, 25, 0.919),
        (0.1, 30, 0.790),
        (0.1, 40, 0.904),
        (0.1, 100, 0.862),
        (0.05, 200, 0.8525),
    ];
    for (epsilon, n, coverage) in measured {
        let q = paper_q(&case, &lib, epsilon);
        let truth = exact_report(&case, &idm, &q, 0.2, 0.9).probability;
        assert!(
            (truth - lib.w).abs() < 1e-12 * lib.w,
            "{truth} against W {}",
            lib.w
        );
        let ours = split_coverage(n, epsilon, z, truth, lib.w / (1.0 - epsilon));
        assert!(
            (ours - coverage).abs() < 6e-4,
            "n {n}: {ours} against {coverage}"
        );
        // The product's campaigns stopped at n (β too small to converge
        // before it) cover as the enumeration says, within 3 standard errors over
        // 1,000 seeds.
        let distribution = TestDistribution::library(q);
        let rule = StoppingRule {
            n_min: n,
            ..StoppingRule::new(1e-4, n)
        };
        let seeds = 1000;
        let covered = (0..seeds)
            .filter(|&seed| {
                let r = run_campaign(&case, &idm, Some(&idm), &distribution, &rule, seed);
                // (Converged with rₙ = 0 when all n drew from the library.)
                assert_eq!(r.tests, n);
                r.covers(truth)
            })
            .count();
        let empirical = covered as f64 / seeds as f64;
        let se = (ours * (1.0 - ours) / seeds as f64).sqrt();
        assert!(
            (empirical - ours).abs() < 3.0 * se,
            "n {n}: {empirical} over {seeds} seeds against the exact {ours}"
        );
    }
}
