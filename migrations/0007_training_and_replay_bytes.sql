-- An agent's training provenance — its checkpoint's `training` section (JSON text, `null` when it has
-- none) — kept apart from the spec, so that its page reads a few kilobytes instead of the whole
-- checkpoint. NULL: not extracted yet (agents stored before this column; the server fills them in
-- when it opens the store).
ALTER TABLE agents ADD COLUMN training_json TEXT;
-- The compressed replay frames a match keeps, bytes (its `replays` rows): what it counts against
-- its submitter's replay quota.
ALTER TABLE matches ADD COLUMN replay_bytes INTEGER NOT NULL DEFAULT 0;
UPDATE matches SET replay_bytes = COALESCE((SELECT SUM(LENGTH(frames_gz)) FROM replays WHERE replays.match_id = matches.id), 0);
-- A token's stored replays are summed at every match it asked for.
CREATE INDEX matches_created_by ON matches (created_by);
