-- Anytime-valid intervals (issue 49). A campaign reads either the normal
-- interval (`wald`) or a confidence sequence (`anytime`); an anytime
-- campaign's fold stores the sequence's interval as of its last settlement,
-- and each history point the interval it had there (NULL for `wald`).
ALTER TABLE campaigns ADD COLUMN interval TEXT NOT NULL DEFAULT 'wald';
ALTER TABLE campaigns ADD COLUMN sequence_low REAL;
ALTER TABLE campaigns ADD COLUMN sequence_high REAL;
ALTER TABLE history ADD COLUMN sequence_low REAL;
ALTER TABLE history ADD COLUMN sequence_high REAL;
