-- The evidence of tests is kept per campaign (issue 67): campaigns that
-- reuse a seed (a gate run every night, the two campaigns of a pair) draw
-- the same tests again, so their pairs repeat and are no new evidence; one
-- e-process per campaign stays a test martingale, and a worker is flagged
-- at 10^4 in any one of them (a false flag at most once in 10^4 honest
-- worker-campaigns).
DROP TABLE worker_test_evidence;
CREATE TABLE worker_test_evidence (
    campaign_id    INTEGER NOT NULL,
    worker         TEXT NOT NULL,
    partner        TEXT NOT NULL,
    compared       INTEGER NOT NULL DEFAULT 0,
    own_event      INTEGER NOT NULL DEFAULT 0,
    partner_event  INTEGER NOT NULL DEFAULT 0,
    PRIMARY KEY (campaign_id, worker, partner)
);

-- A report made on a lease handed out again (its earlier holder gave it
-- back or let it expire, perhaps after seeing outcomes) is left out of the
-- pairing: which tests it holds may depend on outcomes.
ALTER TABLE reports ADD COLUMN handed_again INTEGER NOT NULL DEFAULT 0;
