-- Thread-seconds that workers spent on a campaign's accepted results
-- (compute seconds × threads of each report, prorated to its new tests):
-- what fair sharing between running campaigns is judged by.
ALTER TABLE campaigns ADD COLUMN worker_seconds REAL NOT NULL DEFAULT 0;
