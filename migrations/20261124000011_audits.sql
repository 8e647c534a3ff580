-- Results checked by replication (issue 20), in the manner of BOINC's
-- validation by redundancy. A test of an external program chosen for an
-- audit (a secret sample, and every event that would carry a large share
-- of the estimate) is run again by a different worker; the campaign's
-- prefix does not pass it until two workers agree. A disagreement is
-- settled by a third worker, and the worker in the minority is flagged:
-- it gets no more work and every result it reported is taken back and run
-- again by others.
CREATE TABLE audits (
    id              INTEGER PRIMARY KEY AUTOINCREMENT,
    campaign_id     INTEGER NOT NULL REFERENCES campaigns (id),
    test_index      INTEGER NOT NULL,
    -- 'sample': drawn by the coordinator's secret key; 'weight': an event
    -- carrying at least the configured share of the estimate.
    reason          TEXT    NOT NULL CHECK (reason IN ('sample', 'weight')),
    -- 'replica': waits for a second run; 'tiebreak': two runs disagree and
    -- a third decides; 'agreed'; 'settled': the third decided and the
    -- minority was flagged; 'void': the first run was taken back with its
    -- worker; 'undecided': three runs, three outcomes; 'past': still open
    -- when the campaign stopped before its test.
    state           TEXT    NOT NULL CHECK (state IN
                        ('replica', 'tiebreak', 'agreed', 'settled', 'void', 'undecided', 'past')),
    -- Outcomes: 'none', 'invalid' or 'event:' and the weight's 16 hex digits.
    first_worker    TEXT    NOT NULL,
    first_outcome   TEXT    NOT NULL,
    replica_worker  TEXT,
    replica_outcome TEXT,
    third_worker    TEXT,
    third_outcome   TEXT,
    -- The lease of the run under way, if one is.
    lease_id        INTEGER,
    created_at      TEXT    NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    UNIQUE (campaign_id, test_index)
);
CREATE INDEX audits_open ON audits (state, campaign_id, test_index);

-- Workers caught reporting what others could not reproduce: refused every
-- request until an operator clears them.
CREATE TABLE flagged_workers (
    name        TEXT PRIMARY KEY,
    reason      TEXT NOT NULL,
    campaign_id INTEGER,
    test_index  INTEGER,
    flagged_at  TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);

-- An audit's run is a lease of one test.
ALTER TABLE leases ADD COLUMN audit_id INTEGER REFERENCES audits (id);
-- Tests chosen for an audit that nobody else could run (no other live
-- worker offered the program when they were reported).
ALTER TABLE campaigns ADD COLUMN audits_waived INTEGER NOT NULL DEFAULT 0;
-- The weights of every event recorded so far, folded or not: what "a share
-- of the estimate" is measured against when choosing events to audit (the
-- folded sum stalls while the prefix waits for audits).
ALTER TABLE campaigns ADD COLUMN reported_s1 REAL NOT NULL DEFAULT 0;
