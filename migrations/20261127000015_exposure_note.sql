-- What the user should know about how a library's exposure table was read:
-- its total variation distance from the case's built-in model, and whether
-- its sum was renormalised (NULL for the built-in model).
ALTER TABLE libraries ADD COLUMN exposure_note TEXT;
