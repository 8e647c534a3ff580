//! Skips said aloud, and the shared fixtures found in one place.

use std::io::Write;
use std::path::PathBuf;

/// Records that the running test skipped (all of it, or the part that
/// needs what is missing): `reason` is a short key (`authors-table`,
/// `sumo`, `slurm`, `docker-engine`) that `.ci/allowed-skips` may list,
/// `detail` what is missing and how to provide it.
///
/// Prints `SKIPPED [reason] test: detail` to stderr and appends the same
/// fields, tab-separated, to the file `TSLG_SKIP_LOG` names (created when
/// missing; lines are short, so concurrent tests' appends do not mix).
pub fn skip(reason: &str, detail: &str) {
    let thread = std::thread::current();
    let test = thread.name().unwrap_or("unnamed test");
    eprintln!("SKIPPED [{reason}] {test}: {detail}");
    if let Some(log) = std::env::var_os("TSLG_SKIP_LOG") {
        let line = format!("{reason}\t{test}\t{}\n", detail.replace(['\n', '\t'], " "));
        let written = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&log)
            .and_then(|mut file| file.write_all(line.as_bytes()));
        if let Err(e) = written {
            panic!(
                "cannot record the skip in TSLG_SKIP_LOG={}: {e}",
                PathBuf::from(log).display()
            );
        }
    }
}

/// The folder of shared reference fixtures: `TSLG_SHARED_DATA` when set,
/// else `../shared/data` beside the workspace.
pub fn shared_data() -> PathBuf {
    std::env::var_os("TSLG_SHARED_DATA").map_or_else(
        || PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/data"),
        PathBuf::from,
    )
}

/// The authors' cut-in exposure table (`cutin_ndd_spmd.csv` in
/// [`shared_data`]), or `None` after a [`skip`] with reason
/// `authors-table`: it is a reference fixture, not part of the product.
pub fn authors_table() -> Option<PathBuf> {
    let path = shared_data().join("cutin_ndd_spmd.csv");
    if path.is_file() {
        Some(path)
    } else {
        skip(
            "authors-table",
            &format!(
                "needs the authors' cut-in table at {}: set TSLG_SHARED_DATA to the folder \
                 that holds cutin_ndd_spmd.csv",
                path.display()
            ),
        );
        None
    }
}
