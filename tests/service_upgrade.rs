//! Upgrading: a database made by an earlier release (every migration but
//! the newest applied) is migrated when the new coordinator starts and then
//! serves campaigns; a database from a newer release (a migration this
//! binary does not know) is refused at start, not silently used.

mod support;

use sqlx::migrate::Migrator;
use sqlx::sqlite::SqliteConnectOptions;
use sqlx::{ConnectOptions, Connection};
use std::path::Path;
use std::process::Command;
use std::time::Duration;
use support::*;
use tslg_api::{CampaignStatus, Method};

const MIGRATIONS: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/migrations");

async fn connect(database: &Path) -> sqlx::SqliteConnection {
    SqliteConnectOptions::new()
        .filename(database)
        .create_if_missing(true)
        .connect()
        .await
        .unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_database_of_the_previous_release_is_migrated_and_one_of_a_newer_is_refused() {
    let dir = scratch();
    // The previous release's schema: every migration but the newest.
    let mut names: Vec<_> = std::fs::read_dir(MIGRATIONS)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    names.sort();
    let old = dir.path().join("old-migrations");
    std::fs::create_dir(&old).unwrap();
    for name in &names[..names.len() - 1] {
        std::fs::copy(Path::new(MIGRATIONS).join(name), old.join(name)).unwrap();
    }
    let database = dir.path().join("db.sqlite");
    let mut conn = connect(&database).await;
    Migrator::new(old.as_path())
        .await
        .unwrap()
        .run(&mut conn)
        .await
        .unwrap();
    conn.close().await.unwrap();

    let server = ServerProcess::start(&database, &[]);
    let client = server.client();
    let _worker = WorkerProcess::start(&server.url, 1, "w1");
    let library = ready_library(&client, "idm", true).await;
    let request = campaign(Method::Library, library.id, "idm", 0.2, 7);
    let id = client.create_campaign(&request).await.unwrap().id;
    let view = finished(&client, id, Duration::from_secs(120)).await;
    assert_eq!(view.status, CampaignStatus::Converged);
    assert_same(&view, &in_process(Some("idm"), &request));
    drop(server);

    let mut conn = connect(&database).await;
    let applied: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM _sqlx_migrations WHERE success")
        .fetch_one(&mut conn)
        .await
        .unwrap();
    assert_eq!(
        applied as usize,
        names.len(),
        "the new migration was applied"
    );
    // A newer release's migration: this binary must not touch the file.
    sqlx::query(
        "INSERT INTO _sqlx_migrations (version, description, success, checksum, execution_time) \
         VALUES (29991231000000, 'from the future', TRUE, x'00', 0)",
    )
    .execute(&mut conn)
    .await
    .unwrap();
    conn.close().await.unwrap();
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
