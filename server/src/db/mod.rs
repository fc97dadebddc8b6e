//! Storage: SQLite through sqlx (WAL), the `migrations/` applied at start. Every state change of a match
//! is one transaction. Runtime queries only (no build-time database).

use std::path::Path;
use std::str::FromStr;

use serde::Serialize;
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions};
use sqlx::{FromRow, SqlitePool};

use agents::matchrun::MatchRecord;

pub use crate::domain::{AgentKind, MatchStatus, SprtStatus, WorkerStatus};

pub mod workers;
pub use workers::Lease;

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

/// An agent row.
#[derive(Debug, Clone, Serialize, FromRow)]
pub struct Agent {
    /// Id.
    pub id: i64,
    /// Unique name.
    pub name: String,
    /// What it is.
    pub kind: AgentKind,
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

/// The agent with a name.
pub async fn agent_by_name(pool: &SqlitePool, name: &str) -> sqlx::Result<Option<Agent>> {
    sqlx::query_as(&format!(
        "SELECT {AGENT_COLUMNS} FROM agents WHERE name = ?"
    ))
    .bind(name)
    .fetch_optional(pool)
    .await
}

/// An agent's kind and spec (for playing it).
pub async fn agent_spec(pool: &SqlitePool, id: i64) -> sqlx::Result<Option<(AgentKind, String)>> {
    sqlx::query_as("SELECT kind, spec FROM agents WHERE id = ?")
        .bind(id)
        .fetch_optional(pool)
        .await
}

/// Inserts a checkpoint agent (submitted, or built in) with its qualification.
pub async fn insert_checkpoint_agent(
    pool: &SqlitePool,
    name: &str,
    spec: &str,
    qual: (usize, f64, f64, f64),
    builtin: bool,
    submitted_by: Option<i64>,
) -> sqlx::Result<i64> {
    let r = sqlx::query(
        "INSERT INTO agents (name, kind, spec, spec_hash, qual_episodes, hit_rate, success_rate, effort, builtin, submitted_by) VALUES (?, 'checkpoint', ?, ?, ?, ?, ?, ?, ?, ?)",
    )
    .bind(name)
    .bind(spec)
    .bind(spec_hash(spec))
    .bind(qual.0 as i64)
    .bind(qual.1)
    .bind(qual.2)
    .bind(qual.3)
    .bind(builtin)
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
    /// Played (or queued) under another simulator version than this server's: its result stands,
    /// but it cannot be re-simulated or played here.
    pub outdated: bool,
    /// Hash of A's spec when queued.
    pub spec_hash_a: String,
    /// Hash of B's spec when queued.
    pub spec_hash_b: String,
    /// Replay frames are stored.
    pub keep_replay: bool,
    /// Where it is in its life.
    pub status: MatchStatus,
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
    /// The tournament it belongs to.
    pub tournament_id: Option<i64>,
    /// The SPRT it belongs to.
    pub sprt_id: Option<i64>,
    /// The submitter token that queued it (null: the admin or the server).
    pub created_by: Option<i64>,
    /// The worker that holds its lease (running) or played it (done, failed).
    pub worker: Option<String>,
    /// How many times a worker claimed it (more than once: a worker died or lost its lease).
    pub attempts: i64,
}

/// The columns of a [`Match`]; `outdated` compares the stored simulator version with this build's
/// (a constant of ours, digits and dots only).
fn match_columns() -> String {
    format!(
        "id, agent_a, agent_b, rallies, seed, preset, sim_version, sim_version <> '{}' AS outdated, spec_hash_a, spec_hash_b, keep_replay, status, created_at, started_at, finished_at, points_a, points_b, mean_rally_length, max_rally_length, in_box_fraction, energy_distance, drift_slope, error, tournament_id, sprt_id, created_by, worker, attempts",
        sim::SIM_VERSION
    )
}

#[cfg(test)]
impl Match {
    /// A queued match row for tests (nothing played, no tournament or SPRT).
    pub(crate) fn example(id: i64, agent_a: i64, agent_b: i64) -> Match {
        Match {
            id,
            agent_a,
            agent_b,
            rallies: 10,
            seed: id,
            preset: "myochallenge".into(),
            sim_version: String::new(),
            outdated: false,
            spec_hash_a: String::new(),
            spec_hash_b: String::new(),
            keep_replay: true,
            status: MatchStatus::Queued,
            created_at: String::new(),
            started_at: None,
            finished_at: None,
            points_a: None,
            points_b: None,
            mean_rally_length: None,
            max_rally_length: None,
            in_box_fraction: None,
            energy_distance: None,
            drift_slope: None,
            error: None,
            tournament_id: None,
            sprt_id: None,
            created_by: None,
            worker: None,
            attempts: 0,
        }
    }
}

/// What queued a match, besides a plain request.
#[derive(Debug, Clone, Copy, Default)]
pub struct Origin {
    /// A tournament.
    pub tournament: Option<i64>,
    /// An SPRT.
    pub sprt: Option<i64>,
    /// The submitter token that asked for it.
    pub created_by: Option<i64>,
}

/// Queues a match (on the pool or inside a transaction).
pub async fn queue_match<'c, E: sqlx::SqliteExecutor<'c>>(
    db: E,
    a: &Agent,
    b: &Agent,
    rallies: u32,
    seed: u64,
    keep_replay: bool,
    origin: Origin,
) -> sqlx::Result<i64> {
    let r = sqlx::query(
        "INSERT INTO matches (agent_a, agent_b, rallies, seed, preset, sim_version, spec_hash_a, spec_hash_b, keep_replay, status, tournament_id, sprt_id, created_by) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, 'queued', ?, ?, ?)",
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
    .bind(origin.tournament)
    .bind(origin.sprt)
    .bind(origin.created_by)
    .execute(db)
    .await?;
    Ok(r.last_insert_rowid())
}

/// One match.
pub async fn match_row(pool: &SqlitePool, id: i64) -> sqlx::Result<Option<Match>> {
    sqlx::query_as(&format!(
        "SELECT {} FROM matches WHERE id = ?",
        match_columns()
    ))
    .bind(id)
    .fetch_optional(pool)
    .await
}

/// Which matches to list.
#[derive(Debug, Clone, Copy, Default)]
pub struct MatchFilter {
    /// Only those this agent played.
    pub agent: Option<i64>,
    /// Only those in this status.
    pub status: Option<MatchStatus>,
    /// Only those with a smaller id (the next page after the last id seen).
    pub before: Option<i64>,
}

/// Matches, newest first, filtered.
pub async fn matches(
    pool: &SqlitePool,
    filter: MatchFilter,
    limit: i64,
) -> sqlx::Result<Vec<Match>> {
    sqlx::query_as(&format!(
        "SELECT {cols} FROM matches WHERE (?1 IS NULL OR agent_a = ?1 OR agent_b = ?1) AND (?2 IS NULL OR status = ?2) AND (?3 IS NULL OR id < ?3) ORDER BY id DESC LIMIT ?4",
        cols = match_columns()
    ))
    .bind(filter.agent)
    .bind(filter.status)
    .bind(filter.before)
    .bind(limit)
    .fetch_all(pool)
    .await
}

/// What became of a result a worker stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stored {
    /// Written, the match done.
    Done,
    /// The match was cancelled meanwhile: it stays cancelled and nothing is written.
    Cancelled,
    /// The worker's lease was lost (the match was queued again, and maybe claimed by another
    /// worker): nothing is written.
    LeaseLost,
}

/// Stores a played match — rallies, crossings, replay, summary, ratings, SPRT step — and marks it
/// done, in one transaction, under the worker's current lease (see [`workers`]).
pub async fn store_result(
    pool: &SqlitePool,
    lease: &Lease,
    r: &MatchRecord,
    replay: &agents::matchrun::Replay,
) -> sqlx::Result<Stored> {
    let id = lease.match_id;
    // The first statement writes, so the transaction takes the write lock at once (waiting out other
    // writers) instead of upgrading a read lock later.
    let mut tx = pool.begin().await?;
    let marked: Option<(i64, i64, Option<i64>)> = sqlx::query_as(
        "UPDATE matches SET status = 'done', finished_at = CURRENT_TIMESTAMP, points_a = ?, points_b = ?, mean_rally_length = ?, max_rally_length = ?, in_box_fraction = ?, energy_distance = ?, drift_slope = ?, drift_json = ? WHERE id = ? AND status = 'running' AND worker = ? AND attempts = ? RETURNING agent_a, agent_b, sprt_id",
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
    .bind(&lease.worker)
    .bind(lease.attempt)
    .fetch_optional(&mut *tx)
    .await?;
    let Some((agent_a, agent_b, sprt_id)) = marked else {
        tx.rollback().await?;
        return lost_or_cancelled(pool, id).await;
    };
    sqlx::query("UPDATE matches SET lease_expires_ms = NULL WHERE id = ?")
        .bind(id)
        .execute(&mut *tx)
        .await?;
    sqlx::query("UPDATE workers SET matches_played = matches_played + 1 WHERE name = ?")
        .bind(&lease.worker)
        .execute(&mut *tx)
        .await?;
    for (side, agent, d) in [
        ("A", agent_a, &r.drift_by_player[0]),
        ("B", agent_b, &r.drift_by_player[1]),
    ] {
        sqlx::query("INSERT INTO match_drift (match_id, side, agent_id, crossings, in_box_fraction, energy_distance, drift_slope, drift_json) VALUES (?, ?, ?, ?, ?, ?, ?, ?)")
            .bind(id)
            .bind(side)
            .bind(agent)
            .bind(d.crossings as i64)
            .bind(d.in_box_fraction)
            .bind(d.energy_distance)
            .bind(d.drift_slope)
            .bind(serde_json::to_string(d).unwrap_or_default())
            .execute(&mut *tx)
            .await?;
    }
    if agent_a != agent_b {
        // Glicko-2, online: both sides' last ratings, one game won by the side with more points.
        let last = |agent: i64| {
            sqlx::query_as::<_, (f64, f64, f64)>("SELECT rating, deviation, volatility FROM rating_history WHERE agent_id = ? ORDER BY seq DESC LIMIT 1").bind(agent)
        };
        let ra = last(agent_a).fetch_optional(&mut *tx).await?;
        let rb = last(agent_b).fetch_optional(&mut *tx).await?;
        let (na, nb) = crate::ratings::glicko2_step(ra, rb, r.points[0], r.points[1]);
        for (agent, g) in [(agent_a, na), (agent_b, nb)] {
            sqlx::query("INSERT INTO rating_history (match_id, agent_id, rating, deviation, volatility) VALUES (?, ?, ?, ?, ?)")
                .bind(id)
                .bind(agent)
                .bind(g.0)
                .bind(g.1)
                .bind(g.2)
                .execute(&mut *tx)
                .await?;
        }
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
    if let Some(sprt) = sprt_id {
        sprt_step(&mut tx, sprt).await?;
    }
    tx.commit().await?;
    Ok(Stored::Done)
}

/// Why a worker's write under its lease matched no row: the match was cancelled, or the lease lost.
async fn lost_or_cancelled(pool: &SqlitePool, id: i64) -> sqlx::Result<Stored> {
    let status: Option<(MatchStatus,)> = sqlx::query_as("SELECT status FROM matches WHERE id = ?")
        .bind(id)
        .fetch_optional(pool)
        .await?;
    Ok(match status {
        Some((MatchStatus::Cancelled,)) => Stored::Cancelled,
        _ => Stored::LeaseLost,
    })
}

/// Marks a running match failed with a reason, under the worker's current lease; an SPRT it belonged
/// to fails with it (one transaction).
pub async fn fail(pool: &SqlitePool, lease: &Lease, error: &str) -> sqlx::Result<Stored> {
    let mut tx = pool.begin().await?;
    let sprt: Option<(Option<i64>,)> = sqlx::query_as("UPDATE matches SET status = 'failed', finished_at = CURRENT_TIMESTAMP, error = ?, lease_expires_ms = NULL WHERE id = ? AND status = 'running' AND worker = ? AND attempts = ? RETURNING sprt_id")
        .bind(error)
        .bind(lease.match_id)
        .bind(&lease.worker)
        .bind(lease.attempt)
        .fetch_optional(&mut *tx)
        .await?;
    let Some((sprt,)) = sprt else {
        tx.rollback().await?;
        return lost_or_cancelled(pool, lease.match_id).await;
    };
    if let Some(sprt) = sprt {
        end_sprt(&mut tx, sprt, SprtStatus::Failed).await?;
    }
    tx.commit().await?;
    Ok(Stored::Done)
}

/// Cancels a queued or running match (and the SPRT it belongs to: it cannot go on without it);
/// false if it had already finished (or does not exist).
pub async fn cancel(pool: &SqlitePool, id: i64) -> sqlx::Result<bool> {
    let mut tx = pool.begin().await?;
    let r: Option<(Option<i64>,)> = sqlx::query_as("UPDATE matches SET status = 'cancelled', finished_at = CURRENT_TIMESTAMP WHERE id = ? AND status IN ('queued', 'running') RETURNING sprt_id")
        .bind(id)
        .fetch_optional(&mut *tx)
        .await?;
    if let Some((Some(sprt),)) = r {
        end_sprt(&mut tx, sprt, SprtStatus::Cancelled).await?;
    }
    tx.commit().await?;
    Ok(r.is_some())
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

pub use crate::ratings::Outcome;

impl From<&Agent> for crate::ratings::Entrant {
    fn from(a: &Agent) -> Self {
        crate::ratings::Entrant {
            id: a.id,
            name: a.name.clone(),
            builtin: a.builtin,
            hit_rate: a.hit_rate,
            success_rate: a.success_rate,
        }
    }
}

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

/// The latest Glicko-2 rating and deviation of every agent that has one.
pub async fn latest_glicko(pool: &SqlitePool) -> sqlx::Result<Vec<(i64, f64, f64)>> {
    sqlx::query_as(
        "SELECT agent_id, rating, deviation FROM rating_history h WHERE seq = (SELECT MAX(seq) FROM rating_history WHERE agent_id = h.agent_id)",
    )
    .fetch_all(pool)
    .await
}

/// Per agent: mean over its finished matches of its own side's in-box fraction and serve → return
/// energy distance (`match_drift`).
pub async fn agent_drift(pool: &SqlitePool) -> sqlx::Result<Vec<(i64, Option<f64>, Option<f64>)>> {
    sqlx::query_as("SELECT agent_id, AVG(in_box_fraction), AVG(energy_distance) FROM match_drift GROUP BY agent_id")
        .fetch_all(pool)
        .await
}

/// An agent's drift over its finished matches (its side's serves and returns, `match_drift`).
#[derive(Debug, Clone, Serialize, FromRow)]
pub struct AgentDrift {
    /// Matches with drift statistics.
    pub matches: i64,
    /// Crossings counted over them.
    pub crossings: i64,
    /// Fraction of those crossings inside the serve box (pooled over matches).
    pub in_box_fraction: Option<f64>,
    /// Mean serve → return energy distance (matches that have one).
    pub energy_distance: Option<f64>,
    /// Mean drift slope over exchange index (matches that have one).
    pub drift_slope: Option<f64>,
}

/// The drift summary of one agent.
pub async fn agent_drift_summary(pool: &SqlitePool, agent: i64) -> sqlx::Result<AgentDrift> {
    sqlx::query_as(
        "SELECT COUNT(*) AS matches, COALESCE(SUM(crossings), 0) AS crossings, \
         SUM(in_box_fraction * crossings) / NULLIF(SUM(crossings), 0) AS in_box_fraction, \
         AVG(energy_distance) AS energy_distance, AVG(drift_slope) AS drift_slope \
         FROM match_drift WHERE agent_id = ?",
    )
    .bind(agent)
    .fetch_one(pool)
    .await
}

/// How many of the rallies of an agent's finished matches had each length: `(length, rallies)`,
/// by length.
pub async fn agent_rally_lengths(pool: &SqlitePool, agent: i64) -> sqlx::Result<Vec<(i64, i64)>> {
    sqlx::query_as(
        "SELECT r.length, COUNT(*) FROM rallies r JOIN matches m ON m.id = r.match_id \
         WHERE m.status = 'done' AND (m.agent_a = ? OR m.agent_b = ?) GROUP BY r.length ORDER BY r.length",
    )
    .bind(agent)
    .bind(agent)
    .fetch_all(pool)
    .await
}

/// A crossing of the hitting plane that an agent is answerable for.
#[derive(Debug, Clone, Serialize, FromRow)]
pub struct AgentCrossing {
    /// The match.
    pub match_id: i64,
    /// The rally in it.
    pub rally: i64,
    /// 0 for a serve, k for the k-th return of the rally.
    pub exchange: i64,
    /// Lateral coordinate in the receiver's frame, m.
    pub y_r: f64,
    /// Height, m.
    pub z: f64,
    /// Inside the serve box.
    pub in_box: bool,
    /// Extrapolated (the receiver hit before the plane).
    pub extrapolated: bool,
}

/// The crossings an agent is answerable for in its finished matches, newest match first: every
/// serve of those rallies and the crossings its own returns produced (the same set as its side's
/// drift statistics); at most `limit`, with the total.
pub async fn agent_crossings(
    pool: &SqlitePool,
    agent: i64,
    limit: i64,
) -> sqlx::Result<(i64, Vec<AgentCrossing>)> {
    const MINE: &str = "FROM crossings c JOIN matches m ON m.id = c.match_id \
        WHERE m.status = 'done' AND ((m.agent_a = ?1 AND (c.exchange = 0 OR c.receiver = 'b')) \
        OR (m.agent_b = ?1 AND (c.exchange = 0 OR c.receiver = 'a')))";
    let (total,): (i64,) = sqlx::query_as(&format!("SELECT COUNT(*) {MINE}"))
        .bind(agent)
        .fetch_one(pool)
        .await?;
    let rows = sqlx::query_as(&format!(
        "SELECT c.match_id AS match_id, c.rally_idx AS rally, c.exchange AS exchange, c.y_r AS y_r, c.z AS z, \
         c.in_box AS in_box, c.extrapolated AS extrapolated {MINE} \
         ORDER BY c.match_id DESC, c.rally_idx, c.seq LIMIT ?2"
    ))
    .bind(agent)
    .bind(limit)
    .fetch_all(pool)
    .await?;
    Ok((total, rows))
}

/// One point of an agent's rating history.
#[derive(Debug, Clone, Serialize, FromRow)]
pub struct RatingPoint {
    /// Order in which matches finished (server-wide).
    pub seq: i64,
    /// The match after which it was computed.
    pub match_id: i64,
    /// Glicko-2 rating.
    pub rating: f64,
    /// Its deviation.
    pub deviation: f64,
    /// Its volatility.
    pub volatility: f64,
    /// When.
    pub created_at: String,
}

/// An agent's rating history, oldest first.
pub async fn rating_history(pool: &SqlitePool, agent: i64) -> sqlx::Result<Vec<RatingPoint>> {
    sqlx::query_as("SELECT seq, match_id, rating, deviation, volatility, created_at FROM rating_history WHERE agent_id = ? ORDER BY seq")
        .bind(agent)
        .fetch_all(pool)
        .await
}

/// The drift statistics of one side of a match: (side, agent, JSON).
pub async fn match_drift(pool: &SqlitePool, id: i64) -> sqlx::Result<Vec<(String, i64, String)>> {
    sqlx::query_as(
        "SELECT side, agent_id, drift_json FROM match_drift WHERE match_id = ? ORDER BY side",
    )
    .bind(id)
    .fetch_all(pool)
    .await
}

/// A tournament row.
#[derive(Debug, Clone, Serialize, FromRow)]
pub struct Tournament {
    /// Id.
    pub id: i64,
    /// round_robin | gauntlet.
    pub kind: String,
    /// Agent ids (JSON array) in the order given.
    pub agents_json: String,
    /// Rallies per match.
    pub rallies_per_match: i64,
    /// Rounds.
    pub rounds: i64,
    /// Seed of its first match (the k-th gets seed + k).
    pub seed: i64,
    /// The submitter token that created it (null: the admin).
    pub created_by: Option<i64>,
    /// When created.
    pub created_at: String,
}

/// A tournament to create: its agents and the (side A, side B) index pairs of its matches.
#[derive(Debug, Clone, Copy)]
pub struct TournamentPlan<'a> {
    /// round_robin | gauntlet.
    pub kind: &'a str,
    /// The agents in the order given.
    pub agents: &'a [Agent],
    /// Its matches, indices into `agents`.
    pub pairs: &'a [(usize, usize)],
    /// Rallies per match.
    pub rallies: u32,
    /// Rounds.
    pub rounds: u32,
    /// Seed of the first match.
    pub seed: u64,
    /// The submitter token that asked for it.
    pub created_by: Option<i64>,
}

/// Creates a tournament and queues all its matches, in one transaction; its id.
pub async fn create_tournament(pool: &SqlitePool, plan: TournamentPlan<'_>) -> sqlx::Result<i64> {
    let TournamentPlan {
        kind,
        agents,
        pairs,
        rallies,
        rounds,
        seed,
        created_by,
    } = plan;
    let mut tx = pool.begin().await?;
    let ids: Vec<i64> = agents.iter().map(|a| a.id).collect();
    let t = sqlx::query("INSERT INTO tournaments (kind, agents_json, rallies_per_match, rounds, seed, created_by) VALUES (?, ?, ?, ?, ?, ?)")
        .bind(kind)
        .bind(serde_json::to_string(&ids).unwrap_or_default())
        .bind(rallies as i64)
        .bind(rounds as i64)
        .bind(seed as i64)
        .bind(created_by)
        .execute(&mut *tx)
        .await?
        .last_insert_rowid();
    for (k, &(a, b)) in pairs.iter().enumerate() {
        let origin = Origin {
            tournament: Some(t),
            sprt: None,
            created_by,
        };
        let seed = seed.wrapping_add(k as u64) & (i64::MAX as u64);
        queue_match(
            &mut *tx, &agents[a], &agents[b], rallies, seed, true, origin,
        )
        .await?;
    }
    tx.commit().await?;
    Ok(t)
}

/// One tournament.
pub async fn tournament(pool: &SqlitePool, id: i64) -> sqlx::Result<Option<Tournament>> {
    sqlx::query_as("SELECT id, kind, agents_json, rallies_per_match, rounds, seed, created_by, created_at FROM tournaments WHERE id = ?")
        .bind(id)
        .fetch_optional(pool)
        .await
}

/// Tournaments, newest first.
pub async fn tournaments(pool: &SqlitePool, limit: i64) -> sqlx::Result<Vec<Tournament>> {
    sqlx::query_as("SELECT id, kind, agents_json, rallies_per_match, rounds, seed, created_by, created_at FROM tournaments ORDER BY id DESC LIMIT ?")
        .bind(limit)
        .fetch_all(pool)
        .await
}

/// A tournament's matches in the order they were queued.
pub async fn tournament_matches(pool: &SqlitePool, id: i64) -> sqlx::Result<Vec<Match>> {
    sqlx::query_as(&format!(
        "SELECT {cols} FROM matches WHERE tournament_id = ? ORDER BY id",
        cols = match_columns()
    ))
    .bind(id)
    .fetch_all(pool)
    .await
}

/// Cancels a tournament's queued and running matches; how many.
pub async fn cancel_tournament(pool: &SqlitePool, id: i64) -> sqlx::Result<u64> {
    let r = sqlx::query("UPDATE matches SET status = 'cancelled', finished_at = CURRENT_TIMESTAMP WHERE tournament_id = ? AND status IN ('queued', 'running')")
        .bind(id)
        .execute(pool)
        .await?;
    Ok(r.rows_affected())
}

/// An SPRT row.
#[derive(Debug, Clone, Serialize, FromRow)]
pub struct Sprt {
    /// Id.
    pub id: i64,
    /// The agent tested.
    pub agent_a: i64,
    /// Its opponent.
    pub agent_b: i64,
    /// H0: A's Elo advantage on points is elo0.
    pub elo0: f64,
    /// H1: it is elo1.
    pub elo1: f64,
    /// False-positive rate.
    pub alpha: f64,
    /// False-negative rate.
    pub beta: f64,
    /// Rallies per match.
    pub rallies_per_match: i64,
    /// Matches after which it stops undecided.
    pub max_matches: i64,
    /// Seed of the first match (the k-th gets seed + k).
    pub seed: i64,
    /// Where it is in its life.
    pub status: SprtStatus,
    /// Log-likelihood ratio after the finished matches.
    pub llr: f64,
    /// Finished matches.
    pub matches_done: i64,
    /// The submitter token that created it (null: the admin).
    pub created_by: Option<i64>,
    /// When created.
    pub created_at: String,
    /// When it ended.
    pub finished_at: Option<String>,
}

const SPRT_COLUMNS: &str = "id, agent_a, agent_b, elo0, elo1, alpha, beta, rallies_per_match, max_matches, seed, status, llr, matches_done, created_by, created_at, finished_at";

/// The parameters of a new SPRT.
#[derive(Debug, Clone, Copy)]
pub struct SprtParams {
    /// H0 Elo.
    pub elo0: f64,
    /// H1 Elo.
    pub elo1: f64,
    /// False-positive rate.
    pub alpha: f64,
    /// False-negative rate.
    pub beta: f64,
    /// Rallies per match.
    pub rallies: u32,
    /// Most matches.
    pub max_matches: u32,
    /// First seed.
    pub seed: u64,
}

/// Creates an SPRT and queues its first match, in one transaction; its id.
pub async fn create_sprt(
    pool: &SqlitePool,
    a: &Agent,
    b: &Agent,
    p: SprtParams,
    created_by: Option<i64>,
) -> sqlx::Result<i64> {
    let mut tx = pool.begin().await?;
    let id = sqlx::query("INSERT INTO sprts (agent_a, agent_b, elo0, elo1, alpha, beta, rallies_per_match, max_matches, seed, status, created_by) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, 'running', ?)")
        .bind(a.id)
        .bind(b.id)
        .bind(p.elo0)
        .bind(p.elo1)
        .bind(p.alpha)
        .bind(p.beta)
        .bind(p.rallies as i64)
        .bind(p.max_matches as i64)
        .bind(p.seed as i64)
        .bind(created_by)
        .execute(&mut *tx)
        .await?
        .last_insert_rowid();
    let origin = Origin {
        tournament: None,
        sprt: Some(id),
        created_by,
    };
    queue_match(&mut *tx, a, b, p.rallies, p.seed, false, origin).await?;
    tx.commit().await?;
    Ok(id)
}

/// One SPRT.
pub async fn sprt(pool: &SqlitePool, id: i64) -> sqlx::Result<Option<Sprt>> {
    sqlx::query_as(&format!("SELECT {SPRT_COLUMNS} FROM sprts WHERE id = ?"))
        .bind(id)
        .fetch_optional(pool)
        .await
}

/// SPRTs, newest first.
pub async fn sprts(pool: &SqlitePool, limit: i64) -> sqlx::Result<Vec<Sprt>> {
    sqlx::query_as(&format!(
        "SELECT {SPRT_COLUMNS} FROM sprts ORDER BY id DESC LIMIT ?"
    ))
    .bind(limit)
    .fetch_all(pool)
    .await
}

/// An SPRT's matches in order.
pub async fn sprt_matches(pool: &SqlitePool, id: i64) -> sqlx::Result<Vec<Match>> {
    sqlx::query_as(&format!(
        "SELECT {cols} FROM matches WHERE sprt_id = ? ORDER BY id",
        cols = match_columns()
    ))
    .bind(id)
    .fetch_all(pool)
    .await
}

/// Ends a running SPRT with `status` and cancels its unfinished matches; false if it had ended.
pub async fn end_sprt(
    conn: &mut sqlx::SqliteConnection,
    id: i64,
    status: SprtStatus,
) -> sqlx::Result<bool> {
    let r = sqlx::query("UPDATE sprts SET status = ?, finished_at = CURRENT_TIMESTAMP WHERE id = ? AND status = 'running'")
        .bind(status)
        .bind(id)
        .execute(&mut *conn)
        .await?;
    sqlx::query("UPDATE matches SET status = 'cancelled', finished_at = CURRENT_TIMESTAMP WHERE sprt_id = ? AND status IN ('queued', 'running')")
        .bind(id)
        .execute(&mut *conn)
        .await?;
    Ok(r.rows_affected() == 1)
}

/// Cancels a running SPRT (one transaction); false if it had ended.
pub async fn cancel_sprt(pool: &SqlitePool, id: i64) -> sqlx::Result<bool> {
    let mut tx = pool.begin().await?;
    let ended = end_sprt(&mut tx, id, SprtStatus::Cancelled).await?;
    tx.commit().await?;
    Ok(ended)
}

/// After one of its matches finished (inside the transaction that stored it): recomputes the SPRT's
/// log-likelihood ratio over its finished matches, ends it when the ratio leaves the bounds or
/// `max_matches` are played, and otherwise queues the next match (sides swapped every match, the
/// k-th with seed plus k). One match at a time, so the test's course depends only on its seeds. SPRT
/// matches keep no replay frames (the replay endpoint re-simulates a rally on request).
async fn sprt_step(conn: &mut sqlx::SqliteConnection, id: i64) -> sqlx::Result<()> {
    let s: Option<Sprt> = sqlx::query_as(&format!("SELECT {SPRT_COLUMNS} FROM sprts WHERE id = ?"))
        .bind(id)
        .fetch_optional(&mut *conn)
        .await?;
    let Some(s) = s.filter(|s| s.status == SprtStatus::Running) else {
        return Ok(());
    };
    let done: Vec<(i64, i64, i64)> = sqlx::query_as("SELECT agent_a, points_a, points_b FROM matches WHERE sprt_id = ? AND status = 'done' ORDER BY id")
        .bind(id)
        .fetch_all(&mut *conn)
        .await?;
    let scores: Vec<f64> = done
        .iter()
        .filter_map(|&(a, pa, pb)| crate::ratings::share_of(s.agent_a, a, pa, pb))
        .collect();
    let llr = crate::ratings::sprt_llr(&scores, s.rallies_per_match as f64, s.elo0, s.elo1);
    let (lower, upper) = crate::ratings::sprt_bounds(s.alpha, s.beta);
    let n = done.len() as i64;
    let status = if llr >= upper {
        SprtStatus::AcceptedH1
    } else if llr <= lower {
        SprtStatus::AcceptedH0
    } else if n >= s.max_matches {
        SprtStatus::Inconclusive
    } else {
        SprtStatus::Running
    };
    sqlx::query("UPDATE sprts SET llr = ?, matches_done = ?, status = ?, finished_at = CASE WHEN ? = 'running' THEN NULL ELSE CURRENT_TIMESTAMP END WHERE id = ?")
        .bind(llr)
        .bind(n)
        .bind(status)
        .bind(status)
        .bind(id)
        .execute(&mut *conn)
        .await?;
    if status != SprtStatus::Running {
        return Ok(());
    }
    let sql = format!("SELECT {AGENT_COLUMNS} FROM agents WHERE id = ?");
    let agent = |id: i64| sqlx::query_as::<_, Agent>(&sql).bind(id);
    let a = agent(s.agent_a).fetch_one(&mut *conn).await?;
    let b = agent(s.agent_b).fetch_one(&mut *conn).await?;
    let (x, y) = if n % 2 == 0 { (&a, &b) } else { (&b, &a) };
    let origin = Origin {
        tournament: None,
        sprt: Some(id),
        created_by: s.created_by,
    };
    let seed = (s.seed as u64).wrapping_add(n as u64) & (i64::MAX as u64);
    queue_match(
        &mut *conn,
        x,
        y,
        s.rallies_per_match as u32,
        seed,
        false,
        origin,
    )
    .await?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn a_match_of_another_simulator_version_says_it_is_outdated() {
        let path =
            std::env::temp_dir().join(format!("rally-db-outdated-{}.db", std::process::id()));
        let _ = std::fs::remove_file(&path);
        let pool = open(&path).await.unwrap();
        register_builtins(&pool).await.unwrap();
        let all = agents(&pool).await.unwrap();
        let (a, b) = (&all[0], &all[1]);
        let now = queue_match(&pool, a, b, 2, 1, true, Origin::default())
            .await
            .unwrap();
        let old = queue_match(&pool, a, b, 2, 2, true, Origin::default())
            .await
            .unwrap();
        sqlx::query("UPDATE matches SET sim_version = '0.1.0' WHERE id = ?")
            .bind(old)
            .execute(&pool)
            .await
            .unwrap();
        let row = |id| {
            let pool = pool.clone();
            async move { match_row(&pool, id).await.unwrap().unwrap() }
        };
        assert!(!row(now).await.outdated);
        let m = row(old).await;
        assert!(m.outdated && m.sim_version == "0.1.0");
        // The list says so too.
        let listed = matches(&pool, MatchFilter::default(), 10).await.unwrap();
        assert_eq!(listed.iter().filter(|m| m.outdated).count(), 1);
        pool.close().await;
        let _ = std::fs::remove_file(&path);
    }
}
