-- What deleted campaigns had resolved, so the totals /metrics exports as
-- counters (tslg_tests_resolved_total, tslg_events_total,
-- tslg_invalid_tests_total) never fall when a campaign is deleted: a
-- counter that falls reads to Prometheus as a reset, and rate() would count
-- the whole remaining total again.
CREATE TABLE deleted_totals (
    id      INTEGER PRIMARY KEY CHECK (id = 1),
    indices INTEGER NOT NULL,
    events  INTEGER NOT NULL,
    invalid INTEGER NOT NULL
);
INSERT INTO deleted_totals (id, indices, events, invalid) VALUES (1, 0, 0, 0);
