-- Match workers and the leases of running matches (DESIGN §12). A worker is a process that plays
-- matches: `rally serve`'s own pool or a `rally worker`. It claims a queued match, which then holds a
-- lease that the worker's heartbeat renews; a match whose lease ran out (its worker died or lost the
-- database) is queued again, and a result stored after the lease was lost is refused.
-- Times are Unix milliseconds written by the processes (no engine's date functions).

CREATE TABLE workers (
    id                  INTEGER PRIMARY KEY AUTOINCREMENT,
    name                TEXT NOT NULL UNIQUE,
    host                TEXT NOT NULL,
    pid                 INTEGER NOT NULL,
    -- Matches it plays at once.
    slots               INTEGER NOT NULL,
    started_ms          INTEGER NOT NULL,
    heartbeat_ms        INTEGER NOT NULL,
    matches_played      INTEGER NOT NULL DEFAULT 0,
    -- running | stopped (a worker that died without saying so stays running, its heartbeat old)
    status              TEXT NOT NULL CHECK (status IN ('running', 'stopped'))
);

-- The lease of a running match: its holder (a worker's name), when it runs out, and the claim's
-- number (each claim adds one; a result is stored only under the claim that is current).
ALTER TABLE matches ADD COLUMN worker TEXT;
ALTER TABLE matches ADD COLUMN lease_expires_ms INTEGER;
ALTER TABLE matches ADD COLUMN attempts INTEGER NOT NULL DEFAULT 0;
CREATE INDEX matches_worker ON matches (worker);
