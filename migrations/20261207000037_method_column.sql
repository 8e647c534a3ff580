-- A campaign's method in one column, by its name (api/src/method.rs):
-- until now an adaptive campaign was stored as method 'library' with
-- adaptive = 1, a build's enumeration as 'ndd' with enumerate = 1 and a
-- whole build as 'ndd' with enumerate = 2, because the initial CHECK on
-- campaigns.method allowed 'library' and 'ndd' alone and SQLite cannot
-- change a CHECK in place. The column is rebuilt without a CHECK (the
-- service refuses a name it does not know when it reads the row), so a new
-- method needs no migration; no index, trigger or key names these columns.
ALTER TABLE campaigns ADD COLUMN method_name TEXT NOT NULL DEFAULT '';
UPDATE campaigns SET method_name = CASE
    WHEN adaptive = 1 THEN 'adaptive'
    WHEN enumerate = 1 THEN 'enumerate'
    WHEN enumerate = 2 THEN 'build'
    ELSE method END;
ALTER TABLE campaigns DROP COLUMN method;
ALTER TABLE campaigns DROP COLUMN adaptive;
ALTER TABLE campaigns DROP COLUMN enumerate;
ALTER TABLE campaigns RENAME COLUMN method_name TO method;
