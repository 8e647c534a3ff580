-- An adaptive campaign's resolved stages, as the dashboard and reports show
-- them (issue 51): where each stage's tests sit among all the campaign's
-- tests, what they found, and the support after it. Written when a stage
-- is resolved, so campaigns whose stages were resolved before this table
-- have rows only for the stages resolved after it.
CREATE TABLE adaptive_stages (
    campaign_id  INTEGER NOT NULL REFERENCES campaigns(id),
    start_index  INTEGER NOT NULL,
    end_index    INTEGER NOT NULL,
    kind         TEXT    NOT NULL,
    events       INTEGER NOT NULL,
    new_failures INTEGER NOT NULL,
    invalid      INTEGER NOT NULL,
    support      INTEGER NOT NULL,
    -- A guarded campaign's estimate starts again after this stage.
    restarts_estimate INTEGER NOT NULL DEFAULT 0,
    PRIMARY KEY (campaign_id, start_index)
) WITHOUT ROWID;
