//! Counts: what the health check, the metrics, the leaderboard cache and continuous mode ask of the
//! store besides rows.

use super::*;

/// Whether the store answers (`/healthz`).
pub async fn ping(pool: &Pool) -> sqlx::Result<()> {
    sqlx::query("SELECT 1").execute(pool).await.map(|_| ())
}

/// Matches per status, for the statuses that have any.
pub async fn matches_by_status(pool: &Pool) -> sqlx::Result<Vec<(String, i64)>> {
    sqlx::query_as("SELECT status, COUNT(*) FROM matches GROUP BY status")
        .fetch_all(pool)
        .await
}

/// (agents, stored rallies).
pub async fn agent_and_rally_counts(pool: &Pool) -> sqlx::Result<(i64, i64)> {
    sqlx::query_as("SELECT (SELECT COUNT(*) FROM agents), (SELECT COUNT(*) FROM rallies)")
        .fetch_one(pool)
        .await
}

/// SPRTs per status (`sprt_STATUS`) and tournaments (`tournaments`), as (name, count).
pub async fn contest_tallies(pool: &Pool) -> sqlx::Result<Vec<(String, i64)>> {
    sqlx::query_as(
        "SELECT 'sprt_' || status, COUNT(*) FROM sprts GROUP BY status UNION ALL SELECT 'tournaments', COUNT(*) FROM tournaments",
    )
    .fetch_all(pool)
    .await
}

/// (agents plus retired agents, finished matches): each only grows, with every agent added or
/// retired and every match finished, so robot `model`'s leaderboard is recomputed when either of
/// its own changed.
pub async fn board_key(pool: &Pool, model: &str) -> sqlx::Result<(i64, i64)> {
    sqlx::query_as(
        "SELECT (SELECT COUNT(*) + COUNT(retired_at) FROM agents WHERE model = $1), (SELECT COUNT(*) FROM matches WHERE status = 'done' AND model = $1)",
    )
    .bind(model)
    .fetch_one(pool)
    .await
}

/// Per agent, its cooperative matches (against itself) neither cancelled nor failed, as (agent id,
/// count), of robot `model`; agents without any are absent.
pub async fn self_play_counts(pool: &Pool, model: &str) -> sqlx::Result<Vec<(i64, i64)>> {
    sqlx::query_as(
        "SELECT agent_a, COUNT(*) FROM matches WHERE agent_a = agent_b AND model = $1 AND status <> 'cancelled' AND status <> 'failed' GROUP BY agent_a",
    )
    .bind(model)
    .fetch_all(pool)
    .await
}

/// The (A, B) agent ids of every running match of robot `model`.
pub async fn running_pairs(pool: &Pool, model: &str) -> sqlx::Result<Vec<(i64, i64)>> {
    sqlx::query_as("SELECT agent_a, agent_b FROM matches WHERE status = 'running' AND model = $1")
        .bind(model)
        .fetch_all(pool)
        .await
}

/// Matches ever queued of robot `model`.
pub async fn match_count(pool: &Pool, model: &str) -> sqlx::Result<i64> {
    sqlx::query_scalar("SELECT COUNT(*) FROM matches WHERE model = $1")
        .bind(model)
        .fetch_one(pool)
        .await
}

/// The highest match id so far (0 with none).
pub async fn last_match_id(pool: &Pool) -> sqlx::Result<i64> {
    sqlx::query_scalar("SELECT COALESCE(MAX(id), 0) FROM matches")
        .fetch_one(pool)
        .await
}
