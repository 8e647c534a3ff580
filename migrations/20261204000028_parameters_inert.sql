-- Whether the vehicle's parameters that differ from its model's defaults
-- change no accident of the preset (its exact P(A) equals the defaults', to
-- the bit): the view says so once (issue 50). NULL where it was not checked
-- (no exact answer, no such parameters, or created before this column).
ALTER TABLE campaigns ADD COLUMN parameters_inert INTEGER;
