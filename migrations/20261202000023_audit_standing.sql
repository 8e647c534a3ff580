-- Audits that cannot be dodged (issue 47). A worker that gives back an
-- audit's run, or lets it expire, is counted here; while it owes an audit
-- of its own results (`owed_audit`, open) it gets no new range, and the
-- share of its tests audited doubles with every run given back in a row
-- (all of them past three). Running an audit clears the streak.
CREATE TABLE worker_audit_standing (
    worker         TEXT PRIMARY KEY,
    dodged_in_row  INTEGER NOT NULL DEFAULT 0,
    dodged         INTEGER NOT NULL DEFAULT 0,
    owed_audit     INTEGER REFERENCES audits (id),
    updated_at     TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);
