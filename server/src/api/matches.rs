//! `/matches`: queueing, the list, one match, cancelling, replays (stored or re-simulated), live feeds.

use super::*;

/// `GET /matches/{id}/live`: a running match as it is played (server-sent events): events `frames`
/// (the next `LIVE_CHUNK` frames of rally `rally`, with body poses as the replay endpoint gives them;
/// `first` is the index of the first in the rally's replay) while a rally is played, `rally` (its
/// record) as it ends, `lagged` when this viewer fell more than `LIVE_BUFFER` messages behind (it
/// goes on from the newest kept), and `end` when the match is over. 409 if the match is not
/// running. The worker never waits for a viewer.
pub(super) async fn live_match(
    State(s): State<AppState>,
    Path(id): Path<String>,
) -> ApiResult<Response> {
    use axum::response::sse::{Event, KeepAlive, Sse};
    use tokio::sync::broadcast::error::RecvError;
    let id = parse_id(&id, "id")?;
    let m = db::match_row(&s.pool, id)
        .await?
        .ok_or_else(|| ApiError::not_found("match", id))?;
    let lookup = || -> ApiResult<_> {
        Ok(s.live
            .lock()
            .map_err(|_| anyhow::anyhow!("live registry poisoned"))?
            .get(&id)
            .map(|tx| tx.subscribe()))
    };
    let mut rx = lookup()?;
    if let Some(w) = m
        .worker
        .as_deref()
        .filter(|w| rx.is_none() && m.status == db::MatchStatus::Running && *w != s.worker.as_str())
    {
        return Err(ApiError::new(
            StatusCode::CONFLICT,
            "not_local",
            format!(
                "match {id} is played by worker '{w}' in another process: only matches this server's own workers play can be watched live (its replay once done: /replay?match={id})"
            ),
        ));
    }
    // Claimed a moment ago: its worker registers the feed as it starts; give it a second.
    let mut tries = 0;
    while rx.is_none() && m.status == db::MatchStatus::Running && tries < 20 {
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
        rx = lookup()?;
        tries += 1;
    }
    let Some(rx) = rx else {
        return Err(ApiError::new(
            StatusCode::CONFLICT,
            "not_running",
            format!(
                "match {id} is {}: only a running match can be watched live (its replay: /replay?match={id})",
                m.status
            ),
        ));
    };
    let stream = futures_util::stream::unfold(Some(rx), |rx| async move {
        let mut rx = rx?;
        let event = match rx.recv().await {
            Ok(msg) => Event::default().event(msg.event).data(msg.data.as_str()),
            Err(RecvError::Lagged(n)) => Event::default().event("lagged").data(n.to_string()),
            Err(RecvError::Closed) => {
                return Some((
                    Ok::<_, std::convert::Infallible>(Event::default().event("end").data("{}")),
                    None,
                ))
            }
        };
        Some((Ok(event), Some(rx)))
    });
    Ok(Sse::new(stream)
        .keep_alive(KeepAlive::new().interval(std::time::Duration::from_secs(15)))
        .into_response())
}

pub(super) async fn queue_match(
    State(s): State<AppState>,
    headers: HeaderMap,
    body: Result<Json<wire::QueueMatch>, JsonRejection>,
) -> ApiResult<Response> {
    let caller = check_token(&s, &headers).await?;
    let Json(q) = body?;
    if q.rallies == 0 || q.rallies > s.settings.max_rallies {
        return Err(ApiError::bad(
            "rallies",
            format!("rallies must be between 1 and {}", s.settings.max_rallies),
        ));
    }
    let seed = seed_or_clock(q.seed)?;
    let a = agent_or_404(&s, &q.a, "a").await?;
    let b = agent_or_404(&s, &q.b, "b").await?;
    same_robot(&s, &a, &b, "b")?;
    charge(
        &s,
        caller,
        &[
            (Budget::Matches, 1),
            (Budget::Rallies, u64::from(q.rallies)),
        ],
    )?;
    let origin = db::Origin {
        created_by: submitter(caller),
        ..db::Origin::default()
    };
    let id = db::queue_match(&s.pool, &a, &b, q.rallies, seed, true, origin).await?;
    s.publish_match(id, db::MatchStatus::Queued);
    s.wake.notify_one();
    let m = db::match_row(&s.pool, id).await?;
    Ok((
        StatusCode::ACCEPTED,
        [(header::LOCATION, format!("/api/v1/matches/{id}"))],
        Json(m),
    )
        .into_response())
}

pub(super) async fn list_matches(
    State(s): State<AppState>,
    Typed(q): Typed<wire::MatchesQuery>,
) -> ApiResult<Json<wire::MatchList>> {
    let positive = |id: Option<i64>, what: &'static str| match id {
        Some(id) if id <= 0 => Err(ApiError::bad(
            what,
            format!("{what} must be a positive id, not {id}"),
        )),
        _ => Ok(id),
    };
    if let Some(robot) = &q.model {
        s.arenas
            .require(robot)
            .map_err(|e| ApiError::bad("model", e))?;
    }
    let filter = db::MatchFilter {
        agent: positive(q.agent, "agent")?,
        model: q.model.clone(),
        status: q.status,
        before: positive(q.before, "before")?,
    };
    let limit = limit_of(q.limit, 100, 1000)?;
    let page = db::matches(&s.pool, filter, limit).await?;
    // A full page may have more behind it: `?before=` this id gets the next one.
    let next = (page.len() as i64 == limit)
        .then(|| page.last().map(|m| m.id))
        .flatten();
    Ok(Json(wire::MatchList {
        matches: page,
        next_before: next,
    }))
}

