-- The outside guard (issue 9): what a library campaign's exploring tests
-- (the ε share drawn outside the library) found, and the upper confidence
-- bound on the failure mass outside the library they give. outside_upper is
-- NULL until the coordinator has counted the exploring tests of the resolved
-- prefix: for campaigns started before this migration it counts them again
-- (replaying each test's draw) at their next fold.
ALTER TABLE campaigns ADD COLUMN guard_outside INTEGER NOT NULL DEFAULT 0;
ALTER TABLE campaigns ADD COLUMN outside_tests INTEGER NOT NULL DEFAULT 0;
ALTER TABLE campaigns ADD COLUMN outside_events INTEGER NOT NULL DEFAULT 0;
ALTER TABLE campaigns ADD COLUMN outside_s1 REAL NOT NULL DEFAULT 0;
-- Of those events, the ones in scenarios where the library's surrogate has
-- no event (the vehicle fails where the surrogate does not).
ALTER TABLE campaigns ADD COLUMN outside_mismatches INTEGER NOT NULL DEFAULT 0;
ALTER TABLE campaigns ADD COLUMN outside_upper REAL;
