-- The largest weighted term max wᵢyᵢ of a campaign's resolved prefix, kept
-- with the power sums for the importance-sampling health figures (the
-- largest weight's share of the estimate). Filled from the stored events.
ALTER TABLE campaigns ADD COLUMN largest REAL NOT NULL DEFAULT 0;
UPDATE campaigns SET largest = COALESCE(
    (SELECT MAX(weight) FROM events e
      WHERE e.campaign_id = campaigns.id AND e.test_index < campaigns.indices),
    0);
