-- Adaptive campaigns (method `adaptive`, method/src/adaptive.rs). SQLite
-- cannot change the CHECK on campaigns.method in place, so an adaptive
-- campaign is stored with method 'library' (its tests start from a
-- library) and adaptive = 1, and read back as 'adaptive'
-- (server/src/store/campaigns.rs, COLUMNS).
ALTER TABLE campaigns ADD COLUMN adaptive INTEGER NOT NULL DEFAULT 0;
-- The running stage's tests [stage_start, stage_end) and kind: no lease
-- reaches past stage_end until every test of the stage has its result and
-- the next stage is planned from them (NULL for other methods).
ALTER TABLE campaigns ADD COLUMN stage_start INTEGER;
ALTER TABLE campaigns ADD COLUMN stage_end INTEGER;
ALTER TABLE campaigns ADD COLUMN stage_kind TEXT;
-- Tests of the library stage and of the searches, stages resolved, and the
-- cells the estimation samples besides its exploring share.
ALTER TABLE campaigns ADD COLUMN library_tests INTEGER NOT NULL DEFAULT 0;
ALTER TABLE campaigns ADD COLUMN search_tests INTEGER NOT NULL DEFAULT 0;
ALTER TABLE campaigns ADD COLUMN stages INTEGER NOT NULL DEFAULT 0;
ALTER TABLE campaigns ADD COLUMN support INTEGER NOT NULL DEFAULT 0;
-- An external program's near misses, as its worker reported them: the plan
-- of an adaptive campaign's next stage reads them.
CREATE TABLE near_misses (
    campaign_id INTEGER NOT NULL REFERENCES campaigns(id),
    test_index  INTEGER NOT NULL,
    criticality REAL    NOT NULL,
    PRIMARY KEY (campaign_id, test_index)
) WITHOUT ROWID;
