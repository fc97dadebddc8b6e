//! Workers and leases (docs/design.md §12, migration 0004): who plays which running match, until when.
//!
//! A claim takes the oldest queued match and gives it a lease: the claiming worker's name, an expiry
//! and the claim's number (`attempts`, one more than the last claim's). The worker's heartbeat
//! renews the leases of every match it holds; a match whose lease ran out is queued again by whoever
//! claims next. A result (done or failed) is written only under the claim that is current — same
//! worker, same number, still running — so a worker that lost its lease and finishes anyway is
//! refused, and no match is ever stored twice. Times are Unix milliseconds from the processes'
//! clocks: workers on several machines need clocks that agree to well within a lease.

use super::{rows, Pool, Row};
pub use wire::Worker;

/// Now, in Unix milliseconds.
pub fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis() as i64)
        .unwrap_or(0)
}

/// The claim a worker holds on a running match: store its result under it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Lease {
    /// The match.
    pub match_id: i64,
    /// The holder's worker name.
    pub worker: String,
    /// The claim's number.
    pub attempt: i64,
}

/// Queues again every running match whose lease ran out before `now` (its worker died, hung or lost
/// the database), and any running match without a lease (left by a version before leases). Returns
/// how many.
pub async fn requeue_expired(pool: &Pool, now: i64) -> sqlx::Result<u64> {
    let r = sqlx::query(
        "UPDATE matches SET status = 'queued', started_at = NULL, worker = NULL, lease_expires_ms = NULL \
         WHERE status = 'running' AND (lease_expires_ms IS NULL OR lease_expires_ms < $1)",
    )
    .bind(now)
    .execute(pool)
    .await?;
    Ok(r.rows_affected())
}

/// Queues again every running match held by `worker` (a worker starting under a name gives back what
/// a previous process of that name held: it holds nothing yet). Returns how many.
pub async fn requeue_held_by(pool: &Pool, worker: &str) -> sqlx::Result<u64> {
    let r = sqlx::query(
        "UPDATE matches SET status = 'queued', started_at = NULL, worker = NULL, lease_expires_ms = NULL \
         WHERE status = 'running' AND worker = $1",
    )
    .bind(worker)
    .execute(pool)
    .await?;
    Ok(r.rows_affected())
}

/// Gives a running match back to the queue under the worker's lease (a process shutting down that
/// stopped it mid-way: nothing of it was stored); false if the lease was lost meanwhile.
pub async fn release(pool: &Pool, lease: &Lease) -> sqlx::Result<bool> {
    let r = sqlx::query(
        "UPDATE matches SET status = 'queued', started_at = NULL, worker = NULL, lease_expires_ms = NULL \
         WHERE id = $1 AND status = 'running' AND worker = $2 AND attempts = $3",
    )
    .bind(lease.match_id)
    .bind(&lease.worker)
    .bind(lease.attempt)
    .execute(pool)
    .await?;
    Ok(r.rows_affected() == 1)
}

