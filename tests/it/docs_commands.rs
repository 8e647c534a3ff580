//! Every command the docs show, run as written. Each `sh` block of
//! README.md and docs/*.md is extracted and run in order, one bash session
//! per document (so `cd`, `alias` and ids carry from line to line as they do
//! for a reader), in a scratch directory that links the repository's
//! `examples/` and `scripts/`, against a real coordinator: the one the
//! document starts itself (README) or one this test starts (with the
//! document's port and `TSLG_SERVER` pointing at it). What a fresh clone
//! cannot do in CI is listed in [`NOT_RUN`] with the reason, and an entry
//! that no longer matches a doc line fails the test: a doc cannot drift
//! from what runs without this file saying so.
//!
//! The only rewrites: `target/release/` is the test build's `target/debug/`
//! (the same code, built once), `cargo build --release` is skipped for the
//! same reason, the coordinator's port is a free one, `http://coordinator`
//! is this machine, the authors' table is found beside the repository (the
//! lines that read it are skipped, with a message, where it is not), and a
//! wait for the coordinator to answer follows a line that starts one in the
//! background (a reader types more slowly than a script).

use crate::support::*;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Doc lines not run, by the document and a piece of the line, with why.
#[rustfmt::skip]
const NOT_RUN: &[(&str, &str, &str)] = &[
    ("README.md", "cargo run --release -- demo", "the demo: cli.rs runs tslg demo"),
    ("README.md", "scripts/test", "CI itself: .ci/run runs it"),
    ("README.md", "tslg reproduce --ndd-table", "10 minutes of CPU; the --quick line above it runs"),
    ("README.md", "--replicates 200 --n-min", "minutes of CPU; the other validate lines run"),
    ("docs/operations.md", "docker compose up", "no Docker engine here"),
    ("docs/operations.md", "TSLG_SERVER=http://127.0.0.1:8080 tslg campaign start", "needs the compose coordinator above"),
    ("docs/operations.md", "openssl rand", "tokens for the compose coordinator above"),
    ("docs/operations.md", "tslg campaign timeline 1", "a campaign run to its end; service_slow.rs runs the command on one"),
    ("docs/reproduction.md", "reproduce --ndd-table ../shared/data/cutin_ndd_spmd.csv          #", "5 minutes of CPU; README's --quick runs"),
    ("docs/reproduction.md", "reproduce --quick", "README's same line runs"),
    ("docs/adaptive-design.md", "--replicates", "the study behind the design: minutes to hours of CPU each"),
    ("docs/statistics.md", "--replicates 2000", "the coverage study: minutes of CPU each"),
    ("docs/statistics.md", "--interval wald,anytime", "the Wald/anytime study: minutes of CPU; cli.rs runs validate --interval"),
    ("docs/statistics.md", "cargo bench", "a benchmark (scripts/bench)"),
    ("docs/statistics.md", "--program-runs 1000", "3,420 cells run 1,000 times: minutes of CPU; cli.rs checks a noisy vehicle's floor"),
    ("docs/benchmarks.md", "scripts/bench", "benchmarks: minutes on a quiet machine, never in CI"),
    ("docs/benchmarks.md", "cargo bench", "benchmarks: minutes on a quiet machine, never in CI"),
    ("docs/bring-your-own.md", "git clone", "this is the clone"),
    ("docs/bring-your-own.md", "tslg-server --library-builds workers", "the coordinator this test starts for the document runs with it"),
    ("docs/bring-your-own.md", "sumo", "SUMO: service_sumo.rs runs these steps with target/sumo-venv"),
];

/// Coordinator options a document's commands rely on, when this test
/// starts its coordinator.
fn coordinator_options(doc: &str) -> &'static [&'static str] {
    match doc {
        "docs/bring-your-own.md" => &["--library-builds", "workers"],
        _ => &[],
    }
}

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Where a block starts in [`commands`]' list: a reader starts each block
/// from the repository's root.
const BLOCK: &str = "\0block";

