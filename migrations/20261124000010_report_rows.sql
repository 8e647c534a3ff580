-- Results stored per accepted report (issue 20) instead of a row per event:
-- one row per report with its range, the worker that sent it, and its
-- events packed (api/src/packed.rs: a varint gap per index, the weights
-- through a dictionary when few are distinct, 2 to 10 bytes an event
-- against about 30 for an events row with its index). Reading a million
-- events is then decoding a few megabytes, not a million rows, and the
-- worker of every reported range is known (a worker caught lying has all
-- its results taken back). Rows without events are kept: they say who
-- reported the range.
CREATE TABLE reports (
    campaign_id INTEGER NOT NULL REFERENCES campaigns (id),
    from_index  INTEGER NOT NULL,
    to_index    INTEGER NOT NULL CHECK (to_index > from_index),
    -- The lease reported on; NULL for events moved from the old table.
    lease_id    INTEGER,
    -- Who reported it; '' for events moved from the old table.
    worker      TEXT    NOT NULL,
    events      INTEGER NOT NULL,
    packed      BLOB    NOT NULL,
    PRIMARY KEY (campaign_id, from_index)
) WITHOUT ROWID;
CREATE INDEX reports_by_worker ON reports (worker, campaign_id);

-- The old per-event rows: the coordinator packs them into `reports` at its
-- first start on this schema (the packing is Rust's, not SQL's) and drops
-- the table.
ALTER TABLE events RENAME TO legacy_events;

-- When the current attempt of a lease was handed out (Unix ms) and for how
-- many threads: a report cannot have spent more seconds than the attempt
-- has existed, nor on more threads than it asked for. Leases from before
-- this migration get the loosest bounds.
ALTER TABLE leases ADD COLUMN claimed_at INTEGER NOT NULL DEFAULT 0;
ALTER TABLE leases ADD COLUMN threads INTEGER NOT NULL DEFAULT 4096;
