//! The Kubernetes manifests of `deploy/kubernetes` (issue 48): every
//! resource validates against Kubernetes' schemas, and what the schemas
//! cannot check holds against a real coordinator: KEDA's `valueLocation`
//! finds a number in its `GET /api/v1/queue`, the HPA's metric is a series
//! of its `/metrics`, every `TSLG_*` variable a container sets is read by
//! the binary it runs (`scripts/check-kubernetes`, with PyPI's
//! kubernetes-validate from `scripts/install-test-deps`).

use crate::support::*;
use std::collections::BTreeSet;
use std::path::Path;
use std::process::Command;
use tslg_api::{CreateCampaign, Method};

/// `TSLG_*` variables set by the manifests, by the command they run.
fn manifest_variables() -> (BTreeSet<String>, BTreeSet<String>) {
    let (mut server, mut worker) = (BTreeSet::new(), BTreeSet::new());
    for entry in std::fs::read_dir(repo_path("deploy/kubernetes")).unwrap() {
        let text = std::fs::read_to_string(entry.unwrap().path()).unwrap();
        let mut command = "";
        for line in text.lines() {
            let line = line.trim();
            if let Some(c) = line.strip_prefix("command: [\"") {
                command = c.split('"').next().unwrap_or("");
            }
            if let Some(name) = line.strip_prefix("- name: TSLG_") {
                let set = if command == "tslg-server" {
                    &mut server
                } else {
                    &mut worker
                };
                set.insert(format!("TSLG_{name}"));
            }
        }
    }
    (server, worker)
}

#[test]
fn every_variable_a_manifest_sets_is_read_by_the_binary_it_runs() {
    let (server, worker) = manifest_variables();
    assert!(server.contains("TSLG_DATABASE_URL") && worker.contains("TSLG_VUT_EXEC"));
    for (binary, variables) in [
        (env!("CARGO_BIN_EXE_tslg-server"), server),
        (env!("CARGO_BIN_EXE_tslg-worker"), worker),
    ] {
        let out = Command::new(binary).arg("--help").output().unwrap();
        let help = String::from_utf8_lossy(&out.stdout);
        for variable in variables {
            // `[env: NAME]` or `[env: NAME=value]`: the whole name.
            assert!(
                help.contains(&format!("env: {variable}]"))
                    || help.contains(&format!("env: {variable}=")),
                "{binary} does not read {variable}"
            );
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_manifests_validate_and_their_autoscalers_read_what_the_coordinator_serves() {
    let python = Path::new(&repo_path("target/k8s-venv/bin/python")).to_owned();
    assert!(
        python.exists(),
        "{} is missing: run scripts/install-test-deps",
        python.display()
    );
    let dir = scratch();
    let server = ServerProcess::start(&dir.path().join("db.sqlite"), &[]);
    let client = server.client();
    // A campaign of the example program's name, which no worker serves,
    // and one of a built-in vehicle: the queue has an entry of each.
    let request = CreateCampaign {
        library_id: None,
        vut: serde_json::json!({"external": "my-av", "mode": "episode"}),
        ..campaign(Method::Ndd, 0, "idm", 0.2, 1)
    };
    client.create_campaign(&request).await.unwrap();
    let builtin = CreateCampaign {
        library_id: None,
        ..campaign(Method::Ndd, 0, "idm", 0.2, 1)
    };
    client.create_campaign(&builtin).await.unwrap();
    let answer = |query: &'static str| {
        let url = format!("{}/api/v1/queue{query}", server.url);
        async move { reqwest::get(url).await.unwrap().text().await.unwrap() }
    };
    let files = [
        ("queue.json", answer("").await),
        ("builtin.json", answer("?program=builtin").await),
        ("my-av.json", answer("?program=my-av").await),
        ("metrics", client.metrics().await.unwrap()),
    ];
    for (name, text) in &files {
        std::fs::write(dir.path().join(name), text).unwrap();
    }
    let file = |name: &str| dir.path().join(name).display().to_string();
    let out = Command::new(&python)
        .arg(repo_path("scripts/check-kubernetes"))
        .args(["--queue", &file("queue.json")])
        .args([
            "--program-queue",
            &format!("builtin={}", file("builtin.json")),
        ])
        .args(["--program-queue", &format!("my-av={}", file("my-av.json"))])
        .args(["--metrics", &file("metrics")])
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{said}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(said.contains("validated against Kubernetes"), "{said}");
    eprintln!("{said}");
}