/// The commands of a document's `sh` blocks, continuation lines joined,
/// comment lines dropped, each block opened by [`BLOCK`].
fn commands(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut in_block = false;
    let mut pending = String::new();
    for line in text.lines() {
        let fence = line.trim_start().strip_prefix("```");
        match (in_block, fence) {
            (false, Some(lang)) => {
                in_block = matches!(lang.trim(), "sh" | "bash");
                if in_block {
                    out.push(BLOCK.to_owned());
                }
            }
            (true, Some(_)) => in_block = false,
            (true, None) => {
                let line = line.trim();
                if pending.is_empty() && (line.is_empty() || line.starts_with('#')) {
                    continue;
                }
                match line.strip_suffix('\\') {
                    Some(start) => pending.push_str(start),
                    None => {
                        pending.push_str(line);
                        out.push(std::mem::take(&mut pending));
                    }
                }
            }
            (false, None) => {}
        }
    }
    out
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), target).unwrap();
        }
    }
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// The document's commands as one bash script, and the skip entries used.
fn script(doc: &str, lines: &[String], url: &str, used: &mut Vec<usize>) -> String {
    let repo = repo();
    let debug = format!("{}/target/debug/", repo.display());
    let table_dir = tslg_testkit::shared_data();
    let mut script = String::from("set -euo pipefail\nshopt -s expand_aliases\n");
    for line in lines {
        if line == BLOCK {
            script.push_str("cd \"$DOC_ROOT\"\n");
            continue;
        }
        if let Some(k) = NOT_RUN
            .iter()
            .position(|(d, piece, _)| *d == doc && line.contains(piece))
        {
            used.push(k);
            script.push_str(&format!(
                "echo {} >&2\n",
                shell_quote(&format!("# not run ({}): {line}", NOT_RUN[k].2))
            ));
            continue;
        }
        // The test build has the same binaries and examples.
        if line.trim().starts_with("cargo build --release") {
            continue;
        }
        if line.contains("../shared/data/") && !table_dir.join("cutin_ndd_spmd.csv").is_file() {
            tslg_testkit::skip(
                "authors-table",
                &format!(
                    "{doc}: `{line}` needs the authors' table in {} (TSLG_SHARED_DATA)",
                    table_dir.display()
                ),
            );
            continue;
        }
        let port = url.rsplit(':').next().unwrap();
        let command = line
            .replace("cargo build --release && ", "")
            .replace("$PWD/target/release/", &debug)
            .replace("target/release/", &debug)
            .replace("127.0.0.1:8080", &format!("127.0.0.1:{port}"))
            .replace("http://coordinator:8080", url)
            .replace("../shared/data/", &format!("{}/", table_dir.display()));
        for built in command.split(&format!("{debug}examples/")).skip(1) {
            let name = built
                .split(|c: char| c.is_whitespace() || c == '"' || c == '\'')
                .next()
                .unwrap_or_default();
            built_example(&format!("{doc}: `{line}`"), name);
        }
        script.push_str(&format!(
            "echo \"[$SECONDS s]\" {} >&2\n",
            shell_quote(&format!("+ {command}"))
        ));
        script.push_str(&command);
        script.push('\n');
        if command.trim_end().ends_with('&') && command.contains("tslg-server") {
            script.push_str(
                "for i in $(seq 100); do tslg health >/dev/null 2>&1 && break; sleep 0.2; done\n",
            );
        }
    }
    script
}

fn shell_quote(text: &str) -> String {
    format!("'{}'", text.replace('\'', "'\\''"))
}

