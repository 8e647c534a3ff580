-- User-defined grid cases (POST /api/v1/cases): the case file and its
-- exposure table, registered again at every start-up.
CREATE TABLE user_cases (
    name       TEXT PRIMARY KEY,
    file       TEXT NOT NULL,
    table_name TEXT NOT NULL,
    table_text TEXT NOT NULL,
    created_at TEXT NOT NULL DEFAULT (strftime('%Y-%m-%dT%H:%M:%fZ', 'now'))
);
