//! User-defined grid cases (issue 22 part 3), on the command line: a case
//! file (dimensions, an exposure table, a program in episode mode) runs
//! through the same library search, campaigns and exact answers as a
//! built-in case. The shipped example, a Python program simulating the
//! cut-in, reproduces the built-in case: the same library and the same
//! exact P(A), on the built-in exposure and on the authors' table. A case
//! file or program that is wrong fails with the reason.

use crate::support::{clean_refusal, tslg};
use std::path::{Path, PathBuf};

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn example() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("examples/cases/cut-in.toml")
        .to_str()
        .unwrap()
        .to_owned()
}

/// A summary field of `tslg library build` (`library size  286 of …`).
fn field<'a>(out: &'a str, name: &str) -> &'a str {
    out.lines()
        .find_map(|l| l.strip_prefix(name))
        .map(str::trim)
        .unwrap_or_else(|| panic!("no `{name}` in\n{out}"))
}

/// The exact P(A) row of `vehicle` printed by `tslg exact` with `args`.
fn exact(args: &[&str], vehicle: &str) -> String {
    let mut all = vec!["exact"];
    all.extend(args);
    let o = tslg(&all);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let out = text(&o.stdout);
    // With a table `tslg exact` prints the built-in exposure first.
    out.lines()
        .rev()
        .find(|l| l.starts_with(vehicle))
        .and_then(|l| l.split_whitespace().nth(1))
        .unwrap_or_else(|| panic!("no {vehicle} in\n{out}"))
        .to_owned()
}

fn build(args: &[&str]) -> String {
    let mut all = vec!["library", "build"];
    all.extend(args);
    let o = tslg(&all);
    assert!(o.status.success(), "{}", text(&o.stderr));
    text(&o.stdout)
}

#[test]
fn the_example_case_reproduces_the_builtin_cut_in() {
    let dir = tempfile::tempdir().unwrap();
    let out = |name: &str| dir.path().join(name).to_str().unwrap().to_owned();
    let (mine, theirs) = (out("mine.json"), out("theirs.json"));
    let user = build(&["--case-file", &example(), "-o", &mine]);
    let builtin = build(&[
        "--surrogate",
        "idm",
        "--search",
        "exhaustive",
        "-o",
        &theirs,
    ]);
    assert_eq!(field(&user, "case"), "cut-in-py (default)");
    assert_eq!(field(&user, "surrogate"), "cutin-idm");
    assert_eq!(field(&user, "search"), "exhaustive");
    for name in ["library size", "mu_S", "W", "gamma"] {
        assert_eq!(field(&user, name), field(&builtin, name), "{name}");
    }
    // The program's exact P(A), run on every cell, is the built-in IDM's.
    assert_eq!(
        exact(&["--case-file", &example()], "cutin-idm"),
        exact(&[], "idm")
    );
    // Campaigns on the case's library: the program is the vehicle.
    for method in ["library", "adaptive", "ndd"] {
        let o = tslg(&[
            "evaluate",
            "--case-file",
            &example(),
            "--library",
            &mine,
            "--method",
            method,
            "--vut",
            "cutin-idm",
            "--seed",
            "2",
            "--json",
        ]);
        assert!(o.status.success(), "{}", text(&o.stderr));
        let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(r["case"], "cut-in-py");
        assert_eq!(r["vut"]["external"], "cutin-idm");
        let (estimate, half_width, exact) = (
            r["estimate"].as_f64().unwrap(),
            r["half_width"].as_f64().unwrap(),
            r["exact"].as_f64().unwrap(),
        );
        assert!((estimate - exact).abs() < 3.0 * half_width, "{method}: {r}");
    }
    // Its library file describes itself.
    let shown = tslg(&["library", "show", &mine]);
    assert!(shown.status.success(), "{}", text(&shown.stderr));
    assert_eq!(field(&text(&shown.stdout), "case"), "cut-in-py (default)");
    // A library of a user case needs its case file to run campaigns.
    let o = tslg(&["evaluate", "--library", &mine, "--vut", "idm"]);
    assert!(clean_refusal(&o));
    assert!(
        text(&o.stderr).contains("give its --case-file"),
        "{}",
        text(&o.stderr)
    );
}

/// The authors' table in long form, and a case file of its grid beside it.
fn authors_case(dir: &Path) -> Option<PathBuf> {
    let table = tslg_testkit::authors_table()?;
    let matrix = std::fs::read_to_string(&table).unwrap();
    let mut lines = matrix.lines().filter(|l| !l.trim().is_empty());
    let rates: Vec<String> = lines
        .next()?
        .split(',')
        .skip(1)
        .map(str::to_owned)
        .collect();
    let mut long = String::from("range,range_rate,probability\n");
    let mut ranges = Vec::new();
    for line in lines {
        let fields: Vec<&str> = line.split(',').collect();
        ranges.push(fields[0].parse::<f64>().unwrap());
        for (rate, p) in rates.iter().zip(&fields[1..]) {
            long.push_str(&format!("{},{rate},{p}\n", fields[0]));
        }
    }
    let rate = |k: usize| rates[k].parse::<f64>().unwrap();
    let dimension = |name: &str, first: f64, last: f64, n: usize| {
        format!(
            "[[dimensions]]\nname = \"{name}\"\nlower = {first}\nupper = {last}\nstep = {}\n",
            (last - first) / (n - 1) as f64
        )
    };
    std::fs::write(dir.join("authors.csv"), long).unwrap();
    let program = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/cases/cutin_idm.py");
    let file = format!(
        "name = \"cut-in-py\"\nprogram = \"cutin-idm\"\ncommand = \"python3 {}\"\n\
         exposure = \"authors.csv\"\n\n{}\n{}",
        program.display(),
        dimension("range", ranges[0], ranges[ranges.len() - 1], ranges.len()),
        dimension("range_rate", rate(0), rate(rates.len() - 1), rates.len()),
    );
    let path = dir.join("authors.toml");
    std::fs::write(&path, file).unwrap();
    Some(path)
}

