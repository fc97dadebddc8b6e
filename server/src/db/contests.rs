//! Tournaments and SPRTs (the API's `api/contests.rs`): creating, reading, cancelling, and the SPRT's
//! step after each of its matches.

use super::*;

/// A tournament to create: its agents and the (side A, side B) index pairs of its matches.
#[derive(Debug, Clone, Copy)]
pub struct TournamentPlan<'a> {
    /// Round robin or gauntlet.
    pub kind: wire::TournamentKind,
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
pub async fn create_tournament(pool: &Pool, plan: TournamentPlan<'_>) -> sqlx::Result<i64> {
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
    let t: i64 = sqlx::query_scalar("INSERT INTO tournaments (kind, agents_json, rallies_per_match, rounds, seed, created_by) VALUES ($1, $2, $3, $4, $5, $6) RETURNING id")
        .bind(kind.as_str())
        .bind(serde_json::to_string(&ids).unwrap_or_default())
        .bind(rallies as i64)
        .bind(rounds as i64)
        .bind(seed as i64)
        .bind(created_by)
        .fetch_one(&mut *tx)
        .await?;
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
pub async fn tournament(pool: &Pool, id: i64) -> sqlx::Result<Option<Tournament>> {
    sqlx::query_as::<_, Row<Tournament>>("SELECT id, kind, agents_json, rallies_per_match, rounds, seed, created_by, created_at FROM tournaments WHERE id = $1")
        .bind(id)
        .fetch_optional(pool)
        .await
        .map(row)
}

/// Tournaments, newest first.
pub async fn tournaments(pool: &Pool, limit: i64) -> sqlx::Result<Vec<Tournament>> {
    sqlx::query_as::<_, Row<Tournament>>("SELECT id, kind, agents_json, rallies_per_match, rounds, seed, created_by, created_at FROM tournaments ORDER BY id DESC LIMIT $1")
        .bind(limit)
        .fetch_all(pool)
        .await
        .map(rows)
}

/// A tournament's matches in the order they were queued.
pub async fn tournament_matches(pool: &Pool, id: i64) -> sqlx::Result<Vec<Match>> {
    sqlx::query_as::<_, Row<Match>>(&format!(
        "SELECT {cols} FROM matches WHERE tournament_id = $1 ORDER BY id",
        cols = match_columns()
    ))
    .bind(id)
    .fetch_all(pool)
    .await
    .map(rows)
}

/// Cancels a tournament's queued and running matches; how many.
pub async fn cancel_tournament(pool: &Pool, id: i64) -> sqlx::Result<u64> {
    let r = sqlx::query("UPDATE matches SET status = 'cancelled', finished_at = $2 WHERE tournament_id = $1 AND status IN ('queued', 'running')")
        .bind(id)
        .bind(crate::db::now_text())
        .execute(pool)
        .await?;
    Ok(r.rows_affected())
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
    pool: &Pool,
    a: &Agent,
    b: &Agent,
    p: SprtParams,
    created_by: Option<i64>,
) -> sqlx::Result<i64> {
    let mut tx = pool.begin().await?;
    let id: i64 = sqlx::query_scalar("INSERT INTO sprts (agent_a, agent_b, elo0, elo1, alpha, beta, rallies_per_match, max_matches, seed, status, created_by) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, 'running', $10) RETURNING id")
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
        .fetch_one(&mut *tx)
        .await?;
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
pub async fn sprt(pool: &Pool, id: i64) -> sqlx::Result<Option<Sprt>> {
    sqlx::query_as::<_, Row<Sprt>>(&format!("SELECT {SPRT_COLUMNS} FROM sprts WHERE id = $1"))
        .bind(id)
        .fetch_optional(pool)
        .await
        .map(row)
}

/// SPRTs, newest first.
pub async fn sprts(pool: &Pool, limit: i64) -> sqlx::Result<Vec<Sprt>> {
    sqlx::query_as::<_, Row<Sprt>>(&format!(
        "SELECT {SPRT_COLUMNS} FROM sprts ORDER BY id DESC LIMIT $1"
    ))
    .bind(limit)
    .fetch_all(pool)
    .await
    .map(rows)
}

/// An SPRT's matches in order.
pub async fn sprt_matches(pool: &Pool, id: i64) -> sqlx::Result<Vec<Match>> {
    sqlx::query_as::<_, Row<Match>>(&format!(
        "SELECT {cols} FROM matches WHERE sprt_id = $1 ORDER BY id",
        cols = match_columns()
    ))
    .bind(id)
    .fetch_all(pool)
    .await
    .map(rows)
}

/// Ends a running SPRT with `status` and cancels its unfinished matches; false if it had ended.
pub async fn end_sprt(
    conn: &mut sqlx::AnyConnection,
    id: i64,
    status: SprtStatus,
) -> sqlx::Result<bool> {
    let r = sqlx::query(
        "UPDATE sprts SET status = $1, finished_at = $3 WHERE id = $2 AND status = 'running'",
    )
    .bind(status.as_str())
    .bind(id)
    .bind(crate::db::now_text())
    .execute(&mut *conn)
    .await?;
    sqlx::query("UPDATE matches SET status = 'cancelled', finished_at = $2 WHERE sprt_id = $1 AND status IN ('queued', 'running')")
        .bind(id)
        .bind(crate::db::now_text())
        .execute(&mut *conn)
        .await?;
    Ok(r.rows_affected() == 1)
}

/// Cancels a running SPRT (one transaction); false if it had ended.
pub async fn cancel_sprt(pool: &Pool, id: i64) -> sqlx::Result<bool> {
    let mut tx = pool.begin().await?;
    let ended = end_sprt(&mut tx, id, SprtStatus::Cancelled).await?;
    tx.commit().await?;
    Ok(ended)
}

/// After one of its matches finished (inside the transaction that stored it): reads the SPRT and its
/// finished matches, lets `domain::sprt_step` decide, and writes the decision (and the next match,
/// if it goes on). One match at a time, so the test's course depends only on its seeds. SPRT
/// matches keep no replay frames (the replay endpoint re-simulates a rally on request).
pub(super) async fn sprt_step(conn: &mut sqlx::AnyConnection, id: i64) -> sqlx::Result<()> {
    let s: Option<Sprt> =
        sqlx::query_as::<_, Row<Sprt>>(&format!("SELECT {SPRT_COLUMNS} FROM sprts WHERE id = $1"))
            .bind(id)
            .fetch_optional(&mut *conn)
            .await
            .map(row)?;
    let Some(s) = s.filter(|s| s.status == SprtStatus::Running) else {
        return Ok(());
    };
    let done: Vec<(i64, i64, i64)> = sqlx::query_as("SELECT agent_a, points_a, points_b FROM matches WHERE sprt_id = $1 AND status = 'done' ORDER BY id")
        .bind(id)
        .fetch_all(&mut *conn)
        .await?;
    let step = crate::domain::sprt_step(&s, &done);
    sqlx::query("UPDATE sprts SET llr = $1, matches_done = $2, status = $3, finished_at = CASE WHEN $4 = 'running' THEN NULL ELSE $6 END WHERE id = $5")
        .bind(step.llr)
        .bind(step.matches_done as i64)
        .bind(step.status.as_str())
        .bind(step.status.as_str())
        .bind(id)
        .bind(crate::db::now_text())
        .execute(&mut *conn)
        .await?;
    let Some(next) = step.next else {
        return Ok(());
    };
    let sql = format!("SELECT {AGENT_COLUMNS} FROM agents WHERE id = $1");
    let agent = |id: i64| sqlx::query_as::<_, Row<Agent>>(&sql).bind(id);
    let a = agent(next.a).fetch_one(&mut *conn).await?.0;
    let b = agent(next.b).fetch_one(&mut *conn).await?.0;
    let origin = Origin {
        tournament: None,
        sprt: Some(id),
        created_by: s.created_by,
    };
    queue_match(&mut *conn, &a, &b, next.rallies, next.seed, false, origin).await?;
    Ok(())
}
