-- Where a campaign's wall time goes (issue 68): one row per piece of work
-- a worker reported, a range of a lease or an audit run, with when its
-- lease attempt was handed out and when the piece was reported (Unix ms).
-- A piece began at its lease's claim or at the lease's previous report,
-- whichever is later (the timeline works it out when read). And when each
-- point of the estimate's history was folded.
CREATE TABLE work_spans (
    campaign_id INTEGER NOT NULL REFERENCES campaigns (id),
    lease_id    INTEGER NOT NULL,
    worker      TEXT    NOT NULL,
    audit       INTEGER NOT NULL CHECK (audit IN (0, 1)),
    from_index  INTEGER NOT NULL,
    to_index    INTEGER NOT NULL CHECK (to_index > from_index),
    leased_at   INTEGER NOT NULL,
    reported_at INTEGER NOT NULL
);
CREATE INDEX work_spans_by_campaign ON work_spans (campaign_id, lease_id, leased_at, from_index);
ALTER TABLE history ADD COLUMN folded_at INTEGER;
-- An adaptive campaign's estimation stages' length, chosen at its creation
-- (100 before this column, and by default for a fleet of up to 20 threads).
ALTER TABLE campaigns ADD COLUMN stage_tests INTEGER NOT NULL DEFAULT 100;
