//! `/workers`: the processes that play matches.

use super::*;

/// `GET /workers`: every process that plays or played matches (this server's own pool and
/// `rally worker`s), with its heartbeat's age, whether its lease would still hold, and the matches
/// it holds now.
pub(super) async fn list_workers(State(s): State<AppState>) -> ApiResult<Json<wire::WorkerList>> {
    let now = db::workers::now_ms();
    let lease = s.settings.lease_ms();
    let running = db::workers::running(&s.pool).await?;
    let workers = db::workers::workers(&s.pool)
        .await?
        .into_iter()
        .map(|w| {
            let holding: Vec<i64> = running
                .iter()
                .filter(|(_, h)| h.as_deref() == Some(w.name.as_str()))
                .map(|(id, _)| *id)
                .collect();
            let age = (now - w.heartbeat_ms).max(0);
            wire::WorkerView {
                seconds_since_heartbeat: age as f64 / 1000.0,
                alive: w.status == db::WorkerStatus::Running && age < lease,
                matches_running: holding,
                row: w,
            }
        })
        .collect();
    Ok(Json(wire::WorkerList {
        workers,
        lease_s: s.settings.lease_s,
    }))
}
