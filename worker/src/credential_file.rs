//! The worker's credential kept on disk (`--credential-file`): the name the
//! coordinator issued, its secret and the coordinator it is for. Without
//! it a restarted worker registers again and is issued `NAME.k`, a new
//! identity whose results, flags and standing in audits start afresh; with
//! it a worker on a cluster that requeues or restarts it stays itself.

use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::Path;
use tslg_api::WorkerCredential;

/// What the file holds (JSON).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StoredCredential {
    /// The coordinator the credential was issued by (its base URL).
    pub server: String,
    pub name: String,
    pub secret: String,
    pub issued_at: String,
}

/// The credential in `path` for `server`, if the file exists; an error
/// when it cannot be read, is not a credential, or is another
/// coordinator's.
pub fn load(path: &Path, server: &str) -> anyhow::Result<Option<StoredCredential>> {
    let text = match std::fs::read_to_string(path) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => anyhow::bail!("credential file {}: {e}", path.display()),
    };
    let stored: StoredCredential = serde_json::from_str(&text).map_err(|e| {
        anyhow::anyhow!("credential file {}: not a credential: {e}", path.display())
    })?;
    anyhow::ensure!(
        stored.server.trim_end_matches('/') == server.trim_end_matches('/'),
        "credential file {} is for the coordinator at {}, not {server}: give this worker \
         another file (or remove it to register anew)",
        path.display(),
        stored.server
    );
    Ok(Some(stored))
}

/// Writes `issued` (by `server`) to a new file `path`, readable by its
/// owner only.
pub fn save(path: &Path, server: &str, issued: &WorkerCredential) -> anyhow::Result<()> {
    let stored = StoredCredential {
        server: server.to_owned(),
        name: issued.name.clone(),
        secret: issued.secret.clone(),
        issued_at: issued.issued_at.clone(),
    };
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    std::os::unix::fs::OpenOptionsExt::mode(&mut options, 0o600);
    let mut file = options
        .open(path)
        .map_err(|e| anyhow::anyhow!("credential file {}: {e}", path.display()))?;
    file.write_all(serde_json::to_string_pretty(&stored)?.as_bytes())?;
    file.sync_all()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_saved_credential_loads_for_its_coordinator_only() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("worker.json");
        assert_eq!(load(&path, "http://a:1").unwrap(), None);
        let issued = WorkerCredential {
            name: "w.2".into(),
            secret: "ab".repeat(32),
            issued_at: "2026-11-28T20:00:00.000Z".into(),
            principal: None,
        };
        save(&path, "http://a:1", &issued).unwrap();
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(&path).unwrap().permissions().mode();
            assert_eq!(mode & 0o777, 0o600);
        }
        let loaded = load(&path, "http://a:1/").unwrap().unwrap();
        assert_eq!(
            (loaded.name.as_str(), loaded.secret.as_str()),
            ("w.2", issued.secret.as_str())
        );
        let other = load(&path, "http://b:1").unwrap_err().to_string();
        assert!(
            other.contains("is for the coordinator at http://a:1"),
            "{other}"
        );
        // Never overwritten: a second save fails.
        assert!(save(&path, "http://a:1", &issued).is_err());
        std::fs::write(&path, "{}").unwrap();
        assert!(load(&path, "http://a:1")
            .unwrap_err()
            .to_string()
            .contains("not a credential"));
    }
}
