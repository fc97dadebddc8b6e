-- Owners retire agents (DELETE /api/v1/agents/{id}): a retired agent keeps its row, matches and
-- replays, is no longer scheduled or named in new matches, and is hidden from lists by default.
-- NULL: active; else when it was retired (UTC, `YYYY-MM-DD HH:MM:SS`).
ALTER TABLE agents ADD COLUMN retired_at TEXT;
