-- One vote per principal (issue 67). An administrator issues enrolment
-- credentials, one per principal (a host, an operator, a cluster job);
-- a worker registering with one belongs to that principal. Audits,
-- quorums and the statistical evidence count principals, not names, and a
-- flag sticks to the principal: registering again does not shed it. Only
-- the SHA-256 of an enrolment secret is kept.
CREATE TABLE enrolments (
    principal   TEXT PRIMARY KEY,
    secret_hash TEXT NOT NULL UNIQUE,
    issued_at   TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    revoked_at  TEXT
);

-- The principal a worker registered under; NULL: the worker is its own
-- principal (registered with the shared worker token alone).
ALTER TABLE worker_credentials ADD COLUMN principal TEXT;
CREATE INDEX worker_credentials_by_principal ON worker_credentials (principal);

-- Principals flagged with one of their workers: every worker of theirs,
-- now or later, is refused.
CREATE TABLE flagged_principals (
    principal  TEXT PRIMARY KEY,
    reason     TEXT NOT NULL,
    flagged_at TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);
