//! Naturalistic data for every case (issue 22 part 2): each case's built-in
//! exposure printed as the table it accepts (`tslg table`) reads back to
//! the built-in model; the user's own tables change the library and the
//! exact answer, say how far they lie from the built-in model, and are
//! refused with the line and the reason when they are wrong; through the
//! API a library records its table's note and fingerprint.

use crate::support::*;
use std::path::Path;
use tslg_api::{CreateLibrary, ExposureRequest};

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn write(dir: &Path, name: &str, content: &str) -> String {
    let path = dir.join(name);
    std::fs::write(&path, content).unwrap();
    path.to_str().unwrap().to_owned()
}

/// `tslg table` of a case, as a file.
fn builtin_table(dir: &Path, case: &str, preset: &str) -> (String, String) {
    let o = tslg(&["table", "--case", case, "--preset", preset]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let content = text(&o.stdout);
    // Labels are the shortest text of their grid values (no
    // `-14.399999999999999`), probabilities in scientific notation (no
    // `0.00000000000000012040820585651798`).
    for line in content.lines().filter(|l| !l.starts_with('#')) {
        for field in line.split(',').filter(|f| f.parse::<f64>().is_ok()) {
            if field.contains('e') {
                continue;
            }
            assert!(field.len() <= 8, "{case}: `{field}` in `{line}`");
        }
    }
    (write(dir, &format!("{case}.csv"), &content), content)
}

/// `tslg exact`'s P(A) of `vehicle` (its row), with `extra` arguments.
fn exact(args: &[&str], vehicle: &str) -> f64 {
    let mut all = vec!["exact"];
    all.extend(args);
    let o = tslg(&all);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let out = text(&o.stdout);
    out.lines()
        .rev()
        .find(|l| l.starts_with(vehicle))
        .and_then(|l| l.split_whitespace().nth(1))
        .unwrap()
        .parse()
        .unwrap()
}

#[test]
fn every_case_reads_its_own_model_back_and_a_users_table_changes_the_answer() {
    let dir = tempfile::tempdir().unwrap();
    // Highway-exit, coarse grid: the exported table gives the built-in
    // exact answer; a table of slower traffic another one.
    let (path, content) = builtin_table(dir.path(), "highway-exit", "coarse");
    let base = ["--case", "highway-exit", "--preset", "coarse"];
    let builtin = exact(&base, "gap-seeker");
    let mut with_table = base.to_vec();
    with_table.extend(["--ndd-table", path.as_str()]);
    let o = tslg(&[&["exact"][..], &with_table].concat());
    assert!(
        text(&o.stderr).contains("total variation distance 0.000"),
        "{}",
        text(&o.stderr)
    );
    let read_back = exact(&with_table, "gap-seeker");
    assert!(
        (read_back - builtin).abs() <= 1e-4 * builtin,
        "{read_back} vs {builtin}"
    );
    // Only the slow half of the speeds (v1 ≤ 28 m/s), renormalised.
    let slow: Vec<&str> = content
        .lines()
        .filter(|l| match l.split(',').next().unwrap().parse::<f64>() {
            Ok(v1) => v1 <= 28.0,
            Err(_) => true,
        })
        .collect();
    let slow_total: f64 = slow
        .iter()
        .filter_map(|l| l.rsplit(',').next()?.parse::<f64>().ok())
        .sum();
    let slow_text: String = slow
        .iter()
        .map(|l| match l.rsplit_once(',') {
            Some((key, p)) if p.parse::<f64>().is_ok() => {
                format!("{key},{}\n", p.parse::<f64>().unwrap() / slow_total)
            }
            _ => format!("{l}\n"),
        })
        .collect();
    let slow_path = write(dir.path(), "slow.csv", &slow_text);
    let mut with_slow = base.to_vec();
    with_slow.extend(["--ndd-table", slow_path.as_str()]);
    let o = tslg(&[&["exact"][..], &with_slow].concat());
    let note = text(&o.stderr);
    let distance: f64 = note
        .split("total variation distance ")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .unwrap()
        .parse()
        .unwrap();
    assert!(distance > 0.2, "{note}");
    assert!(
        (exact(&with_slow, "gap-seeker") - builtin).abs() > 0.05 * builtin,
        "another exposure, another answer"
    );

    // Car-following and cut-in: the exported model builds the same library
    // as the built-in one.
    for (case, preset, size) in [
        ("car-following", "risky", "3575 of 45885 states"),
        ("cut-in", "paper-code", "of 3420 scenarios"),
    ] {
        let (path, _) = builtin_table(dir.path(), case, preset);
        let out = dir.path().join(format!("{case}.lib"));
        let o = tslg(&[
            "library",
            "build",
            "--case",
            case,
            "--preset",
            preset,
            "--ndd-table",
            &path,
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", text(&o.stderr));
        assert!(
            text(&o.stderr).contains("distance 0.000"),
            "{}",
            text(&o.stderr)
        );
        let summary = text(&o.stdout);
        assert!(summary.contains(size), "{summary}");
        assert!(summary.contains(&format!("{case}.csv")), "{summary}");
    }
}

#[test]
fn wrong_tables_are_refused_with_the_line_and_the_reason() {
    let dir = tempfile::tempdir().unwrap();
    let (_, follow) = builtin_table(dir.path(), "car-following", "risky");
    let (states, laws) = follow.split_once("\n\n").unwrap();
    let cases = [
        (
            "highway-exit",
            "v1,range,v2,probability\n28,40,28,0.5\n28,40,28,0.5\n".to_owned(),
            "line 3 gives the same point as line 2",
        ),
        (
            "highway-exit",
            "v1,range,v2,probability\n28,42,28,1\n".to_owned(),
            "range = 42 is not on the grid (5 to 300 in steps of 5)",
        ),
        (
            "highway-exit",
            "v1,range,v2,probability\n28,40,28,NaN\n".to_owned(),
            "probabilities must be finite",
        ),
        (
            "highway-exit",
            "v1,range,v2,probability\n28,40,28,-0.5\n28,45,28,1.5\n".to_owned(),
            "the probability -0.5 is negative",
        ),
        (
            "highway-exit",
            "v1,range,v2,probability\n28,40,28,0.4\n".to_owned(),
            "sum to 0.4",
        ),
        // Another case's table: the reader says what this one's looks like.
        (
            "cut-in",
            "v1,range,v2,probability\n28,40,28,1\n".to_owned(),
            "`range` is not a number (this case's table is a matrix",
        ),
        // Every cut-in at R ≤ 0: the built-in model has no density there
        // to compare with (a panic and exit 101 before).
        (
            "cut-in",
            ",-0.4,0\n-1,0.5,0\n0,0.25,0.25\n".to_owned(),
            "no probability at a positive range (R > 0 m)",
        ),
        ("car-following", states.to_owned(), "P(u | v) is missing"),
        (
            "car-following",
            format!("speed,range,range_rate,probability\n30,1,0,1\n\n{laws}"),
            "an accident that has happened",
        ),
        (
            "car-following",
            format!("speed,range,range_rate\n30,10,0\n\n{laws}"),
            "not one this case reads",
        ),
    ];
    for (case, table, expected) in cases {
        let path = write(dir.path(), "bad.csv", &table);
        let o = tslg(&["exact", "--case", case, "--ndd-table", &path]);
        let o = if case == "car-following" {
            tslg(&[
                "library",
                "build",
                "--case",
                case,
                "--ndd-table",
                &path,
                "-o",
                dir.path().join("x").to_str().unwrap(),
            ])
        } else {
            o
        };
        // A refusal (1), not a panic (101).
        assert_eq!(o.status.code(), Some(1), "{case}: {expected}");
        // Refused before anything is worked out or printed.
        assert!(o.stdout.is_empty(), "{case}: {}", text(&o.stdout));
        let err = text(&o.stderr);
        assert!(err.contains(expected), "{case}: `{expected}` not in\n{err}");
        assert!(err.contains("bad.csv"), "the table is named: {err}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_api_takes_a_table_for_every_case_and_records_how_far_it_is() {
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let client = server.client();
    let table = tslg_method::cases::builtin_table("highway-exit", Some("coarse")).unwrap();
    let request = |exposure| CreateLibrary {
        case: "highway-exit".into(),
        preset: Some("coarse".into()),
        surrogate: serde_json::json!({"model": "mobil"}),
        exposure,
        search: None,
        threshold: None,
    };
    let builtin = build_library(&client, &request(ExposureRequest::Builtin)).await;
    let tabled = build_library(
        &client,
        &request(ExposureRequest::Table {
            name: "highway.csv".into(),
            text: table,
        }),
    )
    .await;
    assert_eq!(builtin.exposure_note, None);
    let note = tabled.exposure_note.as_deref().unwrap();
    assert!(
        note.contains("highway.csv: total variation distance 0.000"),
        "{note}"
    );
    assert_eq!(tabled.exposure, "highway.csv");
    // Read at the last digit, the table is another exposure: its
    // fingerprint is its own, so campaigns cannot mix the two.
    assert_ne!(tabled.exposure_fingerprint, builtin.exposure_fingerprint);
    assert_eq!(tabled.size, builtin.size);
    // A wrong table is a 422 naming the line.
    let refused = client
        .create_library(&request(ExposureRequest::Table {
            name: "bad.csv".into(),
            text: "v1,range,v2,probability\n28,40,28,1\n28,40,28,0\n".into(),
        }))
        .await
        .unwrap_err()
        .to_string();
    assert!(
        refused.contains("line 3 gives the same point as line 2"),
        "{refused}"
    );
    // A cut-in table with no positive range: a 422 that says so (was a 500).
    let refused = client
        .create_library(&CreateLibrary {
            case: "cut-in".into(),
            preset: None,
            surrogate: serde_json::json!({"model": "idm"}),
            exposure: ExposureRequest::Table {
                name: "behind.csv".into(),
                text: ",-0.4,0\n-1,0.5,0\n0,0.25,0.25\n".into(),
            },
            search: None,
            threshold: None,
        })
        .await
        .unwrap_err();
    let message = refused.to_string();
    assert!(message.contains("422"), "{message}");
    assert!(
        message.contains("behind.csv") && message.contains("positive range"),
        "{message}"
    );
    // One cell at a range of 10⁷ km, where the built-in model's density
    // underflows to 0 on every cell: the library builds (the IDM never
    // fails there) and its note says there is no distance to give (the
    // distance's panic was a 500, and `tslg library build` exited 101).
    let far = build_library(
        &client,
        &CreateLibrary {
            case: "cut-in".into(),
            preset: None,
            surrogate: serde_json::json!({"model": "idm"}),
            exposure: ExposureRequest::Table {
                name: "far.csv".into(),
                text: ",-1\n10000000000,1\n".into(),
            },
            search: Some(tslg_api::SearchRequest::Exhaustive),
            threshold: None,
        },
    )
    .await;
    let note = far.exposure_note.as_deref().unwrap();
    assert!(
        note.contains("far.csv: the built-in model puts no mass on its grid"),
        "{note}"
    );
    assert_eq!(far.size, Some(0), "{far:?}");
}
