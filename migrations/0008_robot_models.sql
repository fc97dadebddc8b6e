-- The robot each agent plays and each match is played with: `default` (the shipped robot) or
-- `myochallenge` (MyoSuite's, once imported). Agents and matches stored before were the shipped
-- robot's. Leaderboards, ratings and continuous mode are per robot.
ALTER TABLE agents ADD COLUMN model TEXT NOT NULL DEFAULT 'default';
ALTER TABLE matches ADD COLUMN model TEXT NOT NULL DEFAULT 'default';
CREATE INDEX matches_model_status ON matches (model, status);
