-- An adaptive campaign's search width (issue 68): a search stage of fewer
-- cells is widened by the rings around them up to this many. Chosen at
-- creation from its stage length (stage_tests / 5 above 100, else 0) and
-- stored, so that a campaign created before the widening (0 here) plans
-- the same stages after an upgrade as before it.
ALTER TABLE campaigns ADD COLUMN search_width INTEGER NOT NULL DEFAULT 0;
