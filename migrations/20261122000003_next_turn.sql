-- Fair sharing by expected worker time: a campaign's next turn comes when
-- the work of its last lease is expected to be done (Unix ms), not merely
-- after its last lease, so a campaign given a small lease gets its turn back
-- sooner.
ALTER TABLE campaigns RENAME COLUMN last_leased_at TO next_turn_at;
