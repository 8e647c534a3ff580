//! The `tslg` command, run as a user runs it.

use crate::support::{clean_refusal, tslg};
use std::path::{Path, PathBuf};
use std::process::Output;

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The coverage a `tslg validate` row of 20 replicates must show:
/// `coverage_floor(20, 0.9, 0.01) / 20` = 0.70, which a method covering at
/// the nominal 0.9 misses on 1 % of seed sets. Twenty replicates tell a
/// method far below (a plain campaign's 0.1–0.6) from a sound one, not one
/// at 0.8: that the method tests do with 200 seeds
/// (`tslg_testkit::CoverageCheck`). These tests check what `validate`
/// computes and writes.
fn floor_of_20() -> f64 {
    tslg_testkit::coverage_floor(20, 0.9, 0.01) as f64 / 20.0
}

/// The authors' cut-in table, or `None` after the test recorded its skip.
fn shared_table() -> Option<PathBuf> {
    tslg_testkit::authors_table()
}

fn field<'a>(text: &'a str, label: &str) -> &'a str {
    text.lines()
        .find_map(|l| l.strip_prefix(label))
        .unwrap_or_else(|| panic!("no `{label}` in\n{text}"))
        .trim()
}

#[test]
fn library_build_on_the_table_finds_184_cells_by_both_searches() {
    let Some(table) = shared_table() else { return };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("idm.json");
    let table = table.to_str().unwrap();
    for search in ["exhaustive", "multistart"] {
        let o = tslg(&[
            "library",
            "build",
            "--ndd-table",
            table,
            "--surrogate",
            "idm",
            "--search",
            search,
            "--recall",
            "-o",
            out.to_str().unwrap(),
            // The second search replaces the first's file.
            "--force",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let text = stdout(&o);
        assert!(
            field(&text, "library size").starts_with("184 of 3420"),
            "{text}"
        );
        assert!(
            stderr(&o).contains("renormalised"),
            "the 1.0000006 sum is reported"
        );
        if search == "multistart" {
            assert!(field(&text, "recall").starts_with("100.00%"), "{text}");
        }
    }
    let shown = tslg(&["library", "show", out.to_str().unwrap()]);
    assert!(shown.status.success());
    assert!(field(&stdout(&shown), "library size").starts_with("184"));
}

#[test]
fn evaluate_prints_an_estimate_near_the_exact_answer() {
    let dir = tempfile::tempdir().unwrap();
    let lib = dir.path().join("fvdm.json");
    let lib = lib.to_str().unwrap();
    let o = tslg(&["library", "build", "--surrogate", "fvdm", "-o", lib]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = tslg(&[
        "evaluate",
        "--library",
        lib,
        "--vut",
        "idm",
        "--seed",
        "3",
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(report["status"], "converged");
    let estimate = report["estimate"].as_f64().unwrap();
    let exact = report["exact"].as_f64().unwrap();
    let half_width = report["half_width"].as_f64().unwrap();
    assert!(report["relative_half_width"].as_f64().unwrap() <= 0.2);
    assert!((estimate - exact).abs() < 3.0 * half_width, "{report}");
    assert!(
        report["tests"].as_u64().unwrap() > 100,
        "FVDM library needs hundreds of tests for IDM"
    );
    let ndd = tslg(&["evaluate", "--method", "ndd", "--vut", "idm", "--json"]);
    assert!(ndd.status.success(), "{}", stderr(&ndd));
    let ndd: serde_json::Value = serde_json::from_slice(&ndd.stdout).unwrap();
    assert!(ndd["tests"].as_u64().unwrap() > 10_000);
}

#[test]
fn evaluate_adaptive_finds_what_the_idm_library_misses_of_the_fvdm() {
    // The IDM's library holds 17 % of the FVDM's failure mass: the plain
    // interval misses it; the adaptive campaign searches for the rest and
    // its interval holds the exact answer, in under a tenth of the NDD's
    // expected 12,550 tests.
    let dir = tempfile::tempdir().unwrap();
    let lib = dir.path().join("idm.json");
    let lib = lib.to_str().unwrap();
    let o = tslg(&["library", "build", "--surrogate", "idm", "-o", lib]);
    assert!(o.status.success(), "{}", stderr(&o));
    let run = |method: &str| -> serde_json::Value {
        let o = tslg(&[
            "evaluate",
            "--method",
            method,
            "--library",
            lib,
            "--vut",
            "fvdm",
            "--seed",
            "3",
            "--json",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        serde_json::from_slice(&o.stdout).unwrap()
    };
    let plain = run("library");
    assert_eq!(plain["covers_exact"], false, "{plain}");
    let adaptive = run("adaptive");
    assert_eq!(adaptive["method"], "adaptive");
    assert_eq!(adaptive["covers_exact"], true, "{adaptive}");
    let search = adaptive["search"]["search_tests"].as_u64().unwrap();
    let library = adaptive["search"]["library_tests"].as_u64().unwrap();
    let total = adaptive["indices"].as_u64().unwrap();
    assert_eq!(
        total,
        library + search + adaptive["tests"].as_u64().unwrap()
    );
    assert!(search > 100 && total < 1_255, "{adaptive}");
    // The text output says what the interval assumes.
    let o = tslg(&[
        "evaluate",
        "--method",
        "adaptive",
        "--library",
        lib,
        "--vut",
        "fvdm",
    ]);
    assert!(stdout(&o).contains("assumes"), "{}", stdout(&o));
    let o = tslg(&["evaluate", "--method", "adaptive", "--vut", "fvdm"]);
    assert!(clean_refusal(&o));
    assert!(stderr(&o).contains("--library"), "{}", stderr(&o));
}

#[test]
fn evaluate_runs_car_following_campaigns_in_process_and_adapts_the_policy() {
    // The offline commands work on every case through its descriptor: the
    // IDM's policy library learned here, then campaigns on its case and
    // preset (taken from the file).
    let dir = tempfile::tempdir().unwrap();
    let lib = dir.path().join("idm.policy");
    let lib = lib.to_str().unwrap();
    let o = tslg(&[
        "library",
        "build",
        "--case",
        "car-following",
        "--preset",
        "risky",
        "-o",
        lib,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("dynamic programming"), "{}", stdout(&o));
    let shown = tslg(&["library", "show", lib]);
    assert!(shown.status.success(), "{}", stderr(&shown));
    assert!(
        stdout(&shown).contains("car-following (risky)"),
        "{}",
        stdout(&shown)
    );
    assert!(
        stdout(&shown).contains("of 45885 states"),
        "{}",
        stdout(&shown)
    );
    let lagged = r#"{"model": "acc-aeb", "actuator_lag": 0.3}"#;
    let run = |method: &str| -> serde_json::Value {
        let o = tslg(&[
            "evaluate",
            "--library",
            lib,
            "--method",
            method,
            "--vut",
            lagged,
            "--seed",
            "3",
            "--json",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        serde_json::from_slice(&o.stdout).unwrap()
    };
    let adaptive = run("adaptive");
    assert_eq!(
        (&adaptive["case"], &adaptive["preset"], &adaptive["method"]),
        (
            &serde_json::json!("car-following"),
            &serde_json::json!("risky"),
            &serde_json::json!("adaptive")
        )
    );
    assert_eq!(adaptive["status"], "converged");
    assert_eq!(adaptive["vut"]["actuator_lag"], 0.3);
    assert!(adaptive["exact"].is_null());
    let search = &adaptive["search"];
    let (library, probes) = (
        search["library_tests"].as_u64().unwrap(),
        search["search_tests"].as_u64().unwrap(),
    );
    assert_eq!(library, 100);
    assert!(probes > 1_000, "{adaptive}");
    assert_eq!(
        adaptive["indices"].as_u64().unwrap(),
        library + probes + adaptive["tests"].as_u64().unwrap()
    );
    // The vehicle's driving, probes included, is far below the NDD
    // baseline's 3.8 × 10⁵ tests.
    let driving = search["driving"].as_f64().unwrap();
    assert!(
        driving > probes as f64 / 30.0 && driving < 38_000.0,
        "{adaptive}"
    );
    let o = tslg(&[
        "evaluate",
        "--case",
        "car-following",
        "--preset",
        "risky",
        "--method",
        "ndd",
        "--vut",
        lagged,
        "--seed",
        "3",
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let ndd: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(ndd["status"], "converged");
    assert!(ndd["tests"].as_u64().unwrap() > 50_000, "{ndd}");
    // Both estimates are near the vehicle's P(A) ≈ 1.79e-4 (NDD, 2 × 10⁷
    // tests): within three half-widths, which fails about one seed in 10³.
    for r in [&adaptive, &ndd] {
        let (estimate, half_width) = (
            r["estimate"].as_f64().unwrap(),
            r["half_width"].as_f64().unwrap(),
        );
        assert!((estimate - 1.79e-4).abs() < 3.0 * half_width, "{r}");
    }
    // What the file or the case refuses, with the reason.
    for (args, expected) in [
        (
            vec!["--library", lib, "--case", "cut-in"],
            "the library was built for case car-following",
        ),
        (
            vec!["--library", lib, "--preset", "paper"],
            "the library was built on preset risky",
        ),
        (
            vec!["--library", lib, "--guard-outside"],
            "--guard-outside applies to the grid cases",
        ),
        (
            vec![
                "--case",
                "car-following",
                "--preset",
                "fast",
                "--method",
                "ndd",
            ],
            "presets are paper",
        ),
    ] {
        let mut all = vec!["evaluate", "--vut", "idm"];
        all.extend(args);
        let o = tslg(&all);
        assert!(clean_refusal(&o));
        assert!(stderr(&o).contains(expected), "{}", stderr(&o));
    }
    let o = tslg(&["exact", "--case", "car-following"]);
    assert!(clean_refusal(&o));
    assert!(stderr(&o).contains("no exact answer"), "{}", stderr(&o));
}

#[test]
fn validate_compares_the_methods_in_one_csv() {
    let dir = tempfile::tempdir().unwrap();
    // The FVDM again, as an external program in step mode (examples/fvdm_vut.rs):
    // a held-out vehicle, run once on every cell.
    let program = crate::support::example_binary("fvdm_vut");
    let exec = format!("rs-fvdm={}", program.display());
    // The same program with noise: every cell run `--program-runs` times,
    // each test drawing one of its cell's runs, and the reference the mean
    // of those runs by exposure; its campaigns run under the guard (its
    // hello says it is noisy) and answer with the guarded interval.
    let noisy = format!("rs-noisy={} --noise 1.5", program.display());
    let out = tslg(&[
        "validate",
        "--cases",
        "cut-in",
        "--vut-exec",
        &noisy,
        "--program-runs",
        "1",
    ]);
    assert!(clean_refusal(&out));
    assert!(
        stderr(&out).contains("needs at least 2 runs a cell"),
        "{}",
        stderr(&out)
    );
    let noisy_dir = tempfile::tempdir().unwrap();
    let out = tslg(&[
        "validate",
        "--cases",
        "cut-in",
        "--methods",
        "adaptive",
        "--replicates",
        "5",
        "--vut-exec",
        &noisy,
        "--program-runs",
        "3",
        "--out",
        noisy_dir.path().to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("noisy program `rs-noisy`, 3 runs on every cell: P(A)"),
        "{}",
        stderr(&out)
    );
    let csv = std::fs::read_to_string(noisy_dir.path().join("methods.csv")).unwrap();
    let program_row: Vec<&str> = csv
        .lines()
        .find(|l| l.contains("rs-noisy (noisy program)"))
        .unwrap_or_else(|| panic!("no row of the noisy program in {csv}"))
        .split(',')
        .collect();
    // Its answer is the guarded interval, and a campaign that met its
    // guard has nothing to warn of.
    assert_eq!(program_row[6], program_row[11], "{csv}");
    assert_eq!(program_row[12], "0.0000", "{csv}");
    let out = tslg(&[
        "validate",
        "--cases",
        "cut-in",
        "--methods",
        "plain,adaptive,adaptive-guarded",
        "--replicates",
        "20",
        "--vut-exec",
        &exec,
        "--noise",
        "1.5",
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let csv = std::fs::read_to_string(dir.path().join("methods.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some(
            "case,exposure,surrogate,vut,method,replicates,coverage,median_tests,ndd_tests,\
             interval,coverage_every_n,guarded_coverage,warned"
        )
    );
    let row = |vut: &str, method: &str| -> Vec<String> {
        csv.lines()
            .map(|l| l.split(',').map(str::to_owned).collect::<Vec<_>>())
            .find(|c| c[2] == "idm" && c[3] == vut && c[4] == method)
            .unwrap_or_else(|| panic!("no idm → {vut} {method} in {csv}"))
    };
    // Six pairings and the program, three methods; the noisy IDM and FVDM
    // two, their campaigns being guarded already (no separate
    // adaptive-guarded row).
    assert_eq!(csv.lines().count(), 1 + 7 * 3 + 2 * 2, "{csv}");
    // The noisy IDM's reference is its Monte Carlo P(A), above the plain
    // IDM's (its noise makes boundary cells fail now and then): a larger
    // rate needs fewer NDD tests.
    let number = |c: &[String], k: usize| c[k].parse::<f64>().unwrap();
    assert!(
        number(&row("idm (noise 1.5)", "adaptive"), 8) < 0.9 * number(&row("idm", "adaptive"), 8),
        "{csv}"
    );
    // The program drives as the built-in FVDM does: the same exact P(A)
    // (the NDD column is computed from it) and the same campaigns.
    for method in ["plain", "adaptive", "adaptive-guarded"] {
        assert_eq!(
            row("rs-fvdm", method)[5..],
            row("fvdm", method)[5..],
            "{csv}"
        );
    }
    let plain = row("fvdm", "plain");
    let adaptive = row("fvdm", "adaptive");
    assert!(number(&plain, 6) < 0.6, "{csv}");
    assert!(number(&adaptive, 6) >= floor_of_20(), "{csv}");
    // Guarded, the adaptive campaign answers with [ci_low, guarded_ci_high]
    // (the coverage column is that one's), explores until the bound on what
    // its support leaves out is within β, and costs more tests for it; the
    // plain library campaign's guarded end covers where its interval does not.
    let guarded = row("fvdm", "adaptive-guarded");
    assert_eq!(guarded[6], guarded[11], "{csv}");
    assert!(number(&guarded, 6) >= floor_of_20(), "{csv}");
    assert!(number(&guarded, 7) > 2.0 * number(&adaptive, 7), "{csv}");
    assert!(number(&plain, 11) >= floor_of_20(), "{csv}");
    // A guarded adaptive campaign that met its guard has nothing to warn of.
    assert_eq!(number(&guarded, 12), 0.0, "{csv}");
    // Fewer than a tenth of the NDD baseline's tests.
    assert!(number(&adaptive, 7) * 10.0 < number(&adaptive, 8), "{csv}");
}

#[test]
fn evaluate_runs_on_the_preset_the_library_was_built_on() {
    let dir = tempfile::tempdir().unwrap();
    let lib = dir.path().join("table.json");
    let lib = lib.to_str().unwrap();
    let o = tslg(&[
        "library",
        "build",
        "--surrogate",
        "idm",
        "--search",
        "exhaustive",
        "--preset",
        "paper-table",
        "-o",
        lib,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let run = |extra: &[&str]| {
        let mut args = vec![
            "evaluate",
            "--library",
            lib,
            "--vut",
            "idm",
            "--seed",
            "2",
            "--json",
        ];
        args.extend_from_slice(extra);
        tslg(&args)
    };
    // Without --preset: the library's own, the same as saying it.
    let implied = run(&[]);
    assert!(implied.status.success(), "{}", stderr(&implied));
    let said = run(&["--preset", "paper-table"]);
    assert!(said.status.success(), "{}", stderr(&said));
    let tests = |o: &Output| {
        serde_json::from_slice::<serde_json::Value>(&o.stdout).unwrap()["tests"]
            .as_u64()
            .unwrap()
    };
    assert_eq!(tests(&implied), tests(&said));
    // The matched surrogate on its own simulation stops at n_min.
    assert!(tests(&implied) <= 200, "{} tests", tests(&implied));
    let other = run(&["--preset", "paper-code"]);
    assert!(clean_refusal(&other));
    assert!(
        stderr(&other).contains("the library was built on preset paper-table"),
        "{}",
        stderr(&other)
    );
    // The NDD baseline beside the library runs on its preset too (it ran
    // on the case's default, paper-code, before).
    let ndd = run(&["--method", "ndd", "--max-tests", "1000"]);
    assert!(ndd.status.success(), "{}", stderr(&ndd));
    let r: serde_json::Value = serde_json::from_slice(&ndd.stdout).unwrap();
    assert_eq!(
        (&r["preset"], &r["method"]),
        (&serde_json::json!("paper-table"), &serde_json::json!("ndd"))
    );
}

#[test]
fn a_library_file_with_an_unknown_field_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let lib = dir.path().join("idm.json");
    let o = tslg(&[
        "library",
        "build",
        "--surrogate",
        "idm",
        "-o",
        lib.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&lib).unwrap();
    for (from, to, field) in [
        ("\"gamma\":", "\"gamma_typo\": 1, \"gamma\":", "gamma_typo"),
        (
            "\"fingerprint\":",
            "\"extra\": 0, \"fingerprint\":",
            "extra",
        ),
        ("\"cell\":", "\"weight\": 2, \"cell\":", "weight"),
    ] {
        let changed = dir.path().join(format!("{field}.json"));
        std::fs::write(&changed, text.replacen(from, to, 1)).unwrap();
        let o = tslg(&["library", "show", changed.to_str().unwrap()]);
        assert!(clean_refusal(&o), "{field} accepted");
        assert!(
            stderr(&o).contains(&format!("unknown field `{field}`")),
            "{field}: {}",
            stderr(&o)
        );
    }
}

#[test]
fn exact_reports_every_vehicle_for_both_exposures() {
    let mut args = vec!["exact"];
    let table = shared_table();
    let table_str = table.as_ref().map(|t| t.to_str().unwrap().to_owned());
    if let Some(t) = &table_str {
        args.extend(["--ndd-table", t.as_str()]);
    }
    let o = tslg(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    let tables = if table.is_some() { 2 } else { 1 };
    for vehicle in ["idm", "fvdm", "switching-acc", "acc-aeb"] {
        let rows: Vec<&str> = text
            .lines()
            .filter(|l| l.starts_with(&format!("{vehicle} ")))
            .collect();
        assert_eq!(rows.len(), tables, "{text}");
        for row in rows {
            let cols: Vec<f64> = row
                .split_whitespace()
                .skip(1)
                .map(|c| c.parse().unwrap())
                .collect();
            let (p, library, ndd, ratio) = (cols[0], cols[1], cols[2], cols[3]);
            assert!(p > 1e-4 && p < 1e-2, "{row}");
            assert!((ndd / library - ratio).abs() / ratio < 0.05, "{row}");
        }
    }
    if table.is_some() {
        // The paper's IDM on the SPMD table: P(A) = 8.6621e-4.
        assert!(text.contains("8.6621e-4"), "{text}");
    }
}

#[test]
fn exact_gives_a_noisy_vehicle_the_tests_of_its_best_guarded_campaign() {
    // The IDM at σ 1.5 fails in a few cells near the library's: a guarded
    // campaign told every rate samples them (0.6 % of the exposure) and
    // spends its tests ruling out failures elsewhere, M ≈ ln(1/(1 − c))
    // P_O/(β μ) exploring tests at share 0.95 (docs/statistics.md).
    let o = tslg(&["exact", "--vut", r#"{"model": "idm", "noise": 1.5}"#]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    let row = text
        .lines()
        .find(|l| l.starts_with("idm (noise 1.5) "))
        .unwrap_or_else(|| panic!("{text}"));
    let cols: Vec<f64> = row
        .split_whitespace()
        .skip(3)
        .map(|c| c.parse().unwrap())
        .collect();
    let (mu, ndd) = (cols[0], cols[2]);
    let note = text
        .lines()
        .find(|l| l.starts_with("idm (noise 1.5): a guarded campaign"))
        .unwrap_or_else(|| panic!("{text}"));
    let number_after = |marker: &str| -> f64 {
        let rest = &note[note.find(marker).unwrap_or_else(|| panic!("{note}")) + marker.len()..];
        rest.split(|c: char| !(c.is_ascii_digit() || c == '.'))
            .next()
            .unwrap()
            .parse()
            .unwrap()
    };
    let tests = number_after("would need about ");
    let times = number_after("tests (");
    let support = number_after("the support then holds ") / 100.0;
    assert!((ndd / tests - times).abs() < 0.06, "{note}");
    let guard = (1.0f64 / 0.1).ln() * (1.0 - support) / (0.2 * mu) / 0.95;
    assert!(
        (tests / guard - 1.0).abs() < 0.01,
        "{tests} against {guard}: {note}"
    );
    assert!(note.contains("100% of the failures"), "{note}");
    assert!(times < 5.9 && times > 5.0, "{note}");
}

fn write(dir: &Path, name: &str, text: &str) -> String {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path.to_str().unwrap().to_owned()
}

#[test]
fn bad_input_gets_a_message_and_a_non_zero_exit() {
    let dir = tempfile::tempdir().unwrap();
    let lib = write(dir.path(), "lib.json", "");
    let cases: Vec<(Vec<String>, &str)> = vec![
        // A wrong value is said before a missing --library.
        (
            ["evaluate", "--vut", "idm", "--beta", "-0.2"]
                .map(String::from)
                .to_vec(),
            "beta = -0.2 must be in",
        ),
        (
            ["evaluate", "--vut", "idm", "--case", "cutin"]
                .map(String::from)
                .to_vec(),
            "unknown case `cutin`; known cases: cut-in",
        ),
        (
            vec![
                "exact".into(),
                "--ndd-table".into(),
                write(dir.path(), "nan.csv", ",0,1\n1,0.5,NaN\n"),
            ],
            "line 2, field 3",
        ),
        (
            vec![
                "exact".into(),
                "--ndd-table".into(),
                write(dir.path(), "sum.csv", ",0,1\n1,0.5,0.6\n"),
            ],
            "sum to 1.1",
        ),
        (
            vec![
                "exact".into(),
                "--ndd-table".into(),
                write(dir.path(), "shape.csv", ",0,1\n1,0.5\n"),
            ],
            "line 2 has 2 fields",
        ),
        (
            vec![
                "exact".into(),
                "--ndd-table".into(),
                dir.path().join("missing.csv").to_str().unwrap().into(),
            ],
            "cannot read the NDD table",
        ),
        (
            vec![
                "evaluate".into(),
                "--method".into(),
                "ndd".into(),
                "--vut".into(),
                "tesla".into(),
            ],
            "unknown variant `tesla`",
        ),
        (
            vec![
                "evaluate".into(),
                "--method".into(),
                "ndd".into(),
                "--vut".into(),
                r#"{"model":"idm","b":0}"#.into(),
            ],
            "parameter `b` = 0 must be > 0",
        ),
        (
            vec![
                "evaluate".into(),
                "--method".into(),
                "ndd".into(),
                "--vut".into(),
                "idm".into(),
                "--stage-tests".into(),
                "200".into(),
            ],
            "--stage-tests sets the length of a grid case's adaptive estimation stages",
        ),
        (
            vec![
                "evaluate".into(),
                "--method".into(),
                "ndd".into(),
                "--vut".into(),
                "idm".into(),
                "--beta".into(),
                "1.5".into(),
            ],
            "beta = 1.5",
        ),
        (
            vec![
                "evaluate".into(),
                "--library".into(),
                lib.clone(),
                "--vut".into(),
                "idm".into(),
            ],
            "not a library file",
        ),
        (
            vec![
                "evaluate".into(),
                "--library".into(),
                lib.clone(),
                "--vut".into(),
                "idm".into(),
                "--adaptive-search".into(),
                "lattice".into(),
            ],
            "use it with --method adaptive",
        ),
        (
            vec![
                "evaluate".into(),
                "--vut".into(),
                "idm".into(),
                "--library".into(),
                lib,
                "--epsilon".into(),
                "1".into(),
            ],
            "epsilon",
        ),
        (
            vec![
                "library".into(),
                "build".into(),
                "--preset".into(),
                "fast".into(),
                "-o".into(),
                "x".into(),
            ],
            "unknown cut-in preset `fast`",
        ),
        (
            vec![
                "library".into(),
                "build".into(),
                "--case".into(),
                "flying".into(),
                "-o".into(),
                "x".into(),
            ],
            "unknown case `flying`; known cases: cut-in, highway-exit",
        ),
        (
            vec![
                "library".into(),
                "build".into(),
                "--case".into(),
                "highway-exit".into(),
                "--ndd-table".into(),
                write(dir.path(), "any.csv", ",0,1\n1,0.5,0.5\n"),
                "-o".into(),
                "x".into(),
            ],
            "exposure table `any.csv` rejected: line 1, field 2: a block starts with a header \
             naming its columns",
        ),
        (
            vec![
                "library".into(),
                "build".into(),
                "--case".into(),
                "car-following".into(),
                "--search".into(),
                "multistart".into(),
                "-o".into(),
                "x".into(),
            ],
            "search.method is dynamic-programming or temporal-difference",
        ),
    ];
    for (args, expected) in cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = tslg(&args);
        assert!(clean_refusal(&o), "{args:?} succeeded");
        assert!(
            stderr(&o).contains(expected),
            "{args:?}: expected `{expected}` in\n{}",
            stderr(&o)
        );
    }
}

#[test]
fn the_offline_commands_run_highway_exit_through_its_descriptor() {
    // The case's default search (exhaustive, its descriptor says why) on
    // the coarse grid, a library and an adaptive campaign of the
    // gap-seeker, each with the exact P(A) by enumeration, and `exact`.
    let dir = tempfile::tempdir().unwrap();
    let lib = dir.path().join("mobil.json");
    let lib = lib.to_str().unwrap();
    let o = tslg(&[
        "library",
        "build",
        "--case",
        "highway-exit",
        "--preset",
        "coarse",
        "-o",
        lib,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    assert_eq!(field(&text, "case"), "highway-exit (coarse)");
    assert_eq!(field(&text, "surrogate"), "mobil");
    assert_eq!(field(&text, "search"), "exhaustive");
    assert!(
        field(&text, "library size").contains("of 9216 scenarios"),
        "{text}"
    );
    let run = |method: &str| -> serde_json::Value {
        let o = tslg(&[
            "evaluate",
            "--library",
            lib,
            "--method",
            method,
            "--vut",
            "gap-seeker",
            "--json",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        serde_json::from_slice(&o.stdout).unwrap()
    };
    let exact = {
        let o = tslg(&["exact", "--case", "highway-exit", "--preset", "coarse"]);
        assert!(o.status.success(), "{}", stderr(&o));
        let text = stdout(&o);
        let row = text.lines().find(|l| l.starts_with("gap-seeker")).unwrap();
        row.split_whitespace()
            .nth(1)
            .unwrap()
            .parse::<f64>()
            .unwrap()
    };
    for method in ["library", "adaptive"] {
        let r = run(method);
        assert_eq!(r["case"], "highway-exit");
        assert_eq!(r["preset"], "coarse");
        // The exact answer is the one `tslg exact` prints, to its digits.
        let e = r["exact"].as_f64().unwrap();
        assert!((e - exact).abs() <= 5e-5 * exact, "{e} vs {exact}");
    }
    // The plain library of MOBIL misses most of the gap-seeker's failures
    // (validate: coverage 0.02); the adaptive campaign finds them.
    assert_eq!(run("adaptive")["covers_exact"], true);
}

/// `--adaptive-search lattice` on highway-exit's paper grid: the campaign
/// says which search it ran and searches a fraction of what the grid
/// search does (whole blocks of 4⁴ cells join the support untested).
#[test]
fn evaluate_searches_the_paper_grid_on_its_lattice_when_asked() {
    let dir = tempfile::tempdir().unwrap();
    let lib = dir.path().join("paper.json");
    let lib = lib.to_str().unwrap();
    let o = tslg(&[
        "library",
        "build",
        "--case",
        "highway-exit",
        "--preset",
        "paper",
        "-o",
        lib,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let run = |search: &str, json: bool| -> Output {
        let mut args = vec![
            "evaluate",
            "--library",
            lib,
            "--method",
            "adaptive",
            "--adaptive-search",
            search,
            "--vut",
            "mobil",
        ];
        if json {
            args.push("--json");
        }
        let o = tslg(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        o
    };
    let json = |o: Output| -> serde_json::Value { serde_json::from_slice(&o.stdout).unwrap() };
    let grid = json(run("grid", true));
    let lattice = json(run("lattice", true));
    assert_eq!(field(&stdout(&run("lattice", false)), "search"), "lattice");
    assert_eq!(grid["search"]["adaptive_search"], "grid");
    assert_eq!(lattice["search"]["adaptive_search"], "lattice");
    let searched = |r: &serde_json::Value| r["search"]["search_tests"].as_u64().unwrap();
    assert!(
        2 * searched(&lattice) < searched(&grid),
        "lattice {lattice}, grid {grid}"
    );
}

#[test]
fn a_library_cannot_be_used_with_another_exposure() {
    let Some(table) = shared_table() else { return };
    let dir = tempfile::tempdir().unwrap();
    let lib = dir.path().join("lib.json");
    let lib = lib.to_str().unwrap();
    assert!(tslg(&[
        "library",
        "build",
        "--ndd-table",
        table.to_str().unwrap(),
        "-o",
        lib
    ])
    .status
    .success());
    let o = tslg(&["evaluate", "--library", lib, "--vut", "idm"]);
    assert!(clean_refusal(&o));
    assert!(
        stderr(&o).contains("was built on exposure cutin_ndd_spmd.csv"),
        "{}",
        stderr(&o)
    );
}

/// The demo's table has a `library` and an `ndd` row, both converged.
fn assert_both_campaigns_converged(text: &str) {
    assert_campaigns_converged(text, &["library", "ndd"]);
}

/// The demo's table has a converged row per method.
fn assert_campaigns_converged(text: &str, methods: &[&str]) {
    for method in methods {
        let row = text
            .lines()
            .find(|l| l.starts_with(&format!("{method} ")))
            .unwrap_or_else(|| panic!("no {method} row in {text}"));
        assert!(row.ends_with("converged"), "{row}");
    }
}

#[test]
fn demo_runs_both_campaigns_through_a_local_service_and_prints_the_table() {
    let o = tslg(&[
        "demo",
        "--vut",
        "fvdm",
        "--surrogate",
        "fvdm",
        "--seed",
        "3",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    assert!(text.contains("2 workers"), "{text}");
    assert!(text.contains("cut-in library 1 of fvdm"), "{text}");
    assert_both_campaigns_converged(&text);
    // The exact P(A) of the FVDM on the built-in exposure (docs/models.md).
    assert!(
        text.contains("exact P(A) by enumeration: 5.3608e-3"),
        "{text}"
    );
    assert!(
        text.contains("acceleration ratio (NDD tests / library tests): "),
        "{text}"
    );
    assert!(stderr(&o).contains("converged"), "progress is shown");
}

#[test]
fn the_default_demo_tests_a_vehicle_that_is_not_the_surrogate_three_ways() {
    // No --vut: on cut-in the FVDM, tested with the IDM's library.
    let o = tslg(&["demo", "--seed", "2"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    assert!(text.contains("cut-in library 1 of idm"), "{text}");
    assert!(text.contains("vehicle under test fvdm"), "{text}");
    assert_campaigns_converged(&text, &["library", "adaptive", "ndd"]);
    // One line per row saying what its interval rests on.
    for line in [
        "library  assumes the library holds the vehicle's failures",
        "adaptive assumes the vehicle's failures outside the library are reachable",
        "ndd      assumes nothing beyond the exposure model",
    ] {
        assert!(text.contains(line), "{line} in {text}");
    }
    assert!(
        text.contains("search tests found where the vehicle fails"),
        "{text}"
    );
    assert!(text.contains("NDD tests / adaptive tests: "), "{text}");
    // Beside the adaptive row, what its answer would be without the
    // assumption: the bound from its exploring tests.
    assert!(
        text.contains("without that assumption: up to ")
            && text.contains("of failure mass outside its support"),
        "{text}"
    );
    // The exact P(A) of the FVDM on the built-in exposure (docs/models.md).
    assert!(
        text.contains("exact P(A) by enumeration: 5.3608e-3"),
        "{text}"
    );
    // It ends on what to take away: the adaptive campaign's answer, and
    // what the library campaign's speed-up rests on.
    let last = text.trim_end().lines().last().unwrap();
    assert!(
        last.starts_with("take away: the adaptive campaign answered P(A) in [")
            && last.contains("(if its search reached every failure; without that, up to ")
            && last.contains("fewer than the NDD baseline")
            && last.contains("the library campaign's speed-up"),
        "{last}"
    );
}

#[test]
fn the_highway_exit_demo_reports_exact_and_analytic_figures() {
    let o = tslg(&["demo", "--case", "highway-exit", "--preset", "coarse"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    assert!(
        text.contains("highway-exit library 1 of mobil: 5 of 9216 scenarios (4320 surrogate runs"),
        "{text}"
    );
    assert_both_campaigns_converged(&text);
    // The exact P(A) of the MOBIL surrogate on the coarse grid (docs/models.md).
    assert!(
        text.contains("exact P(A) by enumeration: 1.0114e-3"),
        "{text}"
    );
    assert!(text.contains(" analytic ("), "{text}");
}

#[test]
fn the_car_following_demo_compares_library_and_ndd_intervals() {
    let o = tslg(&[
        "demo",
        "--case",
        "car-following",
        "--preset",
        "risky",
        "--vut",
        "acc-aeb",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    // The IDM's library on the risky preset: the states with P(S|s) > 0.
    assert!(
        text.contains("car-following library 1 of idm: 3575 of 45885 states"),
        "{text}"
    );
    assert!(text.contains("vehicle under test acc-aeb"), "{text}");
    assert_both_campaigns_converged(&text);
    assert!(text.contains("no exact P(A) for this case"), "{text}");
    assert!(text.contains("measured"), "{text}");
    let o = tslg(&["demo", "--case", "car-following", "--preset", "dense"]);
    assert!(clean_refusal(&o));
    assert!(stderr(&o).contains("presets are paper"), "{}", stderr(&o));
}

/// What the coordinator would refuse is refused before the demo starts one
/// and builds its library: nothing is printed but the reason.
#[test]
fn the_demo_refuses_bad_settings_before_it_starts() {
    for (args, reason) in [
        (
            &["--beta", "0.00001"][..],
            "--beta = 1e-5 must be in [0.0001, 0.99]",
        ),
        (
            &["--vut", "gap-seeker"][..],
            "invalid vehicle under test `gap-seeker`",
        ),
        (&["--surrogate", "nope"][..], "invalid surrogate `nope`"),
        (&["--epsilon", "2"][..], "--epsilon: ε = 2 must be 0 or in"),
        // A leading minus is a value, answered by the range check.
        (
            &["--beta", "-0.1"][..],
            "--beta = -0.1 must be in [0.0001, 0.99]",
        ),
    ] {
        let o = tslg(&[&["demo"][..], args].concat());
        assert!(clean_refusal(&o), "{args:?}");
        assert!(stdout(&o).is_empty(), "{args:?}: {}", stdout(&o));
        assert!(stderr(&o).contains(reason), "{args:?}: {}", stderr(&o));
    }
}

/// In a terminal (a pseudo-terminal from `script`), the demo's bars show no
/// bar before the first state (a bar of 0 of 0 was drawn full) and end
/// with a newline, so that the summary starts on a line of its own.
#[test]
fn in_a_terminal_the_bars_start_empty_and_end_on_their_own_line() {
    let command = format!("{} demo", env!("CARGO_BIN_EXE_tslg"));
    let o = std::process::Command::new("script")
        .args(["-qec", &command, "/dev/null"])
        .output()
        .expect("script (util-linux) runs the demo in a pseudo-terminal");
    assert!(o.status.success(), "{}", stderr(&o));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("waiting for its first state"), "{text}");
    assert!(text.contains("converged"), "the bars were drawn: {text}");
    assert!(!text.contains(" 0/0 "), "a full bar of 0/0 tests: {text}");
    // After the last frame of the bars (a bar's message reads `… tests  r
    // 0.199 → β 0.2 …`; the summary's lines do not), a newline comes before
    // anything else.
    let frame = text.rfind("tests  r ").expect("a bar's frame");
    let end = frame + text[frame..].find("converged").expect("a stopped bar");
    let after = &text[end + "converged".len()..];
    let next = after.trim_start_matches([' ', '\r']);
    assert!(
        next.starts_with('\n'),
        "no newline after the bars: {after:?}"
    );
}

/// A vehicle is named with the parameters that differ from its model's
/// defaults, and a parameter that changes no accident of the preset is
/// said to (the README's `{"model": "idm", "v0": 25}` read `idm`, and gave
/// exactly the plain IDM's answer without a word).
#[test]
fn a_vehicle_is_named_with_its_parameters_and_inert_ones_are_said_so() {
    let run = |vut: &str| {
        let o = tslg(&[
            "evaluate",
            "--vut",
            vut,
            "--method",
            "ndd",
            "--max-tests",
            "500",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        stdout(&o)
    };
    let inert = run(r#"{"model": "idm", "v0": 25}"#);
    assert!(
        inert.contains("vehicle under test idm (v0 25)\n"),
        "{inert}"
    );
    assert!(
        inert.contains("these parameters change no accident of preset paper-code"),
        "{inert}"
    );
    let active = run(r#"{"model": "idm", "s0": 4}"#);
    assert!(
        active.contains("vehicle under test idm (s0 4)\n"),
        "{active}"
    );
    assert!(!active.contains("change no accident"), "{active}");
    let lag = run(r#"{"model": "acc-aeb", "actuator_lag": 0.3}"#);
    assert!(
        lag.contains("vehicle under test acc-aeb (actuator_lag 0.3)"),
        "{lag}"
    );
    let plain = run("idm");
    assert!(plain.contains("vehicle under test idm\n"), "{plain}");
    assert!(!plain.contains("change no accident"), "{plain}");
}

/// Commands that write files refuse to replace one without `--force`,
/// before they do their work.
#[test]
fn files_written_are_not_replaced_without_force() {
    let dir = tempfile::tempdir().unwrap();
    let library = dir.path().join("idm.tslg.json");
    let path = library.to_str().unwrap();
    let build = |force: bool| {
        let mut args = vec!["library", "build", "--search", "exhaustive", "--out", path];
        if force {
            args.push("--force");
        }
        tslg(&args)
    };
    assert!(build(false).status.success());
    let first = std::fs::read(&library).unwrap();
    std::fs::write(&library, b"mine").unwrap();
    let refused = build(false);
    assert!(clean_refusal(&refused));
    assert!(
        stderr(&refused).contains("idm.tslg.json exists; pass --force to replace it"),
        "{}",
        stderr(&refused)
    );
    assert!(stdout(&refused).is_empty(), "no work before the refusal");
    assert_eq!(std::fs::read(&library).unwrap(), b"mine");
    assert!(build(true).status.success());
    assert_eq!(std::fs::read(&library).unwrap(), first);
    // validate --out: refused before the replicates run.
    std::fs::write(dir.path().join("validation.md"), "mine").unwrap();
    let out = dir.path().to_str().unwrap();
    let refused = tslg(&["validate", "--quick", "--out", out]);
    assert!(clean_refusal(&refused));
    assert!(
        stderr(&refused).contains("validation.md exists; pass --force to replace it"),
        "{}",
        stderr(&refused)
    );
    assert!(
        !stderr(&refused).contains("[1/"),
        "it ran: {}",
        stderr(&refused)
    );
}

/// An error says each cause once (`tslg backup` of a database it cannot
/// open repeated SQLite's "(code: 14) unable to open database file").
#[test]
fn an_error_says_its_cause_once() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("copy.sqlite");
    let o = tslg(&[
        "backup",
        "--database-url",
        "sqlite:///nonexistent-dir/db.sqlite",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(clean_refusal(&o));
    let text = stderr(&o);
    assert_eq!(
        text.matches("unable to open database file").count(),
        1,
        "{text}"
    );
}

/// Commands that reach a coordinator take it from `TSLG_SERVER` or their
/// default: their usage line does not ask for `--server`.
#[test]
fn the_coordinator_address_is_not_shown_as_required() {
    for command in [
        &["campaign", "start", "--help"][..],
        &["campaign", "list", "--help"],
        &["library", "create", "--help"],
    ] {
        let o = tslg(command);
        let usage = stdout(&o)
            .lines()
            .find(|l| l.starts_with("Usage:"))
            .unwrap_or_default()
            .to_owned();
        assert!(usage.contains("[OPTIONS]"), "{command:?}: {usage}");
        assert!(!usage.contains("--server"), "{command:?}: {usage}");
    }
}

/// docs/operations.md's pipeline gate quotes what its guarded campaigns
/// need in process: the numbers there are these commands' (docs as tests).
#[test]
fn the_gate_example_s_numbers_are_what_its_guarded_campaigns_give() {
    let dir = tempfile::tempdir().unwrap();
    let library = dir.path().join("idm.json");
    let library = library.to_str().unwrap();
    let o = tslg(&["library", "build", "--surrogate", "idm", "--out", library]);
    assert!(o.status.success(), "{}", stderr(&o));
    let docs = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/operations.md"),
    )
    .unwrap();
    for (vut, fails) in [("fvdm", true), ("idm", false)] {
        let o = tslg(&[
            "evaluate",
            "--library",
            library,
            "--vut",
            vut,
            "--guard-outside",
            "--outside",
            "ndd",
            "--beta",
            "0.2",
            "--max-tests",
            "200000",
            "--json",
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
        let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let tests = report["tests"].as_u64().unwrap();
        let quoted = format!("{},{:03}", tests / 1000, tests % 1000);
        assert!(
            docs.contains(&quoted),
            "operations.md does not quote {quoted} ({vut})"
        );
        // The gate `--fail-above 5e-3` judges the guarded upper end.
        let high = report["guarded_ci_high"].as_f64().unwrap();
        assert_eq!(high > 5e-3, fails, "{vut}: guarded upper end {high}");
    }
}

/// `tslg validate --stage-tests`: adaptive campaigns with a fleet's stage
/// length, whose search is widened to `stage_tests / 5` cells, still cover
/// and cost what the widened search tests; a length that is no multiple
/// of 20 is refused before anything runs.
#[test]
fn validate_runs_adaptive_campaigns_at_a_fleet_s_stage_length() {
    let medians = |stage_tests: &str| -> Vec<(String, f64, u64)> {
        let dir = tempfile::tempdir().unwrap();
        let out = tslg(&[
            "validate",
            "--cases",
            "cut-in",
            "--methods",
            "adaptive",
            "--replicates",
            "20",
            "--stage-tests",
            stage_tests,
            "--out",
            dir.path().to_str().unwrap(),
        ]);
        assert!(out.status.success(), "{}", stderr(&out));
        let csv = std::fs::read_to_string(dir.path().join("methods.csv")).unwrap();
        csv.lines()
            .skip(1)
            .map(|l| {
                let c: Vec<&str> = l.split(',').collect();
                (
                    format!("{} → {}", c[2], c[3]),
                    c[6].parse().unwrap(),
                    c[7].parse().unwrap(),
                )
            })
            .collect()
    };
    let (one_ring, widened) = (medians("100"), medians("640"));
    assert_eq!(one_ring.len(), 6, "{one_ring:?}");
    for ((pairing, _, tests), (same, coverage, wider)) in one_ring.iter().zip(&widened) {
        assert_eq!(pairing, same);
        assert!(*coverage >= floor_of_20(), "{pairing}: {coverage}");
        // The rings around each search stage are tested too (statistics.md:
        // 1.2 to 1.9 times the tests at 200 seeds).
        assert!(wider > tests, "{pairing}: {wider} against {tests}");
    }
    let refused = tslg(&["validate", "--quick", "--stage-tests", "110"]);
    assert!(clean_refusal(&refused));
    assert!(
        stderr(&refused)
            .contains("--stage-tests must be a multiple of 20 from 20 to 100000, not 110"),
        "{}",
        stderr(&refused)
    );
}

/// Numeric flags take a leading minus, so that the range check says what
/// the range is (clap alone said "unexpected argument '-0' found").
#[test]
fn a_negative_number_is_a_value_that_the_range_check_refuses() {
    for args in [
        &[
            "evaluate", "--vut", "idm", "--method", "ndd", "--beta", "-0.1",
        ][..],
        &["validate", "--quick", "--beta", "-0.1"][..],
        &["exact", "--beta", "-0.1"][..],
        &[
            "evaluate",
            "--vut",
            "idm",
            "--method",
            "ndd",
            "--confidence",
            "-0.9",
        ][..],
        &["evaluate", "--vut", "idm", "--epsilon", "-0.5"][..],
    ] {
        let o = tslg(args);
        assert!(clean_refusal(&o), "{args:?}");
        let text = stderr(&o);
        assert!(!text.contains("unexpected argument"), "{args:?}: {text}");
        assert!(
            text.contains("-0.") && text.contains("must be"),
            "{args:?}: {text}"
        );
    }
}

#[test]
fn policy_prints_the_car_following_librarys_action_distribution_at_the_papers_state() {
    let o = tslg(&["policy", "--state", "38,6,-2"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    assert!(text.contains("zone dangerous"), "{text}");
    assert!(!text.contains("not a grid state"), "{text}");
    // An off-grid state is answered by the nearest grid state, saying so.
    let off = stdout(&tslg(&["policy", "--state", "100,6.5,-2"]));
    assert!(off.contains("state (v 40, R 7, Ṙ -2)"), "{off}");
    assert!(
        off.contains("(--state 100,6.5,-2 is not a grid state: the nearest one answers)"),
        "{off}"
    );
    assert!(text.contains("by dynamic programming"), "{text}");
    // The learned distribution peaks at a hard but not the hardest braking.
    assert!(text.contains("peaks at u = -3.6 m/s²"), "{text}");
    // Row of u = −3.6: the NDD gives it well under 0.1%, the library most of its mass.
    let row = text
        .lines()
        .find(|l| l.trim_start().starts_with("-3.6 "))
        .expect("a row for u = -3.6");
    let cols: Vec<f64> = row.split_whitespace().map(|c| c.parse().unwrap()).collect();
    assert!(cols[1] < 1e-3 && cols[2] > 0.3, "{row}");
    for (state, expected) in [
        ("38,6", "must be three numbers"),
        ("30,200,0", "beyond the grid"),
    ] {
        let o = tslg(&["policy", "--state", state]);
        assert!(clean_refusal(&o));
        assert!(stderr(&o).contains(expected), "{}", stderr(&o));
    }
}

/// The value of `column` in the Markdown row of `surrogate` → `vehicle`
/// (unguarded unless `guard`).
fn validation_cell(
    table: &str,
    surrogate: &str,
    vehicle: &str,
    guard: bool,
    column: &str,
) -> String {
    let header: Vec<&str> = table
        .lines()
        .next()
        .unwrap()
        .split('|')
        .map(str::trim)
        .collect();
    let at = header.iter().position(|h| *h == column).unwrap();
    let guard = if guard { "yes" } else { "no" };
    table
        .lines()
        .map(|l| l.split('|').map(str::trim).collect::<Vec<_>>())
        .find(|c| c.len() > at && c[2] == surrogate && c[3] == vehicle && c[7] == guard)
        .unwrap_or_else(|| panic!("no row {surrogate} → {vehicle} in\n{table}"))[at]
        .to_owned()
}

#[test]
fn validate_measures_the_coverage_curve_at_every_n_on_the_authors_table() {
    let Some(table) = shared_table() else { return };
    let dir = tempfile::tempdir().unwrap();
    let out = tslg(&[
        "validate",
        "--cases",
        "cut-in",
        "--ndd-table",
        table.to_str().unwrap(),
        "--curve-to",
        "100",
        "--replicates",
        "1000",
        "--splits",
        "random,stratified",
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let csv = std::fs::read_to_string(dir.path().join("curve.csv")).unwrap();
    // Six pairings under two splits, n = 2 … 100 each.
    assert_eq!(csv.lines().count(), 1 + 2 * 6 * 99, "{csv}");
    let split_coverage = |surrogate: &str, vut: &str, split: &str, n: u64| -> f64 {
        let prefix = format!("cut-in,cutin_ndd_spmd.csv,{surrogate},{vut},0.1,{split},1000,{n},");
        let line = csv.lines().find(|l| l.starts_with(&prefix));
        line.unwrap_or_else(|| panic!("no {prefix} in {csv}"))[prefix.len()..]
            .parse()
            .unwrap()
    };
    let coverage = |surrogate: &str, vut: &str, n: u64| split_coverage(surrogate, vut, "random", n);
    // The matched IDM under the random split: the exact lattice of the Binomial split (by
    // enumeration in method/tests/it/cutin_paper.rs), within three
    // standard errors of 1,000 replicates.
    for (n, exact) in [
        (20, 0.8672),
        (25, 0.9187),
        (30, 0.7905),
        (40, 0.9040),
        (100, 0.8622),
    ] {
        let measured = coverage("idm", "idm", n);
        let se = (exact * (1.0 - exact) / 1000.0f64).sqrt();
        assert!(
            (measured - exact).abs() < 3.0 * se,
            "n {n}: {measured} against {exact}"
        );
    }
    // Stratified, the split is no noise: from the first exploring test
    // (n = 10) every interval of the matched pairs holds P(A).
    for vut in ["idm", "fvdm"] {
        assert!(
            (10..=100).all(|n| split_coverage(vut, vut, "stratified", n) == 1.0),
            "{csv}"
        );
    }
    // The IDM library testing the FVDM: far below nominal at every n,
    // whatever the split: the library does not cover the vehicle.
    for split in ["random", "stratified"] {
        assert!(
            (2..=100).all(|n| split_coverage("idm", "fvdm", split, n) < 0.5),
            "{csv}"
        );
    }
    let summary = stdout(&out);
    assert!(
        summary.contains("| idm | fvdm | 0.1 | random | 1000 | 100 |"),
        "{summary}"
    );
    // Tables are for cut-in only.
    let refused = tslg(&[
        "validate",
        "--cases",
        "highway-exit",
        "--ndd-table",
        table.to_str().unwrap(),
        "--curve-to",
        "10",
    ]);
    assert!(clean_refusal(&refused));
}

#[test]
fn validate_flags_the_mismatched_pair_and_the_guard_restores_coverage() {
    let dir = tempfile::tempdir().unwrap();
    let out = tslg(&[
        "validate",
        "--cases",
        "cut-in",
        "--replicates",
        "40",
        "--guard",
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let table = stdout(&out);
    let cell = |s, v, g, c| validation_cell(&table, s, v, g, c);
    let number = |s, v, g, c| cell(s, v, g, c).parse::<f64>().unwrap();
    // The IDM library testing the FVDM: the plain interval misses far more
    // often than 1 in 10, and is flagged; the guarded interval covers.
    assert!(
        number("idm", "fvdm", false, "coverage plain") < 0.5,
        "{table}"
    );
    assert!(
        cell("idm", "fvdm", false, "flag").contains("LOW plain"),
        "{table}"
    );
    assert!(
        number("idm", "fvdm", false, "coverage guarded") >= 0.9,
        "{table}"
    );
    // A matched pair stops at the default n_min, ⌈10/ε⌉ = 100 for ε 0.1;
    // with the guard it needs thousands.
    assert_eq!(number("fvdm", "fvdm", false, "tests median"), 100.0);
    assert!(
        number("fvdm", "fvdm", true, "tests median") > 1000.0,
        "{table}"
    );
    assert!(
        number("idm", "fvdm", true, "coverage guarded") >= 0.9,
        "{table}"
    );
    let csv = std::fs::read_to_string(dir.path().join("validation.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 12, "{csv}");
    assert!(csv.starts_with("case,surrogate,vehicle,"), "{csv}");
    let unknown = tslg(&["validate", "--cases", "car-following"]);
    assert!(clean_refusal(&unknown));
    assert!(
        stderr(&unknown).contains("needs an exact answer"),
        "{}",
        stderr(&unknown)
    );
}

/// Issue 54's own 4-D check: a highway-exit vehicle written as a program
/// (examples/merger_vut.rs, a cautious merger) through the validation
/// table, on the coarse grid (9,216 cells, the program run once on each).
/// Its failures lie away from the MOBIL library's failures and from its
/// own near misses, so the adaptive search does not reach them and the
/// plain adaptive interval misses (measured 0.12 over 200 seeds); the
/// guard's exploring tests bound what the support leaves out, and the
/// guarded interval covers. 200 seeds: floor 170 (`CoverageCheck`).
#[test]
fn the_merger_program_s_failures_escape_the_adaptive_search_and_the_guard_covers_them() {
    let dir = tempfile::tempdir().unwrap();
    let exec = format!(
        "merger={}",
        crate::support::example_binary("merger_vut").display()
    );
    let out = tslg(&[
        "validate",
        "--quick",
        "--cases",
        "highway-exit",
        "--methods",
        "adaptive,adaptive-guarded",
        "--replicates",
        "200",
        "--vut-exec",
        &exec,
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let csv = std::fs::read_to_string(dir.path().join("methods.csv")).unwrap();
    let row = |method: &str| -> Vec<String> {
        csv.lines()
            .map(|l| l.split(',').map(str::to_owned).collect::<Vec<_>>())
            .find(|c| c[3] == "merger" && c[4] == method)
            .unwrap_or_else(|| panic!("no merger {method} in {csv}"))
    };
    let coverage = |method: &str| row(method)[6].parse::<f64>().unwrap();
    let check = tslg_testkit::CoverageCheck::new(200, 0.9, 0.01);
    assert!(coverage("adaptive") < 0.5, "{csv}");
    check.assert_covers(
        (coverage("adaptive-guarded") * 200.0).round() as u64,
        "the merger, adaptive under the guard",
    );
    // The exact P(A) is the program's own: about one run in a hundred
    // fails, so the NDD needs thousands of tests.
    let ndd: f64 = row("adaptive")[8].parse().unwrap();
    assert!((1_000.0..50_000.0).contains(&ndd), "{csv}");
}

/// `tslg validate --interval wald,anytime`: each pairing once per
/// interval, with the share of campaigns whose interval held at every n.
/// The IDM library on the FVDM: the plain Wald interval misses along the
/// way; the anytime one (guarded by construction) holds, at more tests.
#[test]
fn validate_compares_the_wald_and_the_anytime_interval_at_every_n() {
    let dir = tempfile::tempdir().unwrap();
    let out = tslg(&[
        "validate",
        "--cases",
        "cut-in",
        "--replicates",
        "20",
        "--interval",
        "wald,anytime",
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let csv = std::fs::read_to_string(dir.path().join("methods.csv")).unwrap();
    let row = |surrogate: &str, vut: &str, interval: &str| -> Vec<String> {
        csv.lines()
            .map(|l| l.split(',').map(str::to_owned).collect::<Vec<_>>())
            .find(|c| c[2] == surrogate && c[3] == vut && c[9] == interval)
            .unwrap_or_else(|| panic!("no {surrogate} → {vut} {interval} in {csv}"))
    };
    assert_eq!(csv.lines().count(), 1 + 6 * 2, "{csv}");
    let number = |c: &[String], k: usize| c[k].parse::<f64>().unwrap();
    let (wald, anytime) = (row("idm", "fvdm", "wald"), row("idm", "fvdm", "anytime"));
    assert!(number(&wald, 10) < 0.5, "{csv}");
    assert!(number(&anytime, 10) >= floor_of_20(), "{csv}");
    assert!(number(&anytime, 7) > 10.0 * number(&wald, 7), "{csv}");
    // Every anytime row holds at every n at about its level or above.
    for line in csv.lines().skip(1).filter(|l| l.contains(",anytime,")) {
        let c: Vec<String> = line.split(',').map(str::to_owned).collect();
        assert!(number(&c, 10) >= floor_of_20(), "{line}");
    }
}

/// `tslg evaluate --paired-with`: a 5-cell regression of the IDM measured
/// on the same NDD tests, the difference of the rates beside the exact one.
#[test]
fn a_paired_evaluation_estimates_the_difference_of_two_builds_on_the_same_tests() {
    let o = tslg(&[
        "evaluate",
        "--method",
        "ndd",
        "--vut",
        r#"{"model": "idm", "s0": 0.5}"#,
        "--paired-with",
        "idm",
        "--seed",
        "1",
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let f = |v: &serde_json::Value| v.as_f64().unwrap();
    let (a, b, d) = (&r["rate_a"], &r["rate_b"], &r["difference"]);
    assert!((f(&d[0]) - (f(&a[0]) - f(&b[0]))).abs() < 1e-15);
    assert!(r["events"][2].as_u64().unwrap() >= 10, "{r}");
    // The exact rates by enumeration: the IDM's 9.3260e-4, and the
    // difference inside the paired interval on this seed.
    let exact = &r["exact"];
    assert!((f(&exact[1]) - 9.3260e-4).abs() < 5e-9, "{exact}");
    assert!(f(&d[1]) <= f(&exact[2]) && f(&exact[2]) <= f(&d[2]), "{r}");
    // Pairing: two separate NDD campaigns would need many times more.
    assert!(f(&r["independent_tests"]) > 10.0 * r["tests"].as_u64().unwrap() as f64);
    // The same vehicle twice never differs: it runs to its budget.
    let o = tslg(&[
        "evaluate",
        "--method",
        "ndd",
        "--vut",
        "idm",
        "--paired-with",
        "idm",
        "--max-tests",
        "20000",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stdout(&o).contains("max tests reached")
            && stdout(&o).contains("discordant (one failed) 0")
    );
    let o = tslg(&[
        "evaluate",
        "--method",
        "adaptive",
        "--library",
        "x.json",
        "--vut",
        "fvdm",
        "--paired-with",
        "idm",
    ]);
    assert!(clean_refusal(&o));
    assert!(stderr(&o).contains("--paired-with runs library and ndd campaigns"));
}
