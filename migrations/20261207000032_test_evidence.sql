-- Every test is evidence (issue 67). A worker's tests are paired with other
-- workers' tests of the same campaign and stratum (tslg_method::test_pairing);
-- a pair where exactly one found the event is the worker's with probability
-- one half when both run the same program. The counts per pair of workers,
-- apart from the audits' (worker_discordance): an audited test may be in
-- both kinds of pair, and one e-value must not count a run twice.
CREATE TABLE worker_test_evidence (
    worker         TEXT NOT NULL,
    partner        TEXT NOT NULL,
    -- Pairs of a test of `worker`'s and one of `partner`'s ...
    compared       INTEGER NOT NULL DEFAULT 0,
    -- ... where `worker`'s found the event and `partner`'s none ...
    own_event      INTEGER NOT NULL DEFAULT 0,
    -- ... and where `partner`'s found it and `worker`'s none.
    partner_event  INTEGER NOT NULL DEFAULT 0,
    PRIMARY KEY (worker, partner)
);

-- How far each campaign's pairing walked its resolved prefix, and the
-- tests waiting there for a partner (JSON, tslg_method::test_pairing::Walk).
CREATE TABLE test_pairing_walks (
    campaign_id  INTEGER PRIMARY KEY,
    walked_to    INTEGER NOT NULL,
    waiting      TEXT NOT NULL
);

-- How close each test of a report came to the event, for the pairing:
-- the tests whose criticality the worker reported (at most the plan's
-- `criticality_below`), packed as events are (index, criticality rounded
-- to thousandths). NULL when none (adaptive campaigns keep theirs in
-- near_misses).
ALTER TABLE reports ADD COLUMN near_packed BLOB;
