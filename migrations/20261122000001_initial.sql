-- The coordinator's state. Storage grows with libraries, campaigns, leases,
-- events and invalid tests, never with the number of tests: a test without
-- the event is recorded only as part of a lease's reported range.

CREATE TABLE libraries (
    id                   INTEGER PRIMARY KEY AUTOINCREMENT,
    case_name            TEXT    NOT NULL,
    preset               TEXT    NOT NULL,
    status               TEXT    NOT NULL CHECK (status IN ('building', 'ready', 'failed')),
    -- The build request as JSON, so a restarted coordinator can build again.
    request              TEXT    NOT NULL,
    surrogate            TEXT    NOT NULL,
    exposure_name        TEXT    NOT NULL,
    exposure_fingerprint TEXT    NOT NULL,
    -- An uploaded exposure table; NULL for the case's built-in exposure.
    exposure_table       TEXT,
    total_scenarios      INTEGER NOT NULL,
    -- The library file (format tslg-library) once ready.
    body                 TEXT,
    size                 INTEGER,
    sm_evaluations       INTEGER,
    mu_s                 REAL,
    w                    REAL,
    build_seconds        REAL,
    error                TEXT,
    created_at           TEXT    NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);

CREATE TABLE campaigns (
    id                   INTEGER PRIMARY KEY AUTOINCREMENT,
    case_name            TEXT    NOT NULL,
    preset               TEXT    NOT NULL,
    method               TEXT    NOT NULL CHECK (method IN ('library', 'ndd')),
    library_id           INTEGER REFERENCES libraries (id),
    exposure_name        TEXT    NOT NULL,
    exposure_fingerprint TEXT    NOT NULL,
    exposure_table       TEXT,
    vut                  TEXT    NOT NULL,
    epsilon              REAL    NOT NULL,
    beta                 REAL    NOT NULL,
    confidence           REAL    NOT NULL,
    n_min                INTEGER NOT NULL,
    min_events           INTEGER NOT NULL,
    max_tests            INTEGER NOT NULL,
    -- The u64 seed's bits as a signed integer.
    seed                 INTEGER NOT NULL,
    status               TEXT    NOT NULL CHECK (status IN
                             ('pending', 'running', 'converged', 'exhausted', 'cancelled', 'failed')),
    status_detail        TEXT,
    -- Leasing cursor: indices 0..next_index have been handed out.
    next_index           INTEGER NOT NULL DEFAULT 0,
    -- The prefix estimator over the resolved indices 0..indices.
    indices              INTEGER NOT NULL DEFAULT 0,
    tests                INTEGER NOT NULL DEFAULT 0,
    events               INTEGER NOT NULL DEFAULT 0,
    invalid              INTEGER NOT NULL DEFAULT 0,
    s1                   REAL    NOT NULL DEFAULT 0,
    s2                   REAL    NOT NULL DEFAULT 0,
    -- Smoothed seconds per test on one thread, for lease sizing.
    cost_per_test        REAL,
    -- Unix milliseconds of the last lease handed out, for fair sharing.
    last_leased_at       INTEGER NOT NULL DEFAULT 0,
    created_at           TEXT    NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now')),
    updated_at           TEXT    NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);

CREATE INDEX campaigns_running ON campaigns (status, last_leased_at);

CREATE TABLE leases (
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
    state       TEXT    NOT NULL CHECK (state IN ('active', 'done', 'cancelled')),
    created_at  TEXT    NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);

CREATE INDEX leases_active ON leases (state, expires_at);
CREATE INDEX leases_by_campaign ON leases (campaign_id, state, resume_at);

CREATE TABLE events (
    campaign_id INTEGER NOT NULL REFERENCES campaigns (id),
    test_index  INTEGER NOT NULL,
    weight      REAL    NOT NULL,
    PRIMARY KEY (campaign_id, test_index)
) WITHOUT ROWID;

CREATE TABLE invalid_tests (
    campaign_id INTEGER NOT NULL REFERENCES campaigns (id),
    test_index  INTEGER NOT NULL,
    reason      TEXT    NOT NULL,
    PRIMARY KEY (campaign_id, test_index)
) WITHOUT ROWID;

-- One point per fold that moved the resolved prefix.
CREATE TABLE history (
    campaign_id INTEGER NOT NULL REFERENCES campaigns (id),
    indices     INTEGER NOT NULL,
    tests       INTEGER NOT NULL,
    events      INTEGER NOT NULL,
    s1          REAL    NOT NULL,
    s2          REAL    NOT NULL,
    PRIMARY KEY (campaign_id, indices)
) WITHOUT ROWID;
