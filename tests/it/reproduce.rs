//! `tslg reproduce`: the paper's cases through a local service, its CSV
//! checked against exact answers computed here.

use std::collections::HashMap;
use std::process::Command;
use tslg_method::cases::open_case;
use tslg_method::estimator::z_for_confidence;
use tslg_method::exact::expected_ndd_tests;
use tslg_method::library::SearchMethod;
use tslg_method::registry::{BuildRequest, ExposureSource, LibrarySearch};

/// The CSV as one map per line, keyed by the header.
fn records(csv: &str) -> Vec<HashMap<String, String>> {
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().expect("a header").split(',').collect();
    lines
        .map(|line| {
            let fields: Vec<&str> = line.split(',').collect();
            assert_eq!(fields.len(), header.len(), "{line}");
            header
                .iter()
                .zip(fields)
                .map(|(h, f)| (h.to_string(), f.to_string()))
                .collect()
        })
        .collect()
}

fn number(record: &HashMap<String, String>, key: &str) -> f64 {
    record[key]
        .parse()
        .unwrap_or_else(|_| panic!("{key} = `{}` is not a number", record[key]))
}

#[test]
fn reproduce_runs_the_cases_and_tables_them_beside_the_paper() {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_tslg"))
        .args([
            "reproduce",
            "--quick",
            "--cases",
            "cut-in,car-following",
            "--replicates",
            "2",
            "--ndd-budget",
            "200000",
            "--out",
            dir.path().to_str().unwrap(),
        ])
        .env_remove("TSLG_NDD_TABLE")
        .output()
        .expect("tslg runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let markdown = std::fs::read_to_string(dir.path().join("reproduction.md")).unwrap();
    assert_eq!(String::from_utf8_lossy(&out.stdout).trim(), markdown.trim());
    // The paper's numbers beside ours.
    assert!(markdown.contains("| 51 / 96300 (1888) |"), "{markdown}");
    assert!(markdown.contains("| 50 / 1.875e7 (375000) |"), "{markdown}");

    let csv = std::fs::read_to_string(dir.path().join("reproduction.csv")).unwrap();
    let rows = records(&csv);
    // Cut-in: two vehicles × (2 plain + 1 guarded + 2 adaptive);
    // car-following: 2 plain.
    assert_eq!(rows.len(), 12, "{csv}");
    let cutin = open_case("cut-in", None, &ExposureSource::Builtin).unwrap();
    // The multistart search through the service finds the whole library
    // (recall 1 on this grid): as many cells as enumeration.
    let exhaustive = cutin
        .build_library(
            &serde_json::json!({"model": "idm"}),
            &BuildRequest {
                threshold: None,
                search: Some(LibrarySearch::Cells(SearchMethod::Exhaustive)),
            },
        )
        .unwrap()
        .size;
    let z = z_for_confidence(0.9);
    for row in &rows {
        assert_eq!(row["status"], "converged", "{row:?}");
        let tests = number(row, "tests");
        match row["case"].as_str() {
            "cut-in" => {
                assert_eq!(number(row, "library_cells"), exhaustive as f64);
                assert_eq!(row["paper_library_cells"], "184");
                let vut = serde_json::json!({"model": row["vehicle"]});
                let exact = cutin.exact_event_probability(&vut).unwrap();
                assert_eq!(number(row, "exact_probability"), exact, "{row:?}");
                // The baseline fits the budget, so it ran, and the ratio is
                // its tests over the median library campaign's.
                assert_eq!(row["ndd_from"], "run");
                let expected = expected_ndd_tests(exact, 0.3, z);
                let ndd = number(row, "ndd_tests");
                assert!(ndd > 0.3 * expected && ndd < 3.0 * expected, "{row:?}");
                let ratio = ndd / number(row, "median_library_tests");
                assert!(
                    (number(row, "ratio") / ratio - 1.0).abs() < 1e-12,
                    "{row:?}"
                );
                if row["campaign"] == "adaptive" {
                    // Every test counted: at least the 100 of the library
                    // stage and n_min = 30 estimation tests.
                    assert!(tests >= 130.0, "{row:?}");
                    assert_eq!(row["epsilon"], "0.05");
                } else if row["campaign"] == "library" {
                    // ε 0.05: the default n_min is ⌈10/ε⌉ = 200.
                    assert_eq!(row["epsilon"], "0.05");
                    assert!(tests >= 200.0, "{row:?}");
                } else {
                    assert_eq!(row["campaign"], "library-guarded", "{row:?}");
                    assert_eq!(row["epsilon"], "0.5");
                    // At the stop r ≤ β puts ci_high ≤ (1 + β) μ̂, and the
                    // guard U − S₁,out/n ≤ β μ̂ puts the guarded upper end
                    // ci_high − S₁,out/n + U at most (1 + 2β) μ̂.
                    let (mu, high) = (number(row, "estimate"), number(row, "ci_high"));
                    let guarded = number(row, "guarded_ci_high");
                    assert!(guarded >= high, "{row:?}");
                    assert!(guarded <= (1.0 + 2.0 * 0.3) * mu * (1.0 + 1e-12), "{row:?}");
                }
            }
            "car-following" => {
                assert_eq!(row["exact_probability"], "", "no exact answer");
                // The baseline's 6 × 10⁷ tests exceed the budget: analytic,
                // from the median of the two estimates (the lower one).
                assert_eq!(row["ndd_from"], "analytic (library estimate)");
                let lower = rows
                    .iter()
                    .filter(|r| r["case"] == "car-following")
                    .map(|r| number(r, "estimate"))
                    .fold(f64::INFINITY, f64::min);
                let analytic = expected_ndd_tests(lower, 0.2, z);
                assert!((number(row, "ndd_tests") / analytic - 1.0).abs() < 1e-12);
                assert!(number(row, "ndd_tests") > 1e7, "{row:?}");
                assert!((30.0..1000.0).contains(&tests), "{row:?}");
                assert!((5e-7..2e-6).contains(&number(row, "estimate")), "{row:?}");
            }
            other => panic!("unexpected case {other}"),
        }
    }
    // A ratio is shown with its coverage where a library interval missed
    // the exact P(A): a speed-up for a wrong answer is not one.
    for vehicle in ["idm", "acc-aeb"] {
        let plain: Vec<_> = rows
            .iter()
            .filter(|r| r["case"] == "cut-in" && r["vehicle"] == vehicle)
            .filter(|r| r["campaign"] == "library")
            .collect();
        let covering = plain
            .iter()
            .filter(|r| {
                let p = number(r, "exact_probability");
                number(r, "ci_low") <= p && p <= number(r, "ci_high")
            })
            .count();
        let line = markdown
            .lines()
            .find(|l| l.starts_with("| cut-in |") && l.contains(&format!(" | {vehicle} | ")))
            .unwrap_or_else(|| panic!("a row of {vehicle} in {markdown}"));
        // `(covers 1 of 2)`, or `(covers 0 of 2: not an answer)`.
        let marked = format!("(covers {covering} of {}", plain.len());
        assert_eq!(line.contains(&marked), covering < plain.len(), "{line}");
    }
}
