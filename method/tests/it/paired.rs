//! Paired regression campaigns against the exact answers on the grid
//! cases: two builds of a vehicle (today's and yesterday's) on the same
//! tests, under the NDD and under a library, on cut-in and on
//! highway-exit's coarse grid. The exact difference of their P(A) and the
//! exact variances of the paired and the independent estimators come from
//! enumerating the grid under the sampling distribution q(x).

use crate::common::{library, paper_q, vehicle};
use rayon::prelude::*;
use tslg_method::case::Case;
use tslg_method::cases::cutin::{CutIn, CutInPreset};
use tslg_method::cases::highway::{HighwayExit, HighwayPreset};
use tslg_method::estimator::StoppingRule;
use tslg_method::library::SearchMethod;
use tslg_method::paired::{run_paired_outcomes, PairedResult, PairedStop};
use tslg_method::sampling::TestDistribution;
use tslg_method::vehicle::VehicleModel;

/// Whether each vehicle fails in each cell of the grid: the paired
/// campaigns below draw thousands of tests per cell, so each cell is
/// simulated once.
struct Outcomes {
    a: Vec<bool>,
    b: Vec<bool>,
}

impl Outcomes {
    fn of<C: Case + Sync>(case: &C, a: &C::Vehicle, b: &C::Vehicle) -> Self
    where
        C::Vehicle: Sync,
    {
        let cells = case.grid().len();
        let run = |v: &C::Vehicle| {
            (0..cells)
                .into_par_iter()
                .map(|c| case.is_event(v, c))
                .collect()
        };
        Self {
            a: run(a),
            b: run(b),
        }
    }
}

/// Exact `(Δ, Var a, Var b, Var d)` of one test drawn from `q(x)`, and
/// the exposure of the cells where the vehicles differ and `q` is 0
/// (which no paired campaign can see).
fn exact(
    exposure: &dyn Fn(usize) -> f64,
    q: &dyn Fn(usize) -> f64,
    o: &Outcomes,
) -> ([f64; 4], f64) {
    let (mut mu, mut sq, mut unseen) = ([0.0; 3], [0.0; 3], 0.0);
    for cell in 0..o.a.len() {
        let p = exposure(cell);
        let (ya, yb) = (o.a[cell] as u8 as f64, o.b[cell] as u8 as f64);
        if p == 0.0 || (ya == 0.0 && yb == 0.0) {
            continue;
        }
        let qx = q(cell);
        if qx == 0.0 {
            unseen += p;
            continue;
        }
        for (k, y) in [ya, yb, ya - yb].into_iter().enumerate() {
            mu[k] += p * y;
            sq[k] += p * p / qx * y * y;
        }
    }
    (
        [
            mu[2],
            sq[0] - mu[0] * mu[0],
            sq[1] - mu[1] * mu[1],
            sq[2] - mu[2] * mu[2],
        ],
        unseen,
    )
}

fn paired_run(
    distribution: &TestDistribution,
    o: &Outcomes,
    rule: &StoppingRule,
    seed: u64,
) -> PairedResult {
    let outcomes = |from: u64, to: u64| {
        let mut out = Vec::new();
        distribution.draw_each(seed, from..to, |i, draw| {
            let (ya, yb) = (o.a[draw.cell], o.b[draw.cell]);
            if ya || yb {
                let w = |y: bool| if y { draw.weight } else { 0.0 };
                out.push((i, w(ya), w(yb)));
            }
        });
        out
    };
    run_paired_outcomes(&outcomes, rule)
}

/// The paired coverage tests' plan: 200 seeds, floor 170, the largest k
/// with P(Bin(200, 0.90) < k) ≤ 0.01; an interval covering 0.80 fails with
/// probability 0.957 (`tslg_testkit::CoverageCheck`).
static COVERAGE: std::sync::LazyLock<tslg_testkit::CoverageCheck> =
    std::sync::LazyLock::new(|| tslg_testkit::CoverageCheck::new(200, 0.9, 0.01));

/// What COVERAGE's paired campaigns of `a` against `b` give.
struct Study {
    delta: f64,
    covered: u64,
    coverage: f64,
    exact_gain: f64,
    measured_gain: f64,
    median_tests: u64,
}

fn study(
    exposure: &dyn Fn(usize) -> f64,
    distribution: &TestDistribution,
    q: &dyn Fn(usize) -> f64,
    o: &Outcomes,
    beta: f64,
) -> Study {
    let ([delta, va, vb, vd], unseen) = exact(exposure, q, o);
    assert_eq!(unseen, 0.0, "every difference can be drawn");
    let rule = StoppingRule::new(beta, 10_000_000);
    let runs: Vec<PairedResult> = (0..COVERAGE.runs)
        .into_par_iter()
        .map(|seed| paired_run(distribution, o, &rule, seed))
        .collect();
    assert!(runs.iter().all(|r| r.stop != PairedStop::Exhausted));
    let covered = runs
        .iter()
        .filter(|r| r.difference.1 <= delta && delta <= r.difference.2)
        .count();
    let mut gains: Vec<f64> = runs
        .iter()
        .filter_map(|r| r.independent_tests.map(|t| t / r.tests as f64))
        .collect();
    gains.sort_by(f64::total_cmp);
    let mut tests: Vec<u64> = runs.iter().map(|r| r.tests).collect();
    tests.sort_unstable();
    let s = Study {
        delta,
        covered: covered as u64,
        coverage: covered as f64 / runs.len() as f64,
        exact_gain: (va + vb) / vd,
        measured_gain: gains[gains.len() / 2],
        median_tests: tests[tests.len() / 2],
    };
    eprintln!(
        "Δ = {:.4e}: coverage {:.3}, gain exact {:.2} measured {:.2}, median tests {}",
        s.delta, s.coverage, s.exact_gain, s.measured_gain, s.median_tests
    );
    s
}

