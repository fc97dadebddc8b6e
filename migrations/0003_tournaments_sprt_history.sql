-- Tournaments, SPRTs, per-agent drift and rating history.

-- A tournament: matches queued together (round robin: every pair; gauntlet: the first agent against
-- each of the others), `rounds` times with sides swapped every round.
CREATE TABLE tournaments (
    id                  INTEGER PRIMARY KEY AUTOINCREMENT,
    kind                TEXT NOT NULL CHECK (kind IN ('round_robin', 'gauntlet')),
    -- The agent ids in the order given, as a JSON array (a gauntlet's challenger first).
    agents_json         TEXT NOT NULL,
    rallies_per_match   INTEGER NOT NULL,
    rounds              INTEGER NOT NULL,
    seed                INTEGER NOT NULL,
    created_by          INTEGER REFERENCES tokens (id),
    created_at          TEXT NOT NULL DEFAULT CURRENT_TIMESTAMP
);

-- A sequential probability ratio test between two agents (fishtest-style GSPRT on per-match point
-- shares): matches are played one at a time until the log-likelihood ratio leaves [lower, upper].
CREATE TABLE sprts (
    id                  INTEGER PRIMARY KEY AUTOINCREMENT,
    agent_a             INTEGER NOT NULL REFERENCES agents (id),
    agent_b             INTEGER NOT NULL REFERENCES agents (id),
    elo0                REAL NOT NULL,
    elo1                REAL NOT NULL,
    alpha               REAL NOT NULL,
    beta                REAL NOT NULL,
    rallies_per_match   INTEGER NOT NULL,
    max_matches         INTEGER NOT NULL,
    seed                INTEGER NOT NULL,
    -- running -> accepted_h1 | accepted_h0 | inconclusive | failed | cancelled
    status              TEXT NOT NULL CHECK (status IN ('running', 'accepted_h1', 'accepted_h0', 'inconclusive', 'failed', 'cancelled')),
    llr                 REAL NOT NULL DEFAULT 0,
    matches_done        INTEGER NOT NULL DEFAULT 0,
    created_by          INTEGER REFERENCES tokens (id),
    created_at          TEXT NOT NULL DEFAULT CURRENT_TIMESTAMP,
    finished_at         TEXT
);

ALTER TABLE matches ADD COLUMN tournament_id INTEGER REFERENCES tournaments (id);
-- The submitter token that queued a match (null: the admin, or the server itself); a submitter may
-- cancel only what its token queued.
ALTER TABLE matches ADD COLUMN created_by INTEGER REFERENCES tokens (id);
ALTER TABLE matches ADD COLUMN sprt_id INTEGER REFERENCES sprts (id);
CREATE INDEX matches_tournament ON matches (tournament_id);
CREATE INDEX matches_sprt ON matches (sprt_id);

-- Drift statistics of each side of a finished match: the serves and the crossings that side's
-- returns produced (DESIGN §7).
CREATE TABLE match_drift (
    match_id            INTEGER NOT NULL REFERENCES matches (id),
    side                TEXT NOT NULL CHECK (side IN ('A', 'B')),
    agent_id            INTEGER NOT NULL REFERENCES agents (id),
    crossings           INTEGER NOT NULL,
    in_box_fraction     REAL NOT NULL,
    energy_distance     REAL,
    drift_slope         REAL,
    drift_json          TEXT NOT NULL,
    PRIMARY KEY (match_id, side)
);
CREATE INDEX match_drift_agent ON match_drift (agent_id);

-- Rating history: the Glicko-2 rating of both sides after each finished match, in the order matches
-- finished (written in the transaction that stores the match).
CREATE TABLE rating_history (
    seq                 INTEGER PRIMARY KEY AUTOINCREMENT,
    match_id            INTEGER NOT NULL REFERENCES matches (id),
    agent_id            INTEGER NOT NULL REFERENCES agents (id),
    rating              REAL NOT NULL,
    deviation           REAL NOT NULL,
    volatility          REAL NOT NULL,
    created_at          TEXT NOT NULL DEFAULT CURRENT_TIMESTAMP
);
CREATE INDEX rating_history_agent ON rating_history (agent_id, seq);
