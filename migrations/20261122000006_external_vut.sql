-- A campaign of an external vehicle under test requires a worker offering
-- that program for the case and mode: 'NAME:case:mode'. NULL for built-in
-- vehicles, which every worker runs.
ALTER TABLE campaigns ADD COLUMN requires TEXT;