#[test]
fn paired_intervals_cover_the_exact_difference_and_need_far_fewer_tests() {
    let case = CutIn::builtin(CutInPreset::PaperCode);
    // A regression: today's IDM keeps a jam distance of 0.5 m instead of
    // 2 m and fails on 5 more of the grid's cells.
    let today: VehicleModel =
        serde_json::from_value(serde_json::json!({"model": "idm", "s0": 0.5})).unwrap();
    let yesterday = vehicle("idm");
    let lib = library(&case, "idm", SearchMethod::Exhaustive);
    let q = paper_q(&case, &lib, 0.1);
    let qf = |cell| q.q(cell);
    let distribution = TestDistribution::library(q.clone());
    let p = |cell| case.exposure().p(cell);
    let regression = Outcomes::of(&case, &today, &yesterday);
    let s = study(&p, &distribution, &qf, &regression, 0.2);
    COVERAGE.assert_covers(s.covered, &format!("Δ = {:e}", s.delta));
    // Under the library both rates are known almost without variance (it
    // samples their failures): the difference's variance is that of the
    // few discordant cells it explores, and pairing gains nothing.
    assert!((s.exact_gain - 1.0).abs() < 0.05, "{}", s.exact_gain);
    // Under the NDD the rates' variances are their P(A) and the paired
    // difference's the discordant cells' mass: the regression is measured
    // with (Var a + Var b)/Var d times fewer tests than two campaigns.
    let ndd = TestDistribution::Ndd(tslg_method::sampling::NddDistribution::new(case.exposure()));
    let s = study(&p, &ndd, &p, &regression, 0.2);
    COVERAGE.assert_covers(s.covered, &format!("Δ = {:e}", s.delta));
    assert!(s.exact_gain > 10.0, "{}", s.exact_gain);
    let agree = |s: &Study| (s.measured_gain / s.exact_gain - 1.0).abs() < 0.3;
    assert!(agree(&s), "{} against {}", s.measured_gain, s.exact_gain);
    // FVDM against IDM: they differ on most of the FVDM's failures.
    let fvdm_idm = Outcomes::of(&case, &vehicle("fvdm"), &vehicle("idm"));
    let s = study(&p, &ndd, &p, &fvdm_idm, 0.2);
    COVERAGE.assert_covers(s.covered, &format!("Δ = {:e}", s.delta));
    assert!(agree(&s), "{} against {}", s.measured_gain, s.exact_gain);
}

#[test]
fn paired_intervals_cover_the_exact_difference_on_highway_exit() {
    let case = HighwayExit::builtin(HighwayPreset::Coarse);
    // A regression: today's MOBIL accepts a lane change that makes the
    // follower brake at up to 3.5 m/s² (yesterday's: 4).
    let vehicle = |spec| serde_json::from_value(spec).unwrap();
    let today = vehicle(serde_json::json!({"model": "mobil", "b_safe": 3.5}));
    let yesterday = vehicle(serde_json::json!({"model": "mobil"}));
    let o = Outcomes::of(&case, &today, &yesterday);
    let p = |cell| case.exposure().p(cell);
    let ndd = TestDistribution::Ndd(tslg_method::sampling::NddDistribution::new(case.exposure()));
    let s = study(&p, &ndd, &p, &o, 0.2);
    assert!(s.delta != 0.0, "the two builds differ");
    COVERAGE.assert_covers(s.covered, &format!("Δ = {:e}", s.delta));
    assert!(
        (s.measured_gain / s.exact_gain - 1.0).abs() < 0.3,
        "{} against {}",
        s.measured_gain,
        s.exact_gain
    );
}

#[test]
fn the_same_vehicle_twice_differs_by_nothing_and_is_never_called_different() {
    let case = CutIn::builtin(CutInPreset::PaperCode);
    let lib = library(&case, "idm", SearchMethod::Exhaustive);
    let distribution = TestDistribution::library(paper_q(&case, &lib, 0.1));
    let a = vehicle("fvdm");
    let o = Outcomes::of(&case, &a, &a);
    let rule = StoppingRule::new(0.2, 100_000);
    for seed in 0..20 {
        let r = paired_run(&distribution, &o, &rule, seed);
        assert_eq!(r.stop, PairedStop::Exhausted);
        assert_eq!(r.difference, (0.0, 0.0, 0.0));
        assert_eq!(r.events.2, 0);
        assert_eq!(r.rate_a, r.rate_b);
    }
}
