//! Upgrading: a database of the previous release, with a campaign under
//! way and leases held, is migrated when the new coordinator starts; the
//! campaign then ends with the same answer as an undisturbed run. A
//! database from a newer release (a migration this binary does not know)
//! is refused at start, not silently used.

mod support;

use sqlx::sqlite::SqliteConnectOptions;
use sqlx::{ConnectOptions, Connection};
use std::path::Path;
use std::process::Command;
use std::time::Duration;
use support::*;
use tslg_api::{CampaignStatus, ResultReport};
use tslg_worker::client::CallError;

/// Undoes this release's migrations (the lease key, the largest term, the
/// outside bound), leaving the previous release's schema with its data.
const UNDO: [&str; 11] = [
    "ALTER TABLE leases DROP COLUMN key",
    "ALTER TABLE campaigns DROP COLUMN largest",
    "ALTER TABLE campaigns DROP COLUMN guard_outside",
    "ALTER TABLE campaigns DROP COLUMN outside_tests",
    "ALTER TABLE campaigns DROP COLUMN outside_events",
    "ALTER TABLE campaigns DROP COLUMN outside_s1",
    "ALTER TABLE campaigns DROP COLUMN outside_mismatches",
    "ALTER TABLE campaigns DROP COLUMN outside_upper",
    "DELETE FROM _sqlx_migrations WHERE version = 20261122000007",
    "DELETE FROM _sqlx_migrations WHERE version = 20261122000008",
    "DELETE FROM _sqlx_migrations WHERE version = 20261122000009",
];

async fn sql(database: &Path, statements: &[&str]) {
    let mut conn = SqliteConnectOptions::new()
        .filename(database)
        .connect()
        .await
        .unwrap();
    for statement in statements {
        sqlx::query(statement).execute(&mut conn).await.unwrap();
    }
    conn.close().await.unwrap();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_database_of_the_previous_release_is_migrated_and_one_of_a_newer_is_refused() {
    let dir = scratch();
    let database = dir.path().join("db.sqlite");
    let options = ["--lease-size", "50000", "--lease-ttl-seconds", "2"];
    let MidCampaign {
        server,
        worker,
        request,
        id,
        ..
    } = MidCampaign::start(&database, &options).await;
    let client = server.client();
    let held = claim(&client, "old").await.expect("a lease");
    drop(worker);
    server.kill();

    // Back to the previous release's schema, data and held leases kept.
    sql(&database, &UNDO).await;

    let server = ServerProcess::start(&database, &options);
    let client = server.client();
    let migrated = client.campaign(id).await.unwrap();
    assert_eq!(migrated.status, CampaignStatus::Running);
    assert!(migrated.indices >= 100_000);
    // The migrations gave every lease a fresh key (the old holder's is
    // void) and filled the largest term from the stored events, which the
    // final comparison checks bit for bit.
    let report = ResultReport {
        worker: "old".into(),
        attempt: held.attempt,
        key: held.key.clone(),
        from: held.resume_at,
        to: held.resume_at + 10,
        events: Vec::new(),
        invalid: Vec::new(),
        compute_seconds: 0.0,
        threads: 1,
    };
    let refused = client.report(held.id, &report).await;
    assert!(
        matches!(refused, Err(CallError::Refused { status: 403, .. })),
        "{refused:?}"
    );
    let _worker = WorkerProcess::start(&server.url, 1, "w2");
    let view = finished(&client, id, Duration::from_secs(300)).await;
    assert_eq!(view.status, CampaignStatus::Converged);
    assert_same(&view, &in_process(None, &request));
    drop(server);

    // A newer release's migration: this binary must not touch the file.
    sql(
        &database,
        &["INSERT INTO _sqlx_migrations (version, description, success, checksum, execution_time) \
           VALUES (29991231000000, 'from the future', TRUE, x'00', 0)"],
    )
    .await;
    let output = Command::new(env!("CARGO_BIN_EXE_tslg-server"))
        .args(["--bind", "127.0.0.1:0", "--database-url"])
        .arg(format!("sqlite://{}", database.display()))
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("cannot apply the database migrations"),
        "{stderr}"
    );
    assert!(stderr.contains("29991231000000"), "{stderr}");
}
