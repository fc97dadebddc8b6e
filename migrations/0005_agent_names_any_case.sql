-- Agent names are unique regardless of case (`SCRIPTED` is not a second `scripted`): names are ASCII
-- (letters, digits, '_', '.', '-'), so lower() is the same on both engines. A database written before
-- this rule may hold names that differ only in case: every such agent but the first keeps its rows and
-- is renamed NAME-ID, so that the index can be built.
UPDATE agents SET name = name || '-' || id
WHERE id NOT IN (SELECT MIN(id) FROM agents GROUP BY lower(name));
CREATE UNIQUE INDEX agents_name_any_case ON agents (lower(name));