/// Claims the oldest queued match for `worker` with a lease of `lease_ms` (queued → running) in one
/// statement (SQLite's single `UPDATE … RETURNING`; on PostgreSQL with `FOR UPDATE SKIP LOCKED`), so
/// two workers never take the same match; expired leases are queued again first. Only matches of
/// the robots in `models` (those this worker has loaded): another worker plays the rest.
pub async fn claim(
    pool: &Pool,
    worker: &str,
    lease_ms: i64,
    models: &[&str],
) -> sqlx::Result<Option<(super::Match, Lease)>> {
    if models.is_empty() {
        return Ok(None);
    }
    let now = now_ms();
    requeue_expired(pool, now).await?;
    // The oldest queued match, taken in one statement. On PostgreSQL, `FOR UPDATE SKIP LOCKED` lets
    // concurrent claims pass over a row another worker is taking (without it, the loser of a race
    // would wait for that row and then find it running: no match, though others are queued).
    let skip_locked = match super::Engine::of(pool) {
        super::Engine::Postgres => " FOR UPDATE SKIP LOCKED",
        super::Engine::Sqlite => "",
    };
    let robots = (0..models.len())
        .map(|k| format!("${}", k + 4))
        .collect::<Vec<_>>()
        .join(", ");
    let sql = format!(
        "UPDATE matches SET status = 'running', started_at = $3, worker = $1, \
         lease_expires_ms = $2, attempts = attempts + 1 \
         WHERE id = (SELECT id FROM matches WHERE status = 'queued' AND model IN ({robots}) ORDER BY id LIMIT 1{skip_locked}) \
         AND status = 'queued' RETURNING id, attempts",
    );
    let mut query = sqlx::query_as(&sql)
        .bind(worker)
        .bind(now + lease_ms)
        .bind(crate::db::now_text());
    for m in models {
        query = query.bind(*m);
    }
    let row: Option<(i64, i64)> = query.fetch_optional(pool).await?;
    let Some((id, attempt)) = row else {
        return Ok(None);
    };
    let m = super::match_row(pool, id)
        .await?
        .ok_or(sqlx::Error::RowNotFound)?;
    Ok(Some((
        m,
        Lease {
            match_id: id,
            worker: worker.to_string(),
            attempt,
        },
    )))
}

/// Registers worker `name` as running (a new row, or the row of a previous process of that name),
/// refusing when a running worker of that name beat less than `lease_ms` ago: two live processes
/// must not share a name. Gives back what a previous process of the name held.
pub async fn register(
    pool: &Pool,
    name: &str,
    host: &str,
    pid: u32,
    slots: usize,
    lease_ms: i64,
) -> anyhow::Result<()> {
    let now = now_ms();
    let live: Option<(i64, String, i64)> = sqlx::query_as(
        "SELECT heartbeat_ms, host, pid FROM workers WHERE name = $1 AND status = 'running'",
    )
    .bind(name)
    .fetch_optional(pool)
    .await?;
    if let Some((beat, h, p)) = live {
        let same_process = h == host && p == pid as i64;
        if now - beat < lease_ms && !same_process {
            anyhow::bail!(
                "a worker named '{name}' ({h}, pid {p}) beat {:.1} s ago: give this one another --name, or wait {:.0} s if that process is gone",
                (now - beat) as f64 / 1000.0,
                lease_ms as f64 / 1000.0
            );
        }
    }
    sqlx::query(
        "INSERT INTO workers (name, host, pid, slots, started_ms, heartbeat_ms, status) VALUES ($1, $2, $3, $4, $5, $6, 'running') \
         ON CONFLICT (name) DO UPDATE SET host = excluded.host, pid = excluded.pid, slots = excluded.slots, \
         started_ms = excluded.started_ms, heartbeat_ms = excluded.heartbeat_ms, status = 'running'",
    )
    .bind(name)
    .bind(host)
    .bind(pid as i64)
    .bind(slots as i64)
    .bind(now)
    .bind(now)
    .execute(pool)
    .await?;
    requeue_held_by(pool, name).await?;
    Ok(())
}

/// The heartbeat of worker `name`: its row's time, and every lease it holds renewed to `lease_ms`
/// from now (one transaction). Returns the number of leases renewed.
pub async fn heartbeat(pool: &Pool, name: &str, lease_ms: i64) -> sqlx::Result<u64> {
    let now = now_ms();
    let mut tx = pool.begin().await?;
    let renewed = sqlx::query(
        "UPDATE matches SET lease_expires_ms = $1 WHERE status = 'running' AND worker = $2",
    )
    .bind(now + lease_ms)
    .bind(name)
    .execute(&mut *tx)
    .await?
    .rows_affected();
    sqlx::query("UPDATE workers SET heartbeat_ms = $1, status = 'running' WHERE name = $2")
        .bind(now)
        .bind(name)
        .execute(&mut *tx)
        .await?;
    tx.commit().await?;
    Ok(renewed)
}

