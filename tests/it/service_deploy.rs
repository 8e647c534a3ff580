//! The deployment contract of `docker-compose.yml`: the coordinator and the
//! workers are configured only through the environment variables the
//! compose file sets, tokens are enforced, and the health check command
//! works. (No container engine runs in CI; this is what the containers run.)

use crate::support::*;
use std::collections::BTreeSet;
use std::process::{Command, Stdio};
use std::time::Duration;
use tslg_api::{CampaignStatus, Method};
use tslg_client::{CallError, Client};

const ADMIN: &str = "admin-secret-4f1c";
const WORKER: &str = "worker-secret-9a2e";

/// `TSLG_*` variables that `docker-compose.yml` sets for its services.
fn compose_variables() -> BTreeSet<String> {
    let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docker-compose.yml"))
        .expect("docker-compose.yml");
    text.lines()
        .filter_map(|line| {
            let key = line.trim().split(':').next()?;
            (key.starts_with("TSLG_") && key.chars().all(|c| c.is_ascii_uppercase() || c == '_'))
                .then(|| key.to_owned())
        })
        .collect()
}

fn help(binary: &str) -> String {
    let out = Command::new(binary).arg("--help").output().expect("--help");
    assert!(out.status.success());
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn every_variable_the_compose_file_sets_is_read_by_the_binary_it_is_set_for() {
    let variables = compose_variables();
    for expected in [
        "TSLG_BIND",
        "TSLG_DATABASE_URL",
        "TSLG_ADMIN_TOKEN",
        "TSLG_WORKER_TOKEN",
        "TSLG_SERVER",
    ] {
        assert!(
            variables.contains(expected),
            "compose file lacks {expected}"
        );
    }
    let server = help(env!("CARGO_BIN_EXE_tslg-server"));
    let worker = help(env!("CARGO_BIN_EXE_tslg-worker"));
    for variable in &variables {
        let read = format!("[env: {variable}");
        assert!(
            server.contains(&read) || worker.contains(&read),
            "{variable} is set in docker-compose.yml but read by neither binary"
        );
    }
}

/// A worker configured as in the compose file; `stderr` captured or dropped.
fn worker_from_env(url: &str, token: &str, name: &str, stderr: Stdio) -> std::process::Child {
    Command::new(env!("CARGO_BIN_EXE_tslg-worker"))
        .env("TSLG_SERVER", url)
        .env("TSLG_WORKER_TOKEN", token)
        .env("TSLG_WORKER_NAME", name)
        .env("TSLG_THREADS", "1")
        .env("TSLG_MAX_BACKOFF", "0.3")
        .stdout(Stdio::null())
        .stderr(stderr)
        .spawn()
        .expect("start tslg-worker")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_coordinator_and_workers_configured_from_the_environment_enforce_tokens_and_converge() {
    let dir = scratch();
    let database = dir.path().join("db.sqlite");
    let mut command = Command::new(env!("CARGO_BIN_EXE_tslg-server"));
    command
        .env("TSLG_BIND", "127.0.0.1:0")
        .env(
            "TSLG_DATABASE_URL",
            format!("sqlite://{}", database.display()),
        )
        .env("TSLG_ADMIN_TOKEN", ADMIN)
        .env("TSLG_WORKER_TOKEN", WORKER);
    let server = ServerProcess::spawn(command, &database);

    // The compose health check.
    let health = Command::new(env!("CARGO_BIN_EXE_tslg"))
        .args(["health", "--server", &server.url])
        .output()
        .unwrap();
    assert!(health.status.success(), "{health:?}");
    assert!(String::from_utf8_lossy(&health.stdout).starts_with("ok"));

    // Without a token, or with the worker's, nobody starts work.
    let request = || {
        let mut r = campaign(Method::Ndd, 0, "idm", 0.2, 3);
        r.library_id = None;
        r
    };
    for token in [None, Some(WORKER.to_owned())] {
        let refused = Client::new(&server.url, token)
            .unwrap()
            .create_campaign(&request())
            .await;
        assert!(
            matches!(refused, Err(CallError::Refused { status: 401, .. })),
            "{refused:?}"
        );
    }

    // A worker with the wrong token stops with a clear message.
    let wrong = worker_from_env(&server.url, "not-the-token", "intruder", Stdio::piped());
    let out = wait_within(wrong, Duration::from_secs(30));
    assert!(clean_refusal(&out));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("refused this worker's token"), "{stderr}");

    // Right tokens: the campaign converges on the environment-configured workers.
    let mut workers = [
        worker_from_env(&server.url, WORKER, "w1", Stdio::null()),
        worker_from_env(&server.url, WORKER, "w2", Stdio::null()),
    ];
    let admin = Client::new(&server.url, Some(ADMIN.to_owned())).unwrap();
    let id = admin.create_campaign(&request()).await.unwrap().id;
    let view = finished(&admin, id, Duration::from_secs(120)).await;
    assert_eq!(view.status, CampaignStatus::Converged, "{view:?}");
    let exact = exact("idm");
    assert!(view.ci_low.unwrap() <= exact && exact <= view.ci_high.unwrap());
    for worker in &mut workers {
        let _ = worker.kill();
        let _ = worker.wait();
    }
}

#[test]
fn a_worker_refuses_a_coordinator_of_another_release() {
    use std::io::{Read, Write};
    // A stand-in coordinator that answers every request as another release.
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let url = format!("http://{}", listener.local_addr().unwrap());
    std::thread::spawn(move || {
        for stream in listener.incoming() {
            let Ok(mut stream) = stream else { break };
            let mut request = [0u8; 4096];
            let _ = stream.read(&mut request);
            let body = r#"{"status":"ok","version":"0.0.1-elsewhere"}"#;
            let _ = write!(
                stream,
                "HTTP/1.1 200 OK\r\ncontent-type: application/json\r\ncontent-length: {}\r\n\
                 connection: close\r\n\r\n{body}",
                body.len()
            );
        }
    });
    let worker = worker_from_env(&url, WORKER, "w-old", Stdio::piped());
    let out = wait_within(worker, Duration::from_secs(30));
    assert!(clean_refusal(&out));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("the coordinator runs tslg 0.0.1-elsewhere")
            && stderr.contains("upgrade workers and coordinator together"),
        "{stderr}"
    );
}

