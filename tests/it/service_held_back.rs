//! Noisy programs held back from the design of the rule for noisy
//! vehicles (issue 66): written after the rule was fixed (the guard by
//! default, its allocation, the support grown by failures only), and run
//! here as a user runs them, through the coordinator and workers. The
//! interval a user is shown (the view's `answer`) must cover the program's
//! own P(A), worked out by `tslg exact --program` from its runs on every
//! cell, in at least 8 campaigns of 10 (docs/statistics.md, "Noisy
//! vehicles"). Their tests against the NDD's are printed, not asserted:
//! on these programs the rule does not reach a third of the NDD's tests
//! (the radar ACC needs about 0.8 of them in `tslg validate`'s 200 seeds,
//! the distracted driver 1.9 times them), which issue 66 leaves open.
//! The distracted driver's 45,000 tests a campaign are too many for a
//! debug build's service: `tslg validate --vut-exec` measures it.

use crate::support::*;
use std::process::Command;
use std::time::Duration;
use tslg_api::{CampaignView, CreateCampaign, Method};

/// The program's P(A) and the NDD's expected tests at β 0.2, from
/// `tslg exact --program NAME=PATH` (40 runs of every cell).
fn truth(name: &str, path: &std::path::Path) -> (f64, f64) {
    let out = Command::new(env!("CARGO_BIN_EXE_tslg"))
        .args([
            "exact",
            "--beta",
            "0.2",
            "--program-runs",
            "40",
            "--program",
            &format!("{name}={}", path.display()),
        ])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let row: Vec<&str> = stdout
        .lines()
        .find(|l| l.starts_with(name))
        .unwrap_or_else(|| panic!("no row for {name} in {stdout}"))
        .split_whitespace()
        .collect();
    (row[1].parse().unwrap(), row[3].parse().unwrap())
}

/// Ten adaptive campaigns of program `example` (default settings: the
/// guard is on because the program says it is noisy) on the IDM's
/// library, run by two workers: how many answers cover, and the median
/// tests run.
async fn ten_campaigns(example: &str) -> (usize, u64, f64, f64, Vec<CampaignView>) {
    let program = example_binary(example);
    let name = example.trim_end_matches("_vut").replace('_', "-");
    let (probability, ndd) = truth(&name, &program);
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &["--lease-size", "200"]);
    let client = server.client();
    let library = ready_library(&client, "idm", true).await;
    let exec = format!("{name}={}", program.display());
    let _workers: Vec<WorkerProcess> = ["held-1", "held-2"]
        .iter()
        .map(|worker| WorkerProcess::start_with(&server.url, 1, worker, &["--vut-exec", &exec]))
        .collect();
    let mut ids = Vec::new();
    for seed in 1..=10 {
        let request = CreateCampaign {
            vut: serde_json::json!({"external": name, "mode": "episode"}),
            vehicle_noise: true,
            guard_outside: None,
            ..campaign(Method::Adaptive, library.id, "idm", 0.2, seed)
        };
        ids.push(client.create_campaign(&request).await.unwrap().id);
    }
    let mut views = Vec::new();
    for id in ids {
        views.push(finished(&client, id, Duration::from_secs(1500)).await);
    }
    let covered = views
        .iter()
        .filter(|v| {
            let a = v.answer.as_ref().expect("a stopped campaign's answer");
            a.low <= probability && probability <= a.high
        })
        .count();
    let mut tests: Vec<u64> = views.iter().map(|v| v.indices).collect();
    tests.sort_unstable();
    let median = (tests[4] + tests[5]) / 2;
    (covered, median, probability, ndd, views)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn held_back_noisy_programs_get_answers_that_cover() {
    for example in ["radar_acc_vut", "distracted_driver_vut"] {
        let (covered, median, probability, ndd, views) = ten_campaigns(example).await;
        for v in &views {
            let a = v.answer.as_ref().unwrap();
            eprintln!(
                "{example} campaign {}: {:?}, {} tests, estimate {:.4e}, answer {} [{:.4e}, {:.4e}]",
                v.id,
                v.status,
                v.indices,
                v.estimate.unwrap_or(f64::NAN),
                a.interval.as_str(),
                a.low,
                a.high
            );
            assert_eq!(v.status, tslg_api::CampaignStatus::Converged, "{v:?}");
            // The program says it is noisy: the campaign ran under the
            // guard and answers with the guarded interval.
            assert!(v.guard_outside, "{example}: not guarded by default");
            assert_eq!(a.interval, tslg_api::AnswerInterval::Guarded);
        }
        eprintln!(
            "{example}: P(A) {probability:.4e}, {covered}/10 cover, median {median} tests, NDD \
             {ndd:.0} ({:.1}×)",
            ndd / median as f64
        );
        // The project's coverage plan (`tslg_testkit::coverage_floor`): a
        // method covering at the nominal 0.9 fails it on at most 1 % of
        // seed sets. Ten campaigns give a floor of 6; a floor of 8, as
        // before, failed a sound method 7 % of the time (the radar program
        // covered 7 of 10 in one CI run, 9 of 10 in others).
        let floor = tslg_testkit::coverage_floor(10, 0.9, 0.01) as usize;
        assert!(
            covered >= floor,
            "{example}: {covered}/10 answers cover {probability:.4e} (floor {floor})"
        );
    }
}
