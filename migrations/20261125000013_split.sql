-- How a library campaign splits its tests between the library and the
-- outside (sampling.rs, Split): campaigns created before this column drew
-- each test's stratum at random and keep doing so. `strata_epsilon` is the
-- exploring share a stratified campaign's estimate weights its strata by
-- (NULL: the plain mean), written by the fold (store/fold.rs).
ALTER TABLE campaigns ADD COLUMN split TEXT NOT NULL DEFAULT 'random';
ALTER TABLE campaigns ADD COLUMN strata_epsilon REAL;
-- A stratified campaign's history points need the exploring stratum's sums.
ALTER TABLE history ADD COLUMN outside_tests INTEGER NOT NULL DEFAULT 0;
ALTER TABLE history ADD COLUMN outside_s1 REAL NOT NULL DEFAULT 0;
