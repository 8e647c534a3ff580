//! Autoscaling on the queue (issue 48): a loop that reads
//! `workers_wanted` from `GET /api/v1/queue` and starts or stops local
//! workers to match, as KEDA or a SLURM submission loop would, takes a
//! campaign from no worker to its stop, and the fleet back to none.

use crate::support::*;
use std::time::{Duration, Instant};
use tslg_api::{CampaignStatus, Method};

/// The most workers the loop starts (the machine has two cores; the
/// program's tests sleep).
const MAX_WORKERS: u32 = 6;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_autoscaler_on_the_queue_takes_a_campaign_from_no_worker_to_its_stop_and_back() {
    let dir = scratch();
    // The predicted work is to be done within 2 s.
    let server = ServerProcess::start(
        &dir.path().join("db.sqlite"),
        &["--queue-target-seconds", "2"],
    );
    let client = server.client();
    let library = ready_library(&client, "idm", false).await;
    // The FVDM as a program whose every test takes 5 ms (the built-in
    // FVDM's outcomes, test for test).
    let exec = format!(
        "slow={} --sleep 0.005",
        example_binary("fvdm_vut").display()
    );
    let plain = campaign(Method::Ndd, library.id, "fvdm", 0.3, 3);
    let request = tslg_api::CreateCampaign {
        vut: serde_json::json!({"external": "slow", "mode": "episode"}),
        ..plain.clone()
    };
    assert_eq!(client.queue().await.unwrap().workers_wanted, 0, "idle");
    let id = client.create_campaign(&request).await.unwrap().id;
    let mut fleet: Vec<WorkerProcess> = Vec::new();
    let (mut started, mut peak, mut wanted_most) = (0, 0, 0);
    let begun = Instant::now();
    let view = loop {
        assert!(
            begun.elapsed() < Duration::from_secs(240),
            "the campaign never stopped"
        );
        let view = client.campaign(id).await.unwrap();
        if view.status.is_final() {
            break view;
        }
        // A worker that left by itself (idle) is gone from the fleet, as a
        // finished pod or job is.
        fleet.retain_mut(|w| match w.0.try_wait().unwrap() {
            None => true,
            Some(status) => {
                assert!(status.success(), "a worker's exit: {status}");
                false
            }
        });
        let q = client.queue().await.unwrap();
        let wanted = q.workers_wanted;
        wanted_most = wanted_most.max(wanted);
        let wanted = wanted.min(MAX_WORKERS) as usize;
        while fleet.len() < wanted {
            started += 1;
            fleet.push(WorkerProcess::start_with(
                &server.url,
                1,
                &format!("scaled-{started}"),
                &["--vut-exec", &exec, "--exit-when-idle-seconds", "3"],
            ));
        }
        while fleet.len() > wanted {
            let worker = fleet.pop().expect("a worker to stop");
            let status = tokio::task::spawn_blocking(move || worker.terminate())
                .await
                .unwrap();
            assert!(status.success(), "a worker stopped by SIGTERM: {status}");
        }
        peak = peak.max(fleet.len());
        tokio::time::sleep(Duration::from_millis(500)).await;
    };
    assert_eq!(view.status, CampaignStatus::Converged, "{view:?}");
    // Whatever the fleet did, the answer is the campaign's.
    assert_same(&view, &in_process(None, &plain));
    // It scaled out beyond one worker once the work was sized...
    assert!(
        wanted_most > 1 && peak > 1,
        "wanted {wanted_most}, peak {peak}"
    );
    // ... and back to none: nothing wanted, and every worker leaves by
    // itself once idle.
    assert_eq!(client.queue().await.unwrap().workers_wanted, 0);
    let left = Instant::now();
    for mut worker in fleet {
        let limit = Duration::from_secs(60).saturating_sub(left.elapsed());
        let status = worker.exit_status(limit).await;
        assert!(status.success(), "an idle worker's exit: {status}");
    }
    eprintln!("scaled to {peak} workers (wanted at most {wanted_most}), {started} started");
}