/// Runs `script` in `dir` in a process group of its own, killing the group
/// (the background coordinator and workers) when it ends or overruns.
fn run(doc: &str, script: &str, dir: &Path, url: &str, limit: Duration) {
    let path = format!(
        "{}/target/debug:{}",
        repo().display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let log = dir.join("doc.log");
    let mut child = Command::new("bash")
        .arg("-c")
        .arg(script)
        .current_dir(dir)
        .env("PATH", path)
        .env("TSLG_SERVER", url)
        .env("DOC_ROOT", dir)
        .env_remove("TSLG_NDD_TABLE")
        .stdin(Stdio::null())
        .stdout(std::fs::File::create(dir.join("doc.out")).unwrap())
        .stderr(std::fs::File::create(&log).unwrap())
        .process_group(0)
        .spawn()
        .expect("bash runs");
    let group = child.id();
    let started = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break Some(status);
        }
        if started.elapsed() > limit {
            break None;
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    // The whole group: the background coordinator and workers too.
    let _ = Command::new("kill")
        .args(["-KILL", "--", &format!("-{group}")])
        .status();
    let _ = child.wait();
    let said = std::fs::read_to_string(&log).unwrap_or_default();
    let tail: Vec<&str> = said.lines().rev().take(40).collect();
    let tail: Vec<&str> = tail.into_iter().rev().collect();
    match status {
        // Each command with the second it started at, for a slow doc.
        Some(s) if s.success() => said
            .lines()
            .filter(|l| l.starts_with('[') || l.starts_with("# not run"))
            .for_each(|l| eprintln!("{doc} {l}")),
        Some(s) => panic!("{doc}: a command failed ({s}):\n{}", tail.join("\n")),
        None => panic!("{doc}: still running after {limit:?}:\n{}", tail.join("\n")),
    }
}

#[test]
fn every_command_the_docs_show_runs_as_written() {
    let repo = repo();
    let mut docs = vec!["README.md".to_owned()];
    let mut more: Vec<String> = std::fs::read_dir(repo.join("docs"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|name| name.ends_with(".md"))
        .map(|name| format!("docs/{name}"))
        .collect();
    more.sort();
    docs.extend(more);
    let mut used = Vec::new();
    for doc in &docs {
        let lines = commands(&std::fs::read_to_string(repo.join(doc)).unwrap());
        if lines.is_empty() {
            continue;
        }
        let dir = scratch();
        // The examples copied (commands write beside them), the scripts
        // linked.
        copy_dir(&repo.join("examples"), &dir.path().join("examples"));
        std::os::unix::fs::symlink(repo.join("scripts"), dir.path().join("scripts")).unwrap();
        let started = Instant::now();
        // A document that starts its coordinator gets a free port for it;
        // the others one started here.
        let starts_its_own = lines.iter().any(|l| l.contains("tslg-server --bind"));
        let (server, url) = if starts_its_own {
            (None, format!("http://127.0.0.1:{}", free_port()))
        } else {
            let server = ServerProcess::start(
                &dir.path().join("coordinator.sqlite"),
                coordinator_options(doc),
            );
            let url = server.url.clone();
            (Some(server), url)
        };
        let script = script(doc, &lines, &url, &mut used);
        run(doc, &script, dir.path(), &url, Duration::from_secs(600));
        drop(server);
        eprintln!(
            "{doc}: {} commands in {:.1?}",
            lines.len(),
            started.elapsed()
        );
    }
    for (k, (doc, piece, _)) in NOT_RUN.iter().enumerate() {
        assert!(
            used.contains(&k),
            "NOT_RUN lists `{piece}` in {doc}, which no longer has that line"
        );
    }
}

/// docs/api.md's example of a library is what a coordinator of this build
/// answers for the default library, field by field (it showed 2136
/// surrogate runs and μ_S 0.00094 when the build gave 2135 and 9.326e-4):
/// only the build time and the date may differ.
#[test]
fn the_api_example_is_what_the_coordinator_answers() {
    let text = std::fs::read_to_string(repo().join("docs/api.md")).unwrap();
    let start = text
        .find("`GET /api/v1/libraries/{id}`:")
        .expect("the library example");
    let block = &text[start..];
    let open = block.find("```json\n").unwrap() + "```json\n".len();
    let close = open + block[open..].find("```").unwrap();
    let example: serde_json::Value =
        serde_json::from_str(&block[open..close]).expect("the example is JSON");
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let o = tslg(&[
        "library",
        "create",
        "--server",
        &server.url,
        "--wait",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let answer: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let fields = example.as_object().unwrap();
    assert!(fields.len() >= 15, "{fields:?}");
    for (key, value) in fields {
        if ["build_seconds", "created_at"].contains(&key.as_str()) {
            assert!(answer.get(key).is_some(), "{key}");
            continue;
        }
        assert_eq!(answer.get(key), Some(value), "docs/api.md's `{key}`");
    }
}

/// Every Markdown table of the docs has as many cells in each row as in its
/// header: a row with one more (an empty column left behind) or a `|` in a
/// formula (GitHub splits cells at it, code spans too, unless it is
/// written `\|`) renders shifted.
#[test]
fn every_docs_table_row_has_its_header_s_cells() {
    let separators = |line: &str| -> usize {
        let bytes = line.as_bytes();
        (0..bytes.len())
            .filter(|&k| bytes[k] == b'|' && (k == 0 || bytes[k - 1] != b'\\'))
            .count()
    };
    let mut docs: Vec<PathBuf> = std::fs::read_dir(repo().join("docs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    docs.push(repo().join("README.md"));
    let mut wrong = Vec::new();
    for doc in &docs {
        let text = std::fs::read_to_string(doc).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        let mut k = 0;
        while k + 1 < lines.len() {
            let delimiter = lines[k + 1];
            let is_table = lines[k].starts_with('|')
                && delimiter.starts_with("|-")
                && delimiter
                    .chars()
                    .all(|c| matches!(c, '|' | '-' | ':' | ' '));
            if !is_table {
                k += 1;
                continue;
            }
            let cells = separators(lines[k]);
            let mut row = k + 2;
            while row < lines.len() && lines[row].starts_with('|') {
                if separators(lines[row]) != cells {
                    wrong.push(format!("{}:{}", doc.display(), row + 1));
                }
                row += 1;
            }
            k = row;
        }
    }
    assert!(
        wrong.is_empty(),
        "rows whose cells differ from their header's: {wrong:?}"
    );
}
