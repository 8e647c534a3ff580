-- What one test of a vehicle costs on one thread, in seconds, kept across
-- campaigns: a program (`key` = `NAME:case:mode`) or a built-in vehicle on
-- a case (`case|preset|vehicle JSON`). A campaign starts from it, so its
-- first leases are sized in seconds of work; where there is none, a lease
-- holds one test per thread until the first report measures it.
CREATE TABLE test_costs (
    key        TEXT PRIMARY KEY,
    seconds    REAL NOT NULL CHECK (seconds > 0),
    updated_at TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);
