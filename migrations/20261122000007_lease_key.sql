-- Each attempt of a lease carries a secret key, handed to its holder only:
-- heartbeats, releases and results must present it, so a worker cannot
-- report on another worker's lease although all share the worker token.
-- Leases from before this migration get a fresh key their old holders do
-- not know: they expire and are handed out again.
ALTER TABLE leases ADD COLUMN key TEXT NOT NULL DEFAULT '';
UPDATE leases SET key = lower(hex(randomblob(16)));
