//! Upgrading: a database of the previous release, with a campaign under
//! way and leases held, is migrated when the new coordinator starts; the
//! campaign then ends with the same answer as an undisturbed run. A
//! database from a newer release (a migration this binary does not know)
//! is refused at start, not silently used.

use crate::support::*;
use sqlx::sqlite::SqliteConnectOptions;
use sqlx::{ConnectOptions, Connection};
use std::path::Path;
use std::process::Command;
use std::time::Duration;
use tslg_api::{CampaignStatus, ResultReport};
use tslg_client::CallError;

/// Undoes the active-lease indexes (migration 20): the leases table as
/// it was before, with its `IN` check and its indexes over every lease,
/// so the migration rebuilds a table that holds a campaign's leases.
const UNDO_ACTIVE_LEASE_INDEXES: [&str; 7] = [
    "CREATE TABLE leases_before (id INTEGER PRIMARY KEY AUTOINCREMENT, \
     campaign_id INTEGER NOT NULL REFERENCES campaigns (id), start_index INTEGER NOT NULL, \
     end_index INTEGER NOT NULL CHECK (end_index > start_index), resume_at INTEGER NOT NULL, \
     attempt INTEGER NOT NULL, worker TEXT NOT NULL, expires_at INTEGER NOT NULL, \
     state TEXT NOT NULL CHECK (state IN ('active', 'done', 'cancelled')), \
     created_at TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')), \
     key TEXT NOT NULL DEFAULT '', claimed_at INTEGER NOT NULL DEFAULT 0, \
     threads INTEGER NOT NULL DEFAULT 4096, audit_id INTEGER REFERENCES audits (id))",
    "INSERT INTO leases_before SELECT * FROM leases",
    "DROP TABLE leases",
    "ALTER TABLE leases_before RENAME TO leases",
    "CREATE INDEX leases_active ON leases (state, expires_at)",
    "CREATE INDEX leases_by_campaign ON leases (campaign_id, state, resume_at)",
    "DELETE FROM _sqlx_migrations WHERE version = 20261130000020",
];

/// Undoes the packed report rows (migration 10): unpacks every report's
/// events into the per-event `events` table of earlier releases, then drops
/// the `reports` table and the leases' attempt columns. What remains is
/// the schema, and the data, an earlier coordinator wrote.
async fn undo_report_rows(database: &Path) {
    let mut conn = SqliteConnectOptions::new()
        .filename(database)
        .connect()
        .await
        .unwrap();
    sqlx::query(
        "CREATE TABLE events (campaign_id INTEGER NOT NULL REFERENCES campaigns (id), \
         test_index INTEGER NOT NULL, weight REAL NOT NULL, \
         PRIMARY KEY (campaign_id, test_index)) WITHOUT ROWID",
    )
    .execute(&mut conn)
    .await
    .unwrap();
    let rows: Vec<(i64, i64, Vec<u8>)> =
        sqlx::query_as("SELECT campaign_id, from_index, packed FROM reports")
            .fetch_all(&mut conn)
            .await
            .unwrap();
    let mut moved = 0;
    for (campaign, from, packed) in rows {
        for (index, weight) in tslg_api::packed::unpack(from as u64, &packed).unwrap() {
            sqlx::query("INSERT INTO events (campaign_id, test_index, weight) VALUES (?, ?, ?)")
                .bind(campaign)
                .bind(index as i64)
                .bind(weight)
                .execute(&mut conn)
                .await
                .unwrap();
            moved += 1;
        }
    }
    assert!(moved > 50, "the campaign has events to move: {moved}");
    for statement in [
        "DROP TABLE reports",
        "ALTER TABLE leases DROP COLUMN claimed_at",
        "ALTER TABLE leases DROP COLUMN threads",
        "DELETE FROM _sqlx_migrations WHERE version = 20261124000010",
        // Later migrations that add to `reports` (and their tables): a
        // release before the report rows had none of them either.
        "DROP TABLE worker_test_evidence",
        "DROP TABLE test_pairing_walks",
        "DELETE FROM _sqlx_migrations WHERE version = 20261207000032",
        "DELETE FROM _sqlx_migrations WHERE version = 20261207000034",
    ] {
        sqlx::query(statement).execute(&mut conn).await.unwrap();
    }
    conn.close().await.unwrap();
}

/// Undoes the migrations of the release before (the lease key, the largest
/// term, the outside bound), leaving the schema of two releases back.
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
    let old_secret = client.secret_of("old").expect("registered");
    drop(worker);
    server.kill();

    // Back to two releases' schemas before, data and held leases kept.
    sql(&database, &UNDO_ACTIVE_LEASE_INDEXES).await;
    undo_report_rows(&database).await;
    sql(&database, &UNDO).await;

    let server = ServerProcess::start(&database, &options);
    let client = server.client();
    client.use_credential("old", &old_secret);
    let migrated = client.campaign(id).await.unwrap();
    assert_eq!(migrated.status, CampaignStatus::Running);
    assert!(migrated.indices >= 100_000);
    // The migrations gave every lease a fresh key (the old holder's is
    // void) and filled the largest term from the stored events, which the
    // final comparison checks bit for bit.
    let report = ResultReport {
        next_lease: None,
        near_misses: Vec::new(),
        worker: "old".into(),
        attempt: held.attempt,
        key: held.key.clone(),
        from: held.resume_at,
        to: held.resume_at + 10,
        events: Vec::new(),
        packed_events: None,
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
    assert!(clean_refusal(&output));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("cannot apply the database migrations"),
        "{stderr}"
    );
    assert!(stderr.contains("29991231000000"), "{stderr}");
}
