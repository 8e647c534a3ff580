-- The allocation of issue 49: a stratified campaign whose library stratum is
-- known switches to exploring nearly every test from test `explore_from` on
-- (NULL until it switches). Tests before it keep their strata; leases say it,
-- so that workers draw as the coordinator does.
ALTER TABLE campaigns ADD COLUMN explore_from INTEGER;
