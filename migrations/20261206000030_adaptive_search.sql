-- How an adaptive campaign searches (issue 54): `grid` (every neighbour of
-- a seed once) or `lattice` (a fine grid's coarser lattice, whole blocks
-- into the support). Campaigns created before this column searched the grid.
ALTER TABLE campaigns ADD COLUMN adaptive_search TEXT NOT NULL DEFAULT 'grid';
