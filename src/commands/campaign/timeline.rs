//! `tslg campaign timeline ID`: where a campaign's wall time went, as
//! `GET /api/v1/campaigns/{id}/timeline` gives it: its workers busy on it
//! over time, so that idle workers show (docs/operations.md, "Where the
//! time goes").

use crate::args::ServerArgs;
use crate::commands::remote::{block_on, client};

/// Width of the busy bar at the most workers.
const BAR: usize = 40;

/// Prints the timeline of campaign `id` in `buckets` buckets, or its JSON.
pub fn timeline(server: &ServerArgs, id: i64, buckets: u32, json: bool) -> anyhow::Result<()> {
    let client = client(server)?;
    let t = block_on(async { Ok(client.timeline(id, buckets).await?) })?;
    if json {
        outln!("{}", serde_json::to_string_pretty(&t)?);
        return Ok(());
    }
    if t.buckets.is_empty() {
        outln!("campaign {id}: no work reported yet");
        return Ok(());
    }
    outln!(
        "campaign {id}: {:.1} s from its first lease to its last report, {} workers ran its \
         work; busy {:.0}% of their time ({:.1} worker-seconds, {:.1} on audit runs, {} reports)",
        t.seconds,
        t.workers,
        100.0 * t.busy_share,
        t.busy_worker_seconds,
        t.audit_worker_seconds,
        t.reports
    );
    outln!(
        "{:>8} {:>8} {:>7} {:>9} {:>9}  busy workers (# on tests, a on audit runs, of {})",
        "from s",
        "busy",
        "audits",
        "reported",
        "folded",
        t.workers
    );
    let scale = BAR as f64 / f64::from(t.workers.max(1));
    for b in &t.buckets {
        let tests = ((b.busy_workers - b.audit_workers).max(0.0) * scale).round() as usize;
        let audits = (b.audit_workers * scale).round() as usize;
        outln!(
            "{:>8.2} {:>8.1} {:>7.1} {:>9} {:>9}  |{}{}",
            b.from_seconds,
            b.busy_workers,
            b.audit_workers,
            b.reported_tests,
            b.folded,
            "#".repeat(tests.min(BAR)),
            "a".repeat(audits.min(BAR - tests.min(BAR)))
        );
    }
    Ok(())
}
