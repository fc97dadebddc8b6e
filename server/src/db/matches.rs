//! Matches: queueing, the list, storing a played match (with its rallies, crossings, replay, drift,
//! ratings and SPRT step) or its failure under the worker's lease, cancelling; rallies and replays.

use super::*;

/// The columns of a [`Match`]; `outdated` compares the stored simulator version with this build's
/// (a constant of ours, digits and dots only).
pub(super) fn match_columns() -> String {
    format!(
        "id, agent_a, agent_b, model, rallies, seed, preset, sim_version, sim_version <> '{}' AS outdated, spec_hash_a, spec_hash_b, keep_replay, replay_bytes, status, created_at, started_at, finished_at, points_a, points_b, mean_rally_length, max_rally_length, in_box_fraction, energy_distance, drift_slope, error, tournament_id, sprt_id, created_by, worker, attempts",
        sim::SIM_VERSION
    )
}

/// A queued match row for tests (nothing played, no tournament or SPRT).
#[cfg(test)]
pub(crate) fn example_match(id: i64, agent_a: i64, agent_b: i64) -> Match {
    Match {
        id,
        agent_a,
        agent_b,
        model: "default".into(),
        rallies: 10,
        seed: id,
        preset: "myochallenge".into(),
        sim_version: String::new(),
        outdated: false,
        spec_hash_a: String::new(),
        spec_hash_b: String::new(),
        keep_replay: true,
        replay_bytes: 0,
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

/// Queues a match (on the pool or inside a transaction) between two agents of one robot (the API
/// refuses others, naming the side; here they are an error that stores nothing).
pub async fn queue_match<'c, E: sqlx::AnyExecutor<'c>>(
    db: E,
    a: &Agent,
    b: &Agent,
    rallies: u32,
    seed: u64,
    keep_replay: bool,
    origin: Origin,
) -> sqlx::Result<i64> {
    if a.model != b.model {
        return Err(sqlx::Error::Protocol(format!(
            "agents {} and {} play different robots ({} and {})",
            a.id, b.id, a.model, b.model
        )));
    }
    sqlx::query_scalar(
        "INSERT INTO matches (agent_a, agent_b, rallies, seed, preset, sim_version, spec_hash_a, spec_hash_b, keep_replay, status, tournament_id, sprt_id, created_by, model) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, 'queued', $10, $11, $12, $13) RETURNING id",
    )
    .bind(a.id)
    .bind(b.id)
    .bind(rallies as i64)
    .bind(seed as i64)
    .bind(sim::arena::MYOCHALLENGE.name)
    .bind(sim::SIM_VERSION)
    .bind(&a.spec_hash)
    .bind(&b.spec_hash)
    .bind(keep_replay as i64)
    .bind(origin.tournament)
    .bind(origin.sprt)
    .bind(origin.created_by)
    .bind(&a.model)
    .fetch_one(db)
    .await
}

/// One match.
pub async fn match_row(pool: &Pool, id: i64) -> sqlx::Result<Option<Match>> {
    sqlx::query_as::<_, Row<Match>>(&format!(
        "SELECT {} FROM matches WHERE id = $1",
        match_columns()
    ))
    .bind(id)
    .fetch_optional(pool)
    .await
    .map(row)
}

/// Which matches to list.
#[derive(Debug, Clone, Default)]
pub struct MatchFilter {
    /// Only those this agent played.
    pub agent: Option<i64>,
    /// Only those of this robot.
    pub model: Option<String>,
    /// Only those in this status.
    pub status: Option<MatchStatus>,
    /// Only those with a smaller id (the next page after the last id seen).
    pub before: Option<i64>,
}

/// Matches, newest first, filtered.
pub async fn matches(pool: &Pool, filter: MatchFilter, limit: i64) -> sqlx::Result<Vec<Match>> {
    sqlx::query_as::<_, Row<Match>>(&format!(
        "SELECT {cols} FROM matches WHERE ($1 IS NULL OR agent_a = $1 OR agent_b = $1) AND ($2 IS NULL OR status = $2) AND ($3 IS NULL OR id < $3) AND ($5 IS NULL OR model = $5) ORDER BY id DESC LIMIT $4",
        cols = match_columns()
    ))
    .bind(filter.agent)
    .bind(filter.status.map(MatchStatus::as_str))
    .bind(filter.before)
    .bind(limit)
    .bind(filter.model)
    .fetch_all(pool)
    .await
    .map(rows)
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

/// A played match's replay frames as stored: each rally that kept frames, its index and its frames'
/// JSON gzip-compressed. Blocking (a long match's frames take seconds): call it off the async
/// threads, before [`store_result`].
pub fn compress_replay(
    r: &MatchRecord,
    replay: &::agents::matchrun::Replay,
) -> Vec<(i64, Vec<u8>)> {
    r.rallies
        .iter()
        .filter_map(|rally| {
            let f = replay.get(rally.index as usize).filter(|f| !f.is_empty())?;
            Some((rally.index as i64, gzip_json(f)))
        })
        .collect()
}

/// Stores a played match — rallies, crossings, replay (as [`compress_replay`] made it), summary,
/// ratings, SPRT step — and marks it done, in one transaction, under the worker's current lease
/// (see [`workers`]). A match a submitter token asked for keeps its frames only while that token's
/// stored replays stay within `replay_quota_bytes`; past it the match keeps none (its rallies are
/// re-simulated when watched, as continuous-mode ones are).
pub async fn store_result(
    pool: &Pool,
    lease: &Lease,
    r: &MatchRecord,
    frames: &[(i64, Vec<u8>)],
    replay_quota_bytes: u64,
) -> sqlx::Result<Stored> {
    let id = lease.match_id;
    // The first statement writes, so the transaction takes the write lock at once (waiting out other
    // writers) instead of upgrading a read lock later.
    let mut tx = pool.begin().await?;
    serialise_writers(pool, &mut tx).await?;
    let marked: Option<(i64, i64, Option<i64>, Option<i64>)> = sqlx::query_as(
        "UPDATE matches SET status = 'done', finished_at = $12, points_a = $1, points_b = $2, mean_rally_length = $3, max_rally_length = $4, in_box_fraction = $5, energy_distance = $6, drift_slope = $7, drift_json = $8 WHERE id = $9 AND status = 'running' AND worker = $10 AND attempts = $11 RETURNING agent_a, agent_b, sprt_id, created_by",
    )
    .bind(r.points[0] as i64)
    .bind(r.points[1] as i64)
    .bind(r.mean_rally_length)
    .bind(r.max_rally_length as i64)
    // A share of no crossings is none, not 0 (it would weigh as a miss in every average).
    .bind((r.drift.crossings > 0).then_some(r.drift.in_box_fraction))
    .bind(r.drift.energy_distance)
    .bind(r.drift.drift_slope)
    .bind(serde_json::to_string(&r.drift).unwrap_or_default())
    .bind(id)
    .bind(&lease.worker)
    .bind(lease.attempt)
    .bind(crate::db::now_text())
    .persistent(false) // NULL_F64: see below
    .fetch_optional(&mut *tx)
    .await?;
    let Some((agent_a, agent_b, sprt_id, created_by)) = marked else {
        tx.rollback().await?;
        return lost_or_cancelled(pool, id).await;
    };
    sqlx::query("UPDATE matches SET lease_expires_ms = NULL WHERE id = $1")
        .bind(id)
        .execute(&mut *tx)
        .await?;
    sqlx::query("UPDATE workers SET matches_played = matches_played + 1 WHERE name = $1")
        .bind(&lease.worker)
        .execute(&mut *tx)
        .await?;
    store_drift(&mut tx, id, [agent_a, agent_b], r).await?;
    store_ratings(&mut tx, id, [agent_a, agent_b], r.points).await?;
    store_rallies(&mut tx, id, r).await?;
    let bytes: i64 = frames.iter().map(|(_, blob)| blob.len() as i64).sum();
    let keep = match created_by {
        Some(token) if bytes > 0 => {
            let used: i64 = sqlx::query_scalar(
                "SELECT CAST(COALESCE(SUM(replay_bytes), 0) AS BIGINT) FROM matches WHERE created_by = $1",
            )
            .bind(token)
            .fetch_one(&mut *tx)
            .await?;
            let keep = (used + bytes) as u64 <= replay_quota_bytes;
            if !keep {
                tracing::info!(
                    id,
                    token,
                    used,
                    bytes,
                    "the token's replay quota is spent: the match keeps no frames (re-simulated when watched)"
                );
            }
            keep
        }
        _ => true,
    };
    if keep {
        for (rally, blob) in frames {
            sqlx::query("INSERT INTO replays (match_id, rally_idx, frames_gz) VALUES ($1, $2, $3)")
                .bind(id)
                .bind(rally)
                .bind(blob)
                .execute(&mut *tx)
                .await?;
        }
        sqlx::query("UPDATE matches SET replay_bytes = $1 WHERE id = $2")
            .bind(bytes)
            .bind(id)
            .execute(&mut *tx)
            .await?;
    } else {
        sqlx::query("UPDATE matches SET keep_replay = 0 WHERE id = $1")
            .bind(id)
            .execute(&mut *tx)
            .await?;
    }
    if let Some(sprt) = sprt_id {
        sprt_step(&mut tx, sprt).await?;
    }
    tx.commit().await?;
    Ok(Stored::Done)
}

/// Each side's drift over the match (inside the match's transaction).
async fn store_drift(
    conn: &mut sqlx::AnyConnection,
    id: i64,
    [agent_a, agent_b]: [i64; 2],
    r: &MatchRecord,
) -> sqlx::Result<()> {
    for (side, agent, d) in [
        ("A", agent_a, &r.drift_by_player[0]),
        ("B", agent_b, &r.drift_by_player[1]),
    ] {
        sqlx::query("INSERT INTO match_drift (match_id, side, agent_id, crossings, in_box_fraction, energy_distance, drift_slope, drift_json) VALUES ($1, $2, $3, $4, $5, $6, $7, $8)")
            .bind(id)
            .bind(side)
            .bind(agent)
            .bind(d.crossings as i64)
            // Weighed by its crossings wherever it is averaged: with none it counts for nothing.
            .bind(d.in_box_fraction)
            .bind(d.energy_distance)
            .bind(d.drift_slope)
            .bind(serde_json::to_string(d).unwrap_or_default())
            // NULL_F64: sqlx's Any driver sends a missing f64 to PostgreSQL as a float4 NULL, and a
            // statement prepared (and cached) with that type then refuses the next real f64
            // ("incorrect binary data format"): statements that may bind a None f64 are not cached.
            .persistent(false)
            .execute(&mut *conn)
            .await?;
    }
    Ok(())
}

/// Both sides' Glicko-2 after the match, from their last ratings: `domain::rating_update` decides.
async fn store_ratings(
    conn: &mut sqlx::AnyConnection,
    id: i64,
    [agent_a, agent_b]: [i64; 2],
    points: [u32; 2],
) -> sqlx::Result<()> {
    let last = |agent: i64| {
        sqlx::query_as::<_, (f64, f64, f64)>("SELECT rating, deviation, volatility FROM rating_history WHERE agent_id = $1 ORDER BY seq DESC LIMIT 1").bind(agent)
    };
    let prior = [
        last(agent_a).fetch_optional(&mut *conn).await?,
        last(agent_b).fetch_optional(&mut *conn).await?,
    ];
    for (agent, g) in crate::domain::rating_update([agent_a, agent_b], prior, points) {
        sqlx::query("INSERT INTO rating_history (match_id, agent_id, rating, deviation, volatility) VALUES ($1, $2, $3, $4, $5)")
            .bind(id)
            .bind(agent)
            .bind(g.0)
            .bind(g.1)
            .bind(g.2)
            .execute(&mut *conn)
            .await?;
    }
    Ok(())
}

/// The match's rallies and their crossings.
async fn store_rallies(
    conn: &mut sqlx::AnyConnection,
    id: i64,
    r: &MatchRecord,
) -> sqlx::Result<()> {
    for rally in &r.rallies {
        sqlx::query("INSERT INTO rallies (match_id, idx, server, length, end_reason, failing_side, duration) VALUES ($1, $2, $3, $4, $5, $6, $7)")
            .bind(id)
            .bind(rally.index as i64)
            .bind(rally.server)
            .bind(rally.length as i64)
            .bind(rally.end)
            .bind(rally.failing_side)
            .bind(rally.duration)
            .execute(&mut *conn)
            .await?;
        for (seq, c) in rally.crossings.iter().enumerate() {
            sqlx::query("INSERT INTO crossings (match_id, rally_idx, seq, receiver, exchange, y_r, z, in_box, extrapolated) VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9)")
                .bind(id)
                .bind(rally.index as i64)
                .bind(seq as i64)
                .bind(c.receiver)
                .bind(c.exchange as i64)
                .bind(c.y_r)
                .bind(c.z)
                .bind(c.in_box as i64)
                .bind(c.extrapolated as i64)
                .execute(&mut *conn)
                .await?;
        }
    }
    Ok(())
}

/// Why a worker's write under its lease matched no row: the match was cancelled, or the lease lost.
async fn lost_or_cancelled(pool: &Pool, id: i64) -> sqlx::Result<Stored> {
    let status: Option<String> = sqlx::query_scalar("SELECT status FROM matches WHERE id = $1")
        .bind(id)
        .fetch_optional(pool)
        .await?;
    Ok(
        match status.as_deref().map(|s| word(s, "status")).transpose()? {
            Some(MatchStatus::Cancelled) => Stored::Cancelled,
            _ => Stored::LeaseLost,
        },
    )
}

/// Marks a running match failed with a reason, under the worker's current lease; an SPRT it belonged
/// to fails with it (one transaction).
pub async fn fail(pool: &Pool, lease: &Lease, error: &str) -> sqlx::Result<Stored> {
    let mut tx = pool.begin().await?;
    serialise_writers(pool, &mut tx).await?;
    let sprt: Option<(Option<i64>,)> = sqlx::query_as("UPDATE matches SET status = 'failed', finished_at = $5, error = $1, lease_expires_ms = NULL WHERE id = $2 AND status = 'running' AND worker = $3 AND attempts = $4 RETURNING sprt_id")
        .bind(error)
        .bind(lease.match_id)
        .bind(&lease.worker)
        .bind(lease.attempt)
        .bind(crate::db::now_text())
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
pub async fn cancel(pool: &Pool, id: i64) -> sqlx::Result<bool> {
    let mut tx = pool.begin().await?;
    let r: Option<(Option<i64>,)> = sqlx::query_as("UPDATE matches SET status = 'cancelled', finished_at = $2 WHERE id = $1 AND status IN ('queued', 'running') RETURNING sprt_id")
        .bind(id)
        .bind(crate::db::now_text())
        .fetch_optional(&mut *tx)
        .await?;
    if let Some((Some(sprt),)) = r {
        end_sprt(&mut tx, sprt, SprtStatus::Cancelled).await?;
    }
    tx.commit().await?;
    Ok(r.is_some())
}

/// A match's rallies.
pub async fn rallies(pool: &Pool, id: i64) -> sqlx::Result<Vec<Rally>> {
    sqlx::query_as::<_, Row<Rally>>("SELECT idx, server, length, end_reason, failing_side, duration FROM rallies WHERE match_id = $1 ORDER BY idx")
        .bind(id)
        .fetch_all(pool)
        .await
        .map(rows)
}

/// A rally's stored replay frames, gzip-compressed JSON ([`gunzip`] them off the async threads).
pub async fn replay(pool: &Pool, id: i64, rally: i64) -> anyhow::Result<Option<Vec<u8>>> {
    let r: Option<(Vec<u8>,)> =
        sqlx::query_as("SELECT frames_gz FROM replays WHERE match_id = $1 AND rally_idx = $2")
            .bind(id)
            .bind(rally)
            .fetch_optional(pool)
            .await?;
    Ok(r.map(|(gz,)| gz))
}

/// Stored replay frames decompressed (blocking).
pub fn gunzip(gz: &[u8]) -> std::io::Result<String> {
    let mut text = String::new();
    std::io::Read::read_to_string(&mut flate2::read::GzDecoder::new(gz), &mut text)?;
    Ok(text)
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
pub async fn drift(pool: &Pool, id: i64) -> sqlx::Result<Option<String>> {
    let r: Option<(Option<String>,)> =
        sqlx::query_as("SELECT drift_json FROM matches WHERE id = $1")
            .bind(id)
            .fetch_optional(pool)
            .await?;
    Ok(r.and_then(|x| x.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn a_match_of_another_simulator_version_says_it_is_outdated() {
        let pool = test_store("outdated").await;
        register_builtins(&pool, "default").await.unwrap();
        let all = agents(&pool).await.unwrap();
        let (a, b) = (&all[0], &all[1]);
        let now = queue_match(&pool, a, b, 2, 1, true, Origin::default())
            .await
            .unwrap();
        let old = queue_match(&pool, a, b, 2, 2, true, Origin::default())
            .await
            .unwrap();
        sqlx::query("UPDATE matches SET sim_version = '0.1.0' WHERE id = $1")
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
    }
}
