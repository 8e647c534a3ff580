-- Paired regression campaigns: two campaigns drawing the same tests (same
-- seed, library and epsilon), one per vehicle. Each keeps its own estimate;
-- the pair folds the difference of the two vehicles' weighted outcomes over
-- the tests both resolved, and stops both (method/src/paired.rs).
ALTER TABLE campaigns ADD COLUMN paired_with INTEGER;

CREATE TABLE campaign_pairs (
    campaign_a      INTEGER PRIMARY KEY REFERENCES campaigns(id),
    campaign_b      INTEGER NOT NULL UNIQUE REFERENCES campaigns(id),
    indices         INTEGER NOT NULL DEFAULT 0,
    tests           INTEGER NOT NULL DEFAULT 0,
    events_a        INTEGER NOT NULL DEFAULT 0,
    events_b        INTEGER NOT NULL DEFAULT 0,
    discordant      INTEGER NOT NULL DEFAULT 0,
    a_s1            REAL NOT NULL DEFAULT 0,
    a_s2            REAL NOT NULL DEFAULT 0,
    b_s1            REAL NOT NULL DEFAULT 0,
    b_s2            REAL NOT NULL DEFAULT 0,
    d_s1            REAL NOT NULL DEFAULT 0,
    d_s2            REAL NOT NULL DEFAULT 0,
    -- NULL while running; precision, significant, exhausted or cancelled.
    stop            TEXT,
    look_confidence REAL
);
