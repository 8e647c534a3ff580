-- Leases: indexes over the active leases only, and a state check without
-- an IN list. Every report moves a lease's resume_at, expires_at and state
-- and every claim inserts one, on the single writer; done leases are never
-- looked up by state again. So:
--   * the indexes that find leases by state hold only the active ones
--     (partial indexes): finished leases leave them instead of piling up,
--     and a report's update touches two small trees;
--   * `CHECK (state IN (...))` built a temporary table of its three values
--     at every insert and every update of the state: the check is the same
--     as a chain of equalities;
--   * leases by campaign (a stopped campaign's cancelled leases, deletion)
--     through an index of the campaign only, which updates never touch.
-- SQLite changes a CHECK only by rebuilding the table; ids, the
-- AUTOINCREMENT sequence and every row are kept.
CREATE TABLE leases_rebuilt (
    id          INTEGER PRIMARY KEY AUTOINCREMENT,
    campaign_id INTEGER NOT NULL REFERENCES campaigns (id),
    start_index INTEGER NOT NULL,
    end_index   INTEGER NOT NULL CHECK (end_index > start_index),
    -- Indices start_index..resume_at have been reported.
    resume_at   INTEGER NOT NULL,
    attempt     INTEGER NOT NULL,
    worker      TEXT    NOT NULL,
    -- Unix milliseconds.
    expires_at  INTEGER NOT NULL,
    state       TEXT    NOT NULL
        CHECK (state = 'active' OR state = 'done' OR state = 'cancelled'),
    created_at  TEXT    NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    key         TEXT    NOT NULL DEFAULT '',
    claimed_at  INTEGER NOT NULL DEFAULT 0,
    threads     INTEGER NOT NULL DEFAULT 4096,
    audit_id    INTEGER REFERENCES audits (id)
);

INSERT INTO leases_rebuilt (id, campaign_id, start_index, end_index, resume_at, attempt,
    worker, expires_at, state, created_at, key, claimed_at, threads, audit_id)
SELECT id, campaign_id, start_index, end_index, resume_at, attempt,
    worker, expires_at, state, created_at, key, claimed_at, threads, audit_id
FROM leases;

-- The sequence goes on from the old table's: a deleted campaign's lease
-- ids are never handed out again.
UPDATE sqlite_sequence
SET seq = MAX(seq, COALESCE((SELECT seq FROM sqlite_sequence WHERE name = 'leases'), 0))
WHERE name = 'leases_rebuilt';
INSERT INTO sqlite_sequence (name, seq)
SELECT 'leases_rebuilt', seq FROM sqlite_sequence
WHERE name = 'leases' AND NOT EXISTS (SELECT 1 FROM sqlite_sequence WHERE name = 'leases_rebuilt');

DROP TABLE leases;
ALTER TABLE leases_rebuilt RENAME TO leases;

-- Expired leases to hand out again, a worker's unstarted leases.
CREATE INDEX leases_active ON leases (expires_at) WHERE state = 'active';
-- The least resume_at of a campaign's active leases (the resolved prefix).
CREATE INDEX leases_open ON leases (campaign_id, resume_at) WHERE state = 'active';
CREATE INDEX leases_by_campaign ON leases (campaign_id);
