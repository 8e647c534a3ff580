-- What /healthz writes (issue 67): one row whose time every health check
-- sets through the writer and commits, so that a coordinator whose
-- database cannot be written (locked by another process, read-only, full)
-- answers 503 instead of 200.
CREATE TABLE health_probe (
    id INTEGER PRIMARY KEY CHECK (id = 1),
    at INTEGER NOT NULL
);
INSERT INTO health_probe (id, at) VALUES (1, 0);
