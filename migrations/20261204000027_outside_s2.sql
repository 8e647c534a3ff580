-- The within-strata half-width of a guarded Wald campaign (issue 49): the
-- exploring stratum's `S₂,out = Σ (wᵢyᵢ)²`, on the campaign and on each
-- history point. NULL on rows created before it: such a campaign keeps the
-- pooled variance (and the proportional split) to its end, since its sums
-- were never tracked; a new campaign starts at 0.
ALTER TABLE campaigns ADD COLUMN outside_s2 REAL;
ALTER TABLE history ADD COLUMN outside_s2 REAL;
