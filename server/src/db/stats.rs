//! What the leaderboard and the agent page read: outcomes, Glicko-2 history, drift, crossings.

use super::*;

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

/// Every finished match's outcome of robot `model`.
pub async fn outcomes(pool: &Pool, model: &str) -> sqlx::Result<Vec<Outcome>> {
    sqlx::query_as(
        "SELECT agent_a, agent_b, points_a, points_b, mean_rally_length, max_rally_length, in_box_fraction, energy_distance, rallies FROM matches WHERE status = 'done' AND model = $1 ORDER BY id",
    )
    .bind(model)
    .fetch_all(pool)
    .await
}

/// The latest Glicko-2 rating and deviation of every agent of robot `model` that has one.
pub async fn latest_glicko(pool: &Pool, model: &str) -> sqlx::Result<Vec<(i64, f64, f64)>> {
    sqlx::query_as(
        "SELECT h.agent_id, h.rating, h.deviation FROM rating_history h JOIN agents a ON a.id = h.agent_id WHERE a.model = $1 AND h.seq = (SELECT MAX(seq) FROM rating_history WHERE agent_id = h.agent_id)",
    )
    .bind(model)
    .fetch_all(pool)
    .await
}

/// Per agent: mean over its finished matches of its own side's in-box fraction and serve → return
/// energy distance (`match_drift`); the agents of robot `model`.
pub async fn agent_drift(
    pool: &Pool,
    model: &str,
) -> sqlx::Result<Vec<(i64, Option<f64>, Option<f64>)>> {
    // As `agent_drift_summary` computes them for the agent's page: the in-box fraction pooled over
    // crossings (a match without any weighs nothing), the energy distance averaged where it exists.
    sqlx::query_as(
        "SELECT d.agent_id, SUM(d.in_box_fraction * d.crossings) / NULLIF(CAST(SUM(d.crossings) AS DOUBLE PRECISION), 0), \
         AVG(d.energy_distance) FROM match_drift d JOIN agents a ON a.id = d.agent_id WHERE a.model = $1 GROUP BY d.agent_id",
    )
        .bind(model)
        .fetch_all(pool)
        .await
}

/// The drift summary of one agent (PostgreSQL sums integers as NUMERIC, which sqlx's Any driver
/// does not read: the sums are cast).
pub async fn agent_drift_summary(pool: &Pool, agent: i64) -> sqlx::Result<AgentDrift> {
    sqlx::query_as::<_, Row<AgentDrift>>(
        "SELECT COUNT(*) AS matches, CAST(COALESCE(SUM(crossings), 0) AS BIGINT) AS crossings, \
         SUM(in_box_fraction * crossings) / NULLIF(CAST(SUM(crossings) AS DOUBLE PRECISION), 0) AS in_box_fraction, \
         AVG(energy_distance) AS energy_distance, AVG(drift_slope) AS drift_slope \
         FROM match_drift WHERE agent_id = $1",
    )
    .bind(agent)
    .fetch_one(pool)
    .await
    .map(|r| r.0)
}

/// How many of the rallies of an agent's finished matches had each length: `(length, rallies)`,
/// by length.
pub async fn agent_rally_lengths(pool: &Pool, agent: i64) -> sqlx::Result<Vec<(i64, i64)>> {
    sqlx::query_as(
        "SELECT r.length, COUNT(*) FROM rallies r JOIN matches m ON m.id = r.match_id \
         WHERE m.status = 'done' AND (m.agent_a = $1 OR m.agent_b = $2) GROUP BY r.length ORDER BY r.length",
    )
    .bind(agent)
    .bind(agent)
    .fetch_all(pool)
    .await
}

/// The crossings an agent is answerable for in its finished matches, newest match first: every
/// serve of those rallies and the crossings its own returns produced (the same set as its side's
/// drift statistics); at most `limit`, with the total.
pub async fn agent_crossings(
    pool: &Pool,
    agent: i64,
    limit: i64,
) -> sqlx::Result<(i64, Vec<AgentCrossing>)> {
    const MINE: &str = "FROM crossings c JOIN matches m ON m.id = c.match_id \
        WHERE m.status = 'done' AND ((m.agent_a = $1 AND (c.exchange = 0 OR c.receiver = 'b')) \
        OR (m.agent_b = $1 AND (c.exchange = 0 OR c.receiver = 'a')))";
    let (total,): (i64,) = sqlx::query_as(&format!("SELECT COUNT(*) {MINE}"))
        .bind(agent)
        .fetch_one(pool)
        .await?;
    let found = sqlx::query_as::<_, Row<AgentCrossing>>(&format!(
        "SELECT c.match_id AS match_id, c.rally_idx AS rally, c.exchange AS exchange, c.y_r AS y_r, c.z AS z, \
         c.in_box AS in_box, c.extrapolated AS extrapolated {MINE} \
         ORDER BY c.match_id DESC, c.rally_idx, c.seq LIMIT $2"
    ))
    .bind(agent)
    .bind(limit)
    .fetch_all(pool)
    .await?;
    Ok((total, rows(found)))
}

/// An agent's rating history: how many points it has, and the newest `limit` of them, oldest first
/// (one transaction: the count is the page's).
pub async fn rating_history(
    pool: &Pool,
    agent: i64,
    limit: i64,
) -> sqlx::Result<(i64, Vec<RatingPoint>)> {
    let mut tx = pool.begin().await?;
    let (total,): (i64,) =
        sqlx::query_as("SELECT COUNT(*) FROM rating_history WHERE agent_id = $1")
            .bind(agent)
            .fetch_one(&mut *tx)
            .await?;
    let mut newest = sqlx::query_as::<_, Row<RatingPoint>>("SELECT seq, match_id, rating, deviation, volatility, created_at FROM rating_history WHERE agent_id = $1 ORDER BY seq DESC LIMIT $2")
        .bind(agent)
        .bind(limit)
        .fetch_all(&mut *tx)
        .await
        .map(rows)?;
    tx.commit().await?;
    newest.reverse();
    Ok((total, newest))
}

/// The drift statistics of one side of a match: (side, agent, JSON).
pub async fn match_drift(pool: &Pool, id: i64) -> sqlx::Result<Vec<(String, i64, String)>> {
    sqlx::query_as(
        "SELECT side, agent_id, drift_json FROM match_drift WHERE match_id = $1 ORDER BY side",
    )
    .bind(id)
    .fetch_all(pool)
    .await
}
