-- Submitter tokens (issued by the admin with POST /api/v1/tokens). Only the SHA-256 of a token is kept.
CREATE TABLE tokens (
    id              INTEGER PRIMARY KEY AUTOINCREMENT,
    name            TEXT NOT NULL UNIQUE,
    token_sha256    TEXT NOT NULL UNIQUE,
    created_at      TEXT NOT NULL DEFAULT CURRENT_TIMESTAMP
);

-- Which token submitted an agent (null: the admin, or a built-in).
ALTER TABLE agents ADD COLUMN submitted_by INTEGER REFERENCES tokens (id);