pub(super) async fn get_match(
    State(s): State<AppState>,
    Path(id): Path<String>,
) -> ApiResult<Json<wire::MatchDetail>> {
    let id = parse_id(&id, "id")?;
    let m = db::match_row(&s.pool, id)
        .await?
        .ok_or_else(|| ApiError::not_found("match", id))?;
    let rally_log = db::rallies(&s.pool, id).await?;
    let drift: Option<Value> = db::drift(&s.pool, id)
        .await?
        .and_then(|d| serde_json::from_str(&d).ok());
    let drift_by_side = db::match_drift(&s.pool, id)
        .await?
        .into_iter()
        .map(|(side, agent_id, d)| wire::SideDrift {
            side,
            agent_id,
            drift: serde_json::from_str::<Value>(&d).unwrap_or(Value::Null),
        })
        .collect();
    Ok(Json(wire::MatchDetail {
        row: m,
        rally_log,
        drift,
        drift_by_side,
    }))
}

pub(super) async fn cancel_match(
    State(s): State<AppState>,
    headers: HeaderMap,
    Path(id): Path<String>,
) -> ApiResult<Json<db::Match>> {
    let caller = check_token(&s, &headers).await?;
    let id = parse_id(&id, "id")?;
    let m = db::match_row(&s.pool, id)
        .await?
        .ok_or_else(|| ApiError::not_found("match", id))?;
    may_cancel(caller, m.created_by, &format!("match {id}"))?;
    if !db::cancel(&s.pool, id).await? {
        return Err(ApiError::not_cancellable(format!(
            "match {id} is {} and can no longer be cancelled",
            m.status
        )));
    }
    // Played here, it stops at the end of its rally; played by another process, that process's
    // heartbeat sees the cancellation.
    s.stop_playing(id);
    s.publish_match(id, db::MatchStatus::Cancelled);
    let m = db::match_row(&s.pool, id)
        .await?
        .ok_or_else(|| anyhow::anyhow!("match {id} vanished after its cancellation"))?;
    Ok(Json(m))
}

pub(super) async fn get_replay(
    State(s): State<AppState>,
    Path(id): Path<String>,
    Typed(q): Typed<wire::ReplayQuery>,
) -> ApiResult<Response> {
    let id = parse_id(&id, "id")?;
    let m = db::match_row(&s.pool, id)
        .await?
        .ok_or_else(|| ApiError::not_found("match", id))?;
    let rally = match q.rally.unwrap_or(0) {
        r if r < 0 => return Err(ApiError::bad("rally", format!("{r} is not a rally index"))),
        r => r,
    };
    if m.status != db::MatchStatus::Done {
        return Err(ApiError::new(
            StatusCode::CONFLICT,
            "not_done",
            format!("match {id} is {}; replays exist once it is done", m.status),
        ));
    }
    if rally >= m.rallies {
        return Err(ApiError::bad(
            "rally",
            format!("match {id} has rallies 0 to {}", m.rallies - 1),
        ));
    }
    // A few replays are read at a time (as many as there are workers): each holds a rally's frames
    // (and, re-simulated, both agents' checkpoints) while it is made.
    let _turn = s
        .resim
        .acquire()
        .await
        .map_err(|e| anyhow::anyhow!("replay queue closed: {e}"))?;
    // The frames: stored (compressed) or re-simulated (JSON).
    let (frames, resimulated) = if m.keep_replay {
        let gz = db::replay(&s.pool, id, rally).await?.ok_or_else(|| {
            ApiError::new(
                StatusCode::NOT_FOUND,
                "not_found",
                "no replay stored for that rally",
            )
        })?;
        (Err(gz), false)
    } else {
        // Continuous-mode and SPRT matches keep no frames: rallies are independent and deterministic,
        // so the rally is re-simulated (bit-identical to the one played), a few at a time.
        let spec_of = |agent: i64| {
            let s = s.clone();
            async move {
                db::agent_spec(&s.pool, agent).await?.ok_or_else(|| {
                    ApiError::new(
                        StatusCode::CONFLICT,
                        "not_replayable",
                        format!("agent {agent} no longer exists"),
                    )
                })
            }
        };
        let agents = [spec_of(m.agent_a).await?, spec_of(m.agent_b).await?];
        let st = s.clone();
        let m = m.clone();
        let frames = tokio::task::spawn_blocking(move || {
            crate::scheduler::resimulate_rally(&st, &m, agents, rally as u32)
        })
        .await
        .map_err(|e| anyhow::anyhow!("re-simulation panicked: {e}"))?
        .map_err(|e| ApiError::new(StatusCode::CONFLICT, "not_replayable", e))?;
        let json = serde_json::to_string(&frames).map_err(|e| anyhow::anyhow!("{e}"))?;
        (Ok(json), true)
    };
    let robot = m.model.clone();
    let model = s
        .arenas
        .require(&robot)
        .map_err(|e| ApiError::new(StatusCode::CONFLICT, "not_replayable", e))?
        .model
        .clone();
    let frames = tokio::task::spawn_blocking(move || {
        let json = match frames {
            Ok(json) => json,
            Err(gz) => db::gunzip(&gz).map_err(|e| e.to_string())?,
        };
        crate::replay::with_body_poses(&model, &json).map_err(|e| e.to_string())
    })
    .await
    .map_err(|e| anyhow::anyhow!("replay poses panicked: {e}"))?
    .map_err(|e| anyhow::anyhow!("stored replay unreadable: {e}"))?;
    let body = format!(
        "{{\"match\":{id},\"model\":{},\"rally\":{rally},\"hz\":{},\"resimulated\":{resimulated},\"frames\":{frames}}}",
        serde_json::Value::from(robot),
        ::agents::matchrun::REPLAY_HZ
    );
    Ok(([(header::CONTENT_TYPE, "application/json")], body).into_response())
}