/// Marks worker `name` stopped (it finished its matches and exits).
pub async fn stopped(pool: &Pool, name: &str) -> sqlx::Result<()> {
    sqlx::query("UPDATE workers SET status = 'stopped', heartbeat_ms = $1 WHERE name = $2")
        .bind(now_ms())
        .bind(name)
        .execute(pool)
        .await?;
    Ok(())
}

/// Every worker that ever registered, the most recent heartbeat first.
pub async fn workers(pool: &Pool) -> sqlx::Result<Vec<Worker>> {
    sqlx::query_as::<_, Row<Worker>>("SELECT name, host, pid, slots, started_ms, heartbeat_ms, matches_played, status FROM workers ORDER BY heartbeat_ms DESC, name")
        .fetch_all(pool)
        .await
        .map(rows)
}

/// The running matches (id and lease holder).
pub async fn running(pool: &Pool) -> sqlx::Result<Vec<(i64, Option<String>)>> {
    sqlx::query_as("SELECT id, worker FROM matches WHERE status = 'running' ORDER BY id")
        .fetch_all(pool)
        .await
}

/// What the server's watcher looks at: every match not finished yet (queued or running) and every
/// match with an id above `after` (new since its last look, finished or not), with status and
/// worker, by id.
pub async fn watched(
    pool: &Pool,
    after: i64,
) -> sqlx::Result<Vec<(i64, crate::domain::MatchStatus, Option<String>)>> {
    let found: Vec<(i64, String, Option<String>)> = sqlx::query_as(
        "SELECT id, status, worker FROM matches \
         WHERE status IN ('queued', 'running') OR id > $1 ORDER BY id",
    )
    .bind(after)
    .fetch_all(pool)
    .await?;
    found
        .into_iter()
        .map(|(id, status, worker)| Ok((id, super::word(&status, "status")?, worker)))
        .collect()
}

/// The highest match id so far (0 when there is none).
pub async fn last_match_id(pool: &Pool) -> sqlx::Result<i64> {
    sqlx::query_scalar("SELECT COALESCE(MAX(id), 0) FROM matches")
        .fetch_one(pool)
        .await
}

