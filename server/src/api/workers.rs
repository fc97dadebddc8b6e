//! `/workers`: the processes that play matches.

use super::*;

/// `GET /workers`: every process that plays or played matches (this server's own pool and
/// `rally worker`s), with its heartbeat's age, whether its lease would still hold, and the matches
/// it holds now.
pub(super) async fn list_workers(State(s): State<AppState>) -> ApiResult<Json<Value>> {
    let now = db::workers::now_ms();
    let lease = s.settings.lease_ms();
    let running = db::workers::running(&s.pool).await?;
    let workers: Vec<Value> = db::workers::workers(&s.pool)
        .await?
        .into_iter()
        .map(|w| {
            let holding: Vec<i64> = running
                .iter()
                .filter(|(_, h)| h.as_deref() == Some(w.name.as_str()))
                .map(|(id, _)| *id)
                .collect();
            let age = (now - w.heartbeat_ms).max(0);
            let mut v = json!(w);
            v["seconds_since_heartbeat"] = json!(age as f64 / 1000.0);
            v["alive"] = json!(w.status == db::WorkerStatus::Running && age < lease);
            v["matches_running"] = json!(holding);
            v
        })
        .collect();
    Ok(Json(
        json!({ "workers": workers, "lease_s": s.settings.lease_s }),
    ))
}
