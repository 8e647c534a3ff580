-- Worker identities (issue 47): a worker registers under the fleet's worker
-- token and gets a secret of its own; every lease request, heartbeat,
-- release, report and upload that names it must present that secret. A
-- name is issued once: a second registration of a name gets the next free
-- `NAME.k`, so a worker's results, audits and flags (all keyed by name)
-- belong to one credential, and nobody can take over a name to have its
-- owner flagged. Only the SHA-256 of the secret is kept.
CREATE TABLE worker_credentials (
    name        TEXT PRIMARY KEY,
    secret_hash TEXT NOT NULL,
    issued_at   TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    revoked_at  TEXT
);