/// Both services run the image the Dockerfile builds (each can build it:
/// `docker compose up --build` of either service alone works), and that
/// image's runtime stage carries what the documented external vehicles
/// need: python3 and the examples, at the path the compose file's worker
/// comment names. This reads the files; building the image and running
/// an example in it is [`the_image_builds_and_runs_the_python_example`].
#[test]
fn both_services_use_the_built_image_whose_runtime_stage_has_python_and_the_examples() {
    let root = env!("CARGO_MANIFEST_DIR");
    let compose = std::fs::read_to_string(format!("{root}/docker-compose.yml")).unwrap();
    let mut services = Vec::new();
    let mut current: Option<(String, bool, bool)> = None;
    for line in compose.lines() {
        let indent = line.len() - line.trim_start().len();
        let text = line.trim();
        if indent == 2 && text.ends_with(':') && !text.starts_with('#') {
            services.extend(current.take());
            current = Some((text.trim_end_matches(':').to_owned(), false, false));
        } else if indent == 0 && !text.is_empty() && !text.starts_with('#') {
            services.extend(current.take());
        } else if let Some((_, image, build)) = &mut current {
            *image |= text == "image: tslg:latest";
            *build |= text == "build: .";
        }
    }
    services.extend(current);
    let names: Vec<&str> = services.iter().map(|s| s.0.as_str()).collect();
    assert!(
        names.contains(&"coordinator") && names.contains(&"worker"),
        "{names:?}"
    );
    for (name, image, build) in &services {
        if name == "coordinator" || name == "worker" {
            assert!(
                *image && *build,
                "service {name}: image {image}, build {build}"
            );
        }
    }
    let dockerfile = std::fs::read_to_string(format!("{root}/Dockerfile")).unwrap();
    let runtime = dockerfile.rsplit("FROM ").next().unwrap();
    assert!(runtime.contains("python3"), "{runtime}");
    assert!(
        runtime.contains("COPY --from=build /src/examples /usr/local/share/tslg/examples"),
        "{runtime}"
    );
    let named = "/usr/local/share/tslg/examples/python/idm_vut.py";
    assert!(compose.contains(named));
    let local = named.replace("/usr/local/share/tslg/", &format!("{root}/"));
    assert!(std::path::Path::new(&local).exists(), "{local}");
}

/// The image builds from the Dockerfile and runs the Python example the
/// compose file's worker comment names. It needs a Docker engine: where
/// none runs (this workplace's machines), the test says SKIPPED with the
/// reason `docker-engine`, which `.ci/allowed-skips` lists.
#[test]
fn the_image_builds_and_runs_the_python_example() {
    let engine = Command::new("docker")
        .arg("info")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !engine {
        tslg_testkit::skip(
            "docker-engine",
            "no Docker engine answers `docker info`: the image is not built",
        );
        return;
    }
    let root = env!("CARGO_MANIFEST_DIR");
    let mut build = Command::new("docker");
    build.args(["build", "-q", "-t", "tslg:test", root]);
    let built = output_within(build, COMMAND_LIMIT);
    assert!(
        built.status.success(),
        "{}",
        String::from_utf8_lossy(&built.stderr)
    );
    let mut run = Command::new("docker");
    run.args(["run", "--rm", "--entrypoint", "python3", "tslg:test"])
        .args(["/usr/local/share/tslg/examples/python/idm_vut.py", "--help"]);
    let ran = output_within(run, Duration::from_secs(120));
    assert!(
        ran.status.success() && String::from_utf8_lossy(&ran.stdout).contains("usage: idm_vut.py"),
        "{ran:?}"
    );
}
