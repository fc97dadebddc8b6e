-- muscle-rally tournament storage (SQLite dialect, kept portable to PostgreSQL: no SQLite-only types).

CREATE TABLE agents (
    id              INTEGER PRIMARY KEY AUTOINCREMENT,
    name            TEXT NOT NULL UNIQUE,
    kind            TEXT NOT NULL CHECK (kind IN ('scripted', 'checkpoint')),
    -- The scripted variant's name, or the checkpoint's JSON.
    spec            TEXT NOT NULL,
    -- Digest of the checkpoint JSON (or of the scripted name), so a match can be re-simulated.
    spec_hash       TEXT NOT NULL,
    builtin         INTEGER NOT NULL DEFAULT 0,
    created_at      TEXT NOT NULL DEFAULT CURRENT_TIMESTAMP,
    -- Qualification: single-serve P2 episodes.
    qual_episodes   INTEGER,
    hit_rate        REAL,
    success_rate    REAL,
    effort          REAL
);

CREATE TABLE matches (
    id              INTEGER PRIMARY KEY AUTOINCREMENT,
    agent_a         INTEGER NOT NULL REFERENCES agents (id),
    agent_b         INTEGER NOT NULL REFERENCES agents (id),
    rallies         INTEGER NOT NULL,
    seed            INTEGER NOT NULL,
    preset          TEXT NOT NULL,
    sim_version     TEXT NOT NULL,
    spec_hash_a     TEXT NOT NULL,
    spec_hash_b     TEXT NOT NULL,
    -- Whether replay frames are stored (continuous-mode matches keep none: they are re-simulated).
    keep_replay     INTEGER NOT NULL DEFAULT 1,
    -- queued -> running -> done | failed | cancelled; a running match whose process died is re-queued.
    status          TEXT NOT NULL CHECK (status IN ('queued', 'running', 'done', 'failed', 'cancelled')),
    created_at      TEXT NOT NULL DEFAULT CURRENT_TIMESTAMP,
    started_at      TEXT,
    finished_at     TEXT,
    points_a        INTEGER,
    points_b        INTEGER,
    mean_rally_length REAL,
    max_rally_length  INTEGER,
    in_box_fraction REAL,
    energy_distance REAL,
    drift_slope     REAL,
    drift_json      TEXT,
    error           TEXT
);

CREATE INDEX matches_status ON matches (status);
CREATE INDEX matches_agent_a ON matches (agent_a);
CREATE INDEX matches_agent_b ON matches (agent_b);

CREATE TABLE rallies (
    match_id        INTEGER NOT NULL REFERENCES matches (id),
    idx             INTEGER NOT NULL,
    server          TEXT NOT NULL,
    length          INTEGER NOT NULL,
    end_reason      TEXT NOT NULL,
    failing_side    TEXT,
    duration        REAL NOT NULL,
    PRIMARY KEY (match_id, idx)
);

CREATE TABLE crossings (
    match_id        INTEGER NOT NULL REFERENCES matches (id),
    rally_idx       INTEGER NOT NULL,
    seq             INTEGER NOT NULL,
    receiver        TEXT NOT NULL,
    exchange        INTEGER NOT NULL,
    y_r             REAL NOT NULL,
    z               REAL NOT NULL,
    in_box          INTEGER NOT NULL,
    extrapolated    INTEGER NOT NULL,
    PRIMARY KEY (match_id, rally_idx, seq)
);

CREATE TABLE replays (
    match_id        INTEGER NOT NULL REFERENCES matches (id),
    rally_idx       INTEGER NOT NULL,
    -- The rally's frames as gzip-compressed JSON.
    frames_gz       BLOB NOT NULL,
    PRIMARY KEY (match_id, rally_idx)
);

-- Submitter tokens are not stored yet: the admin token (config or RALLY_ADMIN_TOKEN) guards submissions.