#[test]
fn on_the_authors_table_the_case_file_gives_the_184_cell_library_and_the_exact_answer() {
    let dir = tempfile::tempdir().unwrap();
    let Some(case) = authors_case(dir.path()) else {
        return;
    };
    let case = case.to_str().unwrap();
    let lib = dir.path().join("lib.json");
    let out = build(&["--case-file", case, "-o", lib.to_str().unwrap()]);
    assert!(
        field(&out, "library size").starts_with("184 of 3420"),
        "{out}"
    );
    let table = tslg_testkit::authors_table().unwrap();
    assert_eq!(
        exact(&["--case-file", case], "cutin-idm"),
        exact(&["--ndd-table", table.to_str().unwrap()], "idm")
    );
}

#[test]
fn a_wrong_case_file_table_or_program_fails_with_the_reason() {
    let dir = tempfile::tempdir().unwrap();
    let example = std::fs::read_to_string(example()).unwrap();
    let exposure = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/cases/cut-in-exposure.csv");
    let faulty = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/faulty_case.py");
    // The example with its exposure and command made absolute, then edited.
    let written = std::cell::Cell::new(0);
    let case = |edit: &dyn Fn(String) -> String| {
        written.set(written.get() + 1);
        let text = example
            .replace(
                "exposure = \"cut-in-exposure.csv\"",
                &format!("exposure = \"{}\"", exposure.display()),
            )
            .replace(
                "python3 cutin_idm.py",
                &format!("python3 {}", program_path().display()),
            );
        let path = dir.path().join(format!("case{}.toml", written.get()));
        std::fs::write(&path, edit(text)).unwrap();
        path.to_str().unwrap().to_owned()
    };
    let failing = |fault: &'static str| {
        let faulty = faulty.clone();
        move |text: String| {
            text.replace(
                &format!(
                    "command = \"python3 {} cut-in-py\"",
                    program_path().display()
                ),
                &format!("command = \"python3 {} {fault}\"", faulty.display()),
            )
        }
    };
    let out = dir.path().join("x.json");
    let out = out.to_str().unwrap();
    let cases: Vec<(String, Vec<&str>, &str)> = vec![
        (
            case(&|t| t.replacen("step = 2", "step = 0", 1)),
            vec![],
            "dimension 1 (`range`): step = 0 must be > 0",
        ),
        (
            case(&|t| t.replacen("lower = 1\n", "", 1)),
            vec![],
            "missing field `lower`",
        ),
        (
            case(&|t| t.replacen("upper = 89", "upper = 87", 1)),
            vec![],
            "range = 89 is not on the grid (1 to 87 in steps of 2)",
        ),
        // 10¹² × 10²⁰ cells: the count wrapped to 0 and the build aborted.
        (
            case(&|t| {
                t.replacen("upper = 89\nstep = 2", "upper = 1e12\nstep = 1", 1)
                    .replacen("upper = 10\nstep = 0.4", "upper = 1e20\nstep = 1", 1)
            }),
            vec![],
            "the grid has more than 10000000 scenarios",
        ),
        (
            case(&failing("crash")),
            vec![],
            "injected crash at R = 51 m",
        ),
        (case(&failing("garbage")), vec![], "broke the protocol"),
        (case(&failing("bad-criticality")), vec![], "criticality 7"),
        // A timeout no `Duration` holds: refused, not a panic.
        (
            case(&|t| t),
            vec!["--vut-timeout", "1e20"],
            "--vut-timeout 100000000000000000000 must be in (0, 86400] seconds",
        ),
        (
            case(&failing("hang")),
            vec!["--vut-timeout", "1"],
            "gave no answer within the per-test timeout of 1 s",
        ),
    ];
    for (path, extra, expected) in cases {
        let mut args = vec!["library", "build", "--case-file", path.as_str(), "-o", out];
        args.extend(extra);
        let o = tslg(&args);
        // A refusal (1), not a panic (101) or an abort.
        assert_eq!(o.status.code(), Some(1), "{expected}");
        let err = text(&o.stderr);
        assert!(err.contains(expected), "`{expected}` not in\n{err}");
        assert!(!Path::new(out).exists(), "a failed build writes no library");
    }
}

fn program_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/cases/cutin_idm.py")
}
