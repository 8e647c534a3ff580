-- Vehicles that are not bit-reproducible (issue 47). A campaign marked
-- `vehicle_noise` audits its program by statistics: two runs of a test may
-- differ, so a single disagreement decides nothing. Each sampled audit
-- whose two runs differ in whether an event occurred counts for the pair
-- of workers below; a worker whose discordances lean to one side against
-- the other workers (an e-value, docs/statistics.md) is flagged.
ALTER TABLE campaigns ADD COLUMN vehicle_noise INTEGER NOT NULL DEFAULT 0;

-- An audit a worker owes for giving back an audit run (report/dodging.rs):
-- drawn among its unresolved tests, so not by the secret sample alone, and
-- left out of the statistics of noisy programs.
ALTER TABLE audits ADD COLUMN owed INTEGER NOT NULL DEFAULT 0;

CREATE TABLE worker_discordance (
    worker         TEXT NOT NULL,
    partner        TEXT NOT NULL,
    -- Sampled audits of a noisy program run by both.
    compared       INTEGER NOT NULL DEFAULT 0,
    -- Of them: `worker` found an event and `partner` none ...
    own_event      INTEGER NOT NULL DEFAULT 0,
    -- ... and `partner` found an event and `worker` none.
    partner_event  INTEGER NOT NULL DEFAULT 0,
    PRIMARY KEY (worker, partner)
);
