-- How a library campaign spreads its exploration share ε outside the
-- library: 'uniform' (the paper's form) or 'ndd' (in proportion to P(x)).
ALTER TABLE campaigns ADD COLUMN outside TEXT NOT NULL DEFAULT 'uniform';