/// A match's status and worker now, if it exists.
pub async fn status_of(
    pool: &Pool,
    id: i64,
) -> sqlx::Result<Option<(crate::domain::MatchStatus, Option<String>)>> {
    let found: Option<(String, Option<String>)> =
        sqlx::query_as("SELECT status, worker FROM matches WHERE id = $1")
            .bind(id)
            .fetch_optional(pool)
            .await?;
    found
        .map(|(status, worker)| Ok((super::word(&status, "status")?, worker)))
        .transpose()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::db::{self, Stored};

    /// A fresh store with the built-ins and one queued 1-rally match of the first two, seed `seed`.
    async fn queued_match(tag: &str, seed: u64) -> (Pool, Vec<db::Agent>, i64) {
        let pool = db::test_store(tag).await;
        db::register_builtins(&pool, "default").await.unwrap();
        let all = db::agents(&pool).await.unwrap();
        let id = db::queue_match(
            &pool,
            &all[0],
            &all[1],
            1,
            seed,
            false,
            db::Origin::default(),
        )
        .await
        .unwrap();
        (pool, all, id)
    }

    /// That match played: one rally of the scripted agent against itself.
    fn one_rally(seed: u64) -> (agents::matchrun::MatchRecord, agents::matchrun::Replay) {
        let spec = agents::matchrun::MatchSpec {
            model: std::sync::Arc::new(sim::config::default_model()),
            config: sim::config::ArenaConfig::default(),
            preset: sim::arena::MYOCHALLENGE,
            rallies: 1,
            seed,
            replay: false,
        };
        let scripted = agents::factory::PlayerSpec::scripted("scripted").unwrap();
        agents::matchrun::play_match(&spec, &scripted, &scripted, &mut |_| {}).unwrap()
    }

    #[tokio::test]
    async fn a_result_reported_after_the_lease_ran_out_is_refused_and_the_new_holder_stores_once() {
        let (pool, _, id) = queued_match("lease", 1).await;
        register(&pool, "old", "h", 1, 1, 60_000).await.unwrap();
        register(&pool, "new", "h", 2, 1, 60_000).await.unwrap();
        // A live name is not taken twice.
        let taken = register(&pool, "old", "h", 3, 1, 60_000).await.unwrap_err();
        assert!(
            taken.to_string().contains("a worker named 'old'"),
            "{taken}"
        );

        let (m, stale) = claim(&pool, "old", 60_000, &["default"])
            .await
            .unwrap()
            .unwrap();
        assert_eq!((m.id, stale.attempt, m.status.as_str()), (id, 1, "running"));
        assert!(
            claim(&pool, "new", 60_000, &["default"])
                .await
                .unwrap()
                .is_none(),
            "claimed once"
        );
        // A heartbeat renews the lease; a lease in the past is queued again at the next claim.
        assert_eq!(heartbeat(&pool, "old", 60_000).await.unwrap(), 1);
        assert_eq!(requeue_expired(&pool, now_ms()).await.unwrap(), 0);
        assert_eq!(requeue_expired(&pool, now_ms() + 120_000).await.unwrap(), 1);
        let (_, current) = claim(&pool, "new", 60_000, &["default"])
            .await
            .unwrap()
            .unwrap();
        assert_eq!(current.attempt, 2);

        let (record, replay) = one_rally(1);
        let frames = db::compress_replay(&record, &replay);
        // The old holder's result is refused, its failure too; the current holder's is stored once.
        assert_eq!(
            db::store_result(&pool, &stale, &record, &frames, u64::MAX)
                .await
                .unwrap(),
            Stored::LeaseLost
        );
        assert_eq!(
            db::fail(&pool, &stale, "late").await.unwrap(),
            Stored::LeaseLost
        );
        assert_eq!(
            db::store_result(&pool, &current, &record, &frames, u64::MAX)
                .await
                .unwrap(),
            Stored::Done
        );
        assert_eq!(
            db::store_result(&pool, &current, &record, &frames, u64::MAX)
                .await
                .unwrap(),
            Stored::LeaseLost,
            "a done match is not stored again"
        );
        let m = db::match_row(&pool, id).await.unwrap().unwrap();
        assert_eq!(
            (m.status.as_str(), m.worker.as_deref(), m.attempts),
            ("done", Some("new"), 2)
        );
        let rallies = db::rallies(&pool, id).await.unwrap();
        assert_eq!(rallies.len(), 1);
        let played: Vec<(String, i64)> = workers(&pool)
            .await
            .unwrap()
            .into_iter()
            .map(|w| (w.name, w.matches_played))
            .collect();
        assert!(played.contains(&("new".into(), 1)) && played.contains(&("old".into(), 0)));
        pool.close().await;
    }

    #[tokio::test]
    async fn a_match_without_crossings_stores_no_in_box_share() {
        let (pool, all, id) = queued_match("no_crossings", 3).await;
        register(&pool, "w", "h", 1, 1, 60_000).await.unwrap();
        let (_, lease) = claim(&pool, "w", 60_000, &["default"])
            .await
            .unwrap()
            .unwrap();
        let (mut record, replay) = one_rally(3);
        // As a match whose balls never crossed a hitting plane has it.
        record.drift.crossings = 0;
        record.drift.in_box_fraction = 0.0;
        for d in record.drift_by_player.iter_mut() {
            d.crossings = 0;
            d.in_box_fraction = 0.0;
        }
        for rally in record.rallies.iter_mut() {
            rally.crossings.clear();
        }
        let frames = db::compress_replay(&record, &replay);
        let stored = db::store_result(&pool, &lease, &record, &frames, u64::MAX).await;
        assert_eq!(stored.unwrap(), Stored::Done);
        let m = db::match_row(&pool, id).await.unwrap().unwrap();
        assert_eq!(m.in_box_fraction, None, "none, not 0");
        let drift = db::agent_drift_summary(&pool, all[0].id).await.unwrap();
        assert_eq!((drift.crossings, drift.in_box_fraction), (0, None));
        pool.close().await;
    }
}
