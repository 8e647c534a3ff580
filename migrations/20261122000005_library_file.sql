-- Library files are bytes in the case's own format: JSON for the grid cases,
-- a compact binary Q-table for car-following. `media_type` says which.
ALTER TABLE libraries ADD COLUMN file BLOB;
ALTER TABLE libraries ADD COLUMN media_type TEXT;
UPDATE libraries SET file = CAST(body AS BLOB), media_type = 'application/json'
    WHERE body IS NOT NULL;
ALTER TABLE libraries DROP COLUMN body;
