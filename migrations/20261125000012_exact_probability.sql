-- The exact P(A) of a campaign's vehicle, by enumeration of the grid, where
-- the vehicle is built in and the grid small enough (campaign_start.rs);
-- NULL otherwise and for campaigns created before this column.
ALTER TABLE campaigns ADD COLUMN exact_probability REAL;
