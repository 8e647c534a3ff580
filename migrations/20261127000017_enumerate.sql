-- Library builds whose surrogate is a program run on workers as campaigns
-- of method `enumerate` (test i: the surrogate on the i-th cell with
-- exposure; library_id: the library being built). SQLite cannot change the
-- CHECK on campaigns.method in place, so such a campaign is stored with
-- method 'ndd' and enumerate = 1, and read back as 'enumerate'.
ALTER TABLE campaigns ADD COLUMN enumerate INTEGER NOT NULL DEFAULT 0;
