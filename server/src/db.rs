//! Storage: SQLite through sqlx (WAL), the `migrations/` applied at start. Every state change of a match
//! is one transaction. Runtime queries only (no build-time database).

use std::path::Path;
use std::str::FromStr;

use serde::Serialize;
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions};
use sqlx::{FromRow, SqlitePool};

use agents::matchrun::MatchRecord;

/// Opens (creating if needed) the database and applies the migrations.
pub async fn open(path: &Path) -> anyhow::Result<SqlitePool> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    let opts = SqliteConnectOptions::from_str(&format!("sqlite://{}", path.display()))?
        .create_if_missing(true)
        .journal_mode(SqliteJournalMode::Wal)
        .foreign_keys(true)
        .busy_timeout(std::time::Duration::from_secs(10));
    let pool = SqlitePoolOptions::new()
        .max_connections(8)
        .connect_with(opts)
        .await?;
    sqlx::migrate!("../migrations").run(&pool).await?;
    Ok(pool)
}

/// A hex SHA-256-like digest of a spec (FNV-1a 64 over the bytes, printed twice salted; enough to tell
/// checkpoints apart and to recognise the same one again).
pub fn spec_hash(spec: &str) -> String {
    let fnv = |salt: u64| {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325 ^ salt;
        for b in spec.as_bytes() {
            h ^= *b as u64;
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
        h
    };
    format!("{:016x}{:016x}", fnv(0), fnv(0x9e37_79b9_7f4a_7c15))
}

/// Registers the scripted variants as built-in agents (idempotent).
pub async fn register_builtins(pool: &SqlitePool) -> anyhow::Result<()> {
    for (name, _) in agents::scripted::variants() {
        sqlx::query("INSERT OR IGNORE INTO agents (name, kind, spec, spec_hash, builtin) VALUES (?, 'scripted', ?, ?, 1)")
            .bind(name)
            .bind(name)
            .bind(spec_hash(name))
            .execute(pool)
            .await?;
    }
    Ok(())
}

/// A match a previous process left running goes back to the queue (its partial results were never
/// written: results are stored in the same transaction that marks it done).
pub async fn requeue_running(pool: &SqlitePool) -> anyhow::Result<u64> {
    let r = sqlx::query(
        "UPDATE matches SET status = 'queued', started_at = NULL WHERE status = 'running'",
    )
    .execute(pool)
    .await?;
    Ok(r.rows_affected())
}

/// An agent row.
#[derive(Debug, Clone, Serialize, FromRow)]
pub struct Agent {
    /// Id.
    pub id: i64,
    /// Unique name.
    pub name: String,
    /// "scripted" or "checkpoint".
    pub kind: String,
    /// Hash of its spec.
    pub spec_hash: String,
    /// Registered by the server itself.
    pub builtin: bool,
    /// When registered.
    pub created_at: String,
    /// Qualification episodes played.
    pub qual_episodes: Option<i64>,
    /// Qualification hit rate.
    pub hit_rate: Option<f64>,
    /// Qualification success rate.
    pub success_rate: Option<f64>,
    /// Qualification effort.
    pub effort: Option<f64>,
}

const AGENT_COLUMNS: &str =
    "id, name, kind, spec_hash, builtin, created_at, qual_episodes, hit_rate, success_rate, effort";

/// All agents.
pub async fn agents(pool: &SqlitePool) -> sqlx::Result<Vec<Agent>> {
    sqlx::query_as(&format!("SELECT {AGENT_COLUMNS} FROM agents ORDER BY id"))
        .fetch_all(pool)
        .await
}

/// One agent.
pub async fn agent(pool: &SqlitePool, id: i64) -> sqlx::Result<Option<Agent>> {
    sqlx::query_as(&format!("SELECT {AGENT_COLUMNS} FROM agents WHERE id = ?"))
        .bind(id)
        .fetch_optional(pool)
        .await
}

/// An agent's kind and spec (for playing it).
pub async fn agent_spec(
    pool: &SqlitePool,
    id: i64,
) -> sqlx::Result<Option<(String, String, String)>> {
    sqlx::query_as("SELECT kind, spec, name FROM agents WHERE id = ?")
        .bind(id)
        .fetch_optional(pool)
        .await
}

/// Inserts a submitted checkpoint agent with its qualification.
pub async fn insert_checkpoint_agent(
    pool: &SqlitePool,
    name: &str,
    spec: &str,
    qual: (usize, f64, f64, f64),
    submitted_by: Option<i64>,
) -> sqlx::Result<i64> {
    let r = sqlx::query(
        "INSERT INTO agents (name, kind, spec, spec_hash, qual_episodes, hit_rate, success_rate, effort, submitted_by) VALUES (?, 'checkpoint', ?, ?, ?, ?, ?, ?, ?)",
    )
    .bind(name)
    .bind(spec)
    .bind(spec_hash(spec))
    .bind(qual.0 as i64)
    .bind(qual.1)
    .bind(qual.2)
    .bind(qual.3)
    .bind(submitted_by)
    .execute(pool)
    .await?;
    Ok(r.last_insert_rowid())
}

/// A match row.
#[derive(Debug, Clone, Serialize, FromRow)]
pub struct Match {
    /// Id.
    pub id: i64,
    /// Agent on side A.
    pub agent_a: i64,
    /// Agent on side B.
    pub agent_b: i64,
    /// Rallies.
    pub rallies: i64,
    /// Seed.
    pub seed: i64,
    /// Arena preset.
    pub preset: String,
    /// Simulator version.
    pub sim_version: String,
    /// Hash of A's spec when queued.
    pub spec_hash_a: String,
    /// Hash of B's spec when queued.
    pub spec_hash_b: String,
    /// Replay frames are stored.
    pub keep_replay: bool,
    /// queued | running | done | failed | cancelled.
    pub status: String,
    /// When queued.
    pub created_at: String,
    /// When a worker took it.
    pub started_at: Option<String>,
    /// When it finished.
    pub finished_at: Option<String>,
    /// Points of A.
    pub points_a: Option<i64>,
    /// Points of B.
    pub points_b: Option<i64>,
    /// Mean rally length.
    pub mean_rally_length: Option<f64>,
    /// Longest rally.
    pub max_rally_length: Option<i64>,
    /// Fraction of crossings in the serve box.
    pub in_box_fraction: Option<f64>,
    /// Serve → return energy distance.
    pub energy_distance: Option<f64>,
    /// Drift slope.
    pub drift_slope: Option<f64>,
    /// Why it failed.
    pub error: Option<String>,
}

const MATCH_COLUMNS: &str = "id, agent_a, agent_b, rallies, seed, preset, sim_version, spec_hash_a, spec_hash_b, keep_replay, status, created_at, started_at, finished_at, points_a, points_b, mean_rally_length, max_rally_length, in_box_fraction, energy_distance, drift_slope, error";

/// Queues a match.
pub async fn queue_match(
    pool: &SqlitePool,
    a: &Agent,
    b: &Agent,
    rallies: u32,
    seed: u64,
    keep_replay: bool,
) -> sqlx::Result<i64> {
    let r = sqlx::query(
        "INSERT INTO matches (agent_a, agent_b, rallies, seed, preset, sim_version, spec_hash_a, spec_hash_b, keep_replay, status) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, 'queued')",
    )
    .bind(a.id)
    .bind(b.id)
    .bind(rallies as i64)
    .bind(seed as i64)
    .bind(sim::arena::MYOCHALLENGE.name)
    .bind(sim::SIM_VERSION)
    .bind(&a.spec_hash)
    .bind(&b.spec_hash)
    .bind(keep_replay)
    .execute(pool)
    .await?;
    Ok(r.last_insert_rowid())
}

/// One match.
pub async fn match_row(pool: &SqlitePool, id: i64) -> sqlx::Result<Option<Match>> {
    sqlx::query_as(&format!("SELECT {MATCH_COLUMNS} FROM matches WHERE id = ?"))
        .bind(id)
        .fetch_optional(pool)
        .await
}

/// Matches, newest first, optionally of one agent and/or in one status.
pub async fn matches(
    pool: &SqlitePool,
    agent: Option<i64>,
    status: Option<&str>,
    limit: i64,
) -> sqlx::Result<Vec<Match>> {
    sqlx::query_as(&format!(
        "SELECT {MATCH_COLUMNS} FROM matches WHERE (?1 IS NULL OR agent_a = ?1 OR agent_b = ?1) AND (?2 IS NULL OR status = ?2) ORDER BY id DESC LIMIT ?3"
    ))
    .bind(agent)
    .bind(status)
    .bind(limit)
    .fetch_all(pool)
    .await
}

/// Claims the oldest queued match (queued → running) in one statement, so two workers never take
/// the same match and no read lock has to be upgraded (which SQLite can refuse under WAL).
pub async fn claim(pool: &SqlitePool) -> sqlx::Result<Option<Match>> {
    sqlx::query_as(&format!(
        "UPDATE matches SET status = 'running', started_at = CURRENT_TIMESTAMP \
         WHERE id = (SELECT id FROM matches WHERE status = 'queued' ORDER BY id LIMIT 1) AND status = 'queued' \
         RETURNING {MATCH_COLUMNS}"
    ))
    .fetch_optional(pool)
    .await
}

/// Stores a played match — rallies, crossings, replay, summary — and marks it done, in one
/// transaction; a match cancelled meanwhile stays cancelled and nothing is written.
pub async fn store_result(
    pool: &SqlitePool,
    id: i64,
    r: &MatchRecord,
    replay: &agents::matchrun::Replay,
) -> sqlx::Result<bool> {
    // The first statement writes, so the transaction takes the write lock at once (waiting out other
    // writers) instead of upgrading a read lock later.
    let mut tx = pool.begin().await?;
    let marked = sqlx::query(
        "UPDATE matches SET status = 'done', finished_at = CURRENT_TIMESTAMP, points_a = ?, points_b = ?, mean_rally_length = ?, max_rally_length = ?, in_box_fraction = ?, energy_distance = ?, drift_slope = ?, drift_json = ? WHERE id = ? AND status = 'running'",
    )
    .bind(r.points[0] as i64)
    .bind(r.points[1] as i64)
    .bind(r.mean_rally_length)
    .bind(r.max_rally_length as i64)
    .bind(r.drift.in_box_fraction)
    .bind(r.drift.energy_distance)
    .bind(r.drift.drift_slope)
    .bind(serde_json::to_string(&r.drift).unwrap_or_default())
    .bind(id)
    .execute(&mut *tx)
    .await?;
    if marked.rows_affected() == 0 {
        // Cancelled meanwhile: it stays cancelled and nothing is written.
        tx.rollback().await?;
        return Ok(false);
    }
    for rally in &r.rallies {
        sqlx::query("INSERT INTO rallies (match_id, idx, server, length, end_reason, failing_side, duration) VALUES (?, ?, ?, ?, ?, ?, ?)")
            .bind(id)
            .bind(rally.index as i64)
            .bind(rally.server)
            .bind(rally.length as i64)
            .bind(rally.end)
            .bind(rally.failing_side)
            .bind(rally.duration)
            .execute(&mut *tx)
            .await?;
        for (seq, c) in rally.crossings.iter().enumerate() {
            sqlx::query("INSERT INTO crossings (match_id, rally_idx, seq, receiver, exchange, y_r, z, in_box, extrapolated) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)")
                .bind(id)
                .bind(rally.index as i64)
                .bind(seq as i64)
                .bind(c.receiver)
                .bind(c.exchange as i64)
                .bind(c.y_r)
                .bind(c.z)
                .bind(c.in_box)
                .bind(c.extrapolated)
                .execute(&mut *tx)
                .await?;
        }
        if let Some(frames) = replay.get(rally.index as usize).filter(|f| !f.is_empty()) {
            sqlx::query("INSERT INTO replays (match_id, rally_idx, frames_gz) VALUES (?, ?, ?)")
                .bind(id)
                .bind(rally.index as i64)
                .bind(gzip_json(frames))
                .execute(&mut *tx)
                .await?;
        }
    }

    tx.commit().await?;
    Ok(true)
}

/// Marks a running match failed with a reason (one statement).
pub async fn fail(pool: &SqlitePool, id: i64, error: &str) -> sqlx::Result<()> {
    sqlx::query("UPDATE matches SET status = 'failed', finished_at = CURRENT_TIMESTAMP, error = ? WHERE id = ? AND status = 'running'")
        .bind(error)
        .bind(id)
        .execute(pool)
        .await?;
    Ok(())
}

/// Cancels a queued or running match; false if it had already finished (or does not exist).
pub async fn cancel(pool: &SqlitePool, id: i64) -> sqlx::Result<bool> {
    let r = sqlx::query("UPDATE matches SET status = 'cancelled', finished_at = CURRENT_TIMESTAMP WHERE id = ? AND status IN ('queued', 'running')")
        .bind(id)
        .execute(pool)
        .await?;
    Ok(r.rows_affected() == 1)
}

/// A stored rally.
#[derive(Debug, Clone, Serialize, FromRow)]
pub struct Rally {
    /// Index in the match.
    pub idx: i64,
    /// Who served.
    pub server: String,
    /// Legal returns.
    pub length: i64,
    /// End reason.
    pub end_reason: String,
    /// Who failed.
    pub failing_side: Option<String>,
    /// Simulated duration, s.
    pub duration: f64,
}

/// A match's rallies.
pub async fn rallies(pool: &SqlitePool, id: i64) -> sqlx::Result<Vec<Rally>> {
    sqlx::query_as("SELECT idx, server, length, end_reason, failing_side, duration FROM rallies WHERE match_id = ? ORDER BY idx")
        .bind(id)
        .fetch_all(pool)
        .await
}

/// A rally's replay frames (JSON), if stored.
pub async fn replay(pool: &SqlitePool, id: i64, rally: i64) -> anyhow::Result<Option<String>> {
    let r: Option<(Vec<u8>,)> =
        sqlx::query_as("SELECT frames_gz FROM replays WHERE match_id = ? AND rally_idx = ?")
            .bind(id)
            .bind(rally)
            .fetch_optional(pool)
            .await?;
    let Some((gz,)) = r else { return Ok(None) };
    let mut text = String::new();
    std::io::Read::read_to_string(&mut flate2::read::GzDecoder::new(&gz[..]), &mut text)?;
    Ok(Some(text))
}

fn gzip_json<T: Serialize>(value: &T) -> Vec<u8> {
    use std::io::Write;
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    // Writing into a Vec cannot fail; serialising plain numbers cannot either.
    let _ = serde_json::to_writer(&mut enc, value);
    enc.flush().ok();
    enc.finish().unwrap_or_default()
}

/// The stored drift statistics of a match (JSON).
pub async fn drift(pool: &SqlitePool, id: i64) -> sqlx::Result<Option<String>> {
    let r: Option<(Option<String>,)> =
        sqlx::query_as("SELECT drift_json FROM matches WHERE id = ?")
            .bind(id)
            .fetch_optional(pool)
            .await?;
    Ok(r.and_then(|x| x.0))
}

/// Per finished match: (agent A, agent B, points A, points B, mean rally length, max rally length,
/// in-box fraction, energy distance).
pub type Outcome = (i64, i64, i64, i64, f64, i64, Option<f64>, Option<f64>);

/// Every finished match's outcome.
pub async fn outcomes(pool: &SqlitePool) -> sqlx::Result<Vec<Outcome>> {
    sqlx::query_as(
        "SELECT agent_a, agent_b, points_a, points_b, mean_rally_length, max_rally_length, in_box_fraction, energy_distance FROM matches WHERE status = 'done' ORDER BY id",
    )
    .fetch_all(pool)
    .await
}

/// The SHA-256 of a token, hex.
pub fn token_sha256(token: &str) -> String {
    use sha2::Digest;
    sha2::Sha256::digest(token.as_bytes())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Stores a new submitter token (its hash only); the id.
pub async fn insert_token(pool: &SqlitePool, name: &str, token: &str) -> sqlx::Result<i64> {
    let r = sqlx::query("INSERT INTO tokens (name, token_sha256) VALUES (?, ?)")
        .bind(name)
        .bind(token_sha256(token))
        .execute(pool)
        .await?;
    Ok(r.last_insert_rowid())
}

/// The id of the submitter token `token`, if it is one.
pub async fn token_id(pool: &SqlitePool, token: &str) -> sqlx::Result<Option<i64>> {
    let r: Option<(i64,)> = sqlx::query_as("SELECT id FROM tokens WHERE token_sha256 = ?")
        .bind(token_sha256(token))
        .fetch_optional(pool)
        .await?;
    Ok(r.map(|x| x.0))
}
