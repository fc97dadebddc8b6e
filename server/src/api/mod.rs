//! The REST API under `/api/v1` (JSON), the leaderboard page at `/`, and the error contract: every
//! rejected request gets a 4xx with `{"error": {"code", "message", "field"}}` and writes nothing.

use axum::extract::multipart::MultipartError;
use axum::extract::rejection::JsonRejection;
use axum::extract::{DefaultBodyLimit, FromRequest, Multipart, Path, Request, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::get;
use axum::{Json, Router};
use serde_json::Value;

use crate::db;
use crate::state::{AppState, Budget};
use wire::AgentRef;

mod agents;
mod contests;
mod error;
mod info;
mod matches;
mod tokens;
mod workers;

pub use agents::check_name;
use agents::*;
use contests::{
    cancel_sprt, cancel_tournament, create_sprt, create_tournament, get_agent_crossings,
    get_rating_history, get_sprt, get_tournament, list_sprts, list_tournaments,
};
pub use error::ApiError;
use error::{limit_of, parse_id, ApiResult, Typed};
use info::*;
use matches::*;
use tokens::*;
use workers::*;

/// The router: API, page, limits, compression.
pub fn router(state: AppState) -> Router {
    let api = Router::new()
        .route("/healthz", get(healthz))
        .route("/agents", get(list_agents).post(submit_agent))
        .route("/agents/{id}", get(get_agent).delete(retire_agent))
        .route("/agents/{id}/ratings", get(get_rating_history))
        .route("/agents/{id}/crossings", get(get_agent_crossings))
        .route("/matches", get(list_matches).post(queue_match))
        .route("/matches/{id}", get(get_match).delete(cancel_match))
        .route("/matches/{id}/replay", get(get_replay))
        .route("/matches/{id}/live", get(live_match))
        .route(
            "/tournaments",
            get(list_tournaments).post(create_tournament),
        )
        .route(
            "/tournaments/{id}",
            get(get_tournament).delete(cancel_tournament),
        )
        .route("/sprt", get(list_sprts).post(create_sprt))
        .route("/sprt/{id}", get(get_sprt).delete(cancel_sprt))
        .route("/leaderboard", get(leaderboard))
        .route("/events", get(events))
        .route("/arena", get(arena))
        .route("/model", get(robot_model))
        .route("/tokens", axum::routing::post(issue_token))
        .route("/workers", get(list_workers))
        .route("/metrics", get(metrics))
        .route("/openapi.json", get(openapi))
        .fallback(|| async {
            ApiError::new(
                StatusCode::NOT_FOUND,
                "no_route",
                "no such endpoint (see /api/v1/openapi.json)",
            )
        })
        .method_not_allowed_fallback(method_not_allowed);
    Router::new()
        .route("/", get(|| async { Html(crate::page::INDEX) }))
        .route("/replay", get(|| async { Html(crate::page::REPLAY) }))
        .route("/agent", get(|| async { Html(crate::page::AGENT) }))
        .method_not_allowed_fallback(method_not_allowed)
        .nest("/api/v1", api)
        .layer(DefaultBodyLimit::max(state.settings.max_body_bytes))
        .layer(axum::middleware::from_fn(json_errors))
        .layer(tower_http::compression::CompressionLayer::new())
        .with_state(state)
}

/// Gives every error answer the JSON error body: the handlers' errors have it already; this catches
/// the rest (an extractor's rejection in plain text, a route-less 404 with no body), keeping its
/// status and its text as the message.
async fn json_errors(req: Request, next: axum::middleware::Next) -> Response {
    let resp = next.run(req).await;
    let status = resp.status();
    let is_json = resp
        .headers()
        .get(axum::http::header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.starts_with("application/json"));
    if !(status.is_client_error() || status.is_server_error()) || is_json {
        return resp;
    }
    let retry_after = resp.headers().get(axum::http::header::RETRY_AFTER).cloned();
    let text = axum::body::to_bytes(resp.into_body(), 4096)
        .await
        .map(|b| String::from_utf8_lossy(&b).trim().to_string())
        .unwrap_or_default();
    let message = if text.is_empty() {
        status.canonical_reason().unwrap_or("error").to_lowercase()
    } else {
        text
    };
    let code = match status.as_u16() {
        400 => "bad_request",
        404 => "not_found",
        405 => "method_not_allowed",
        408 => "request_timeout",
        413 => "body_too_large",
        415 => "unsupported_media_type",
        422 => "unprocessable",
        429 => "rate_limited",
        500..=599 => "internal",
        _ => "http_error",
    };
    let mut out = ApiError::new(status, code, message).into_response();
    if let Some(r) = retry_after {
        out.headers_mut().insert(axum::http::header::RETRY_AFTER, r);
    }
    out
}

/// A route that exists, asked with a method it does not take: 405 with the JSON error body.
async fn method_not_allowed(method: axum::http::Method) -> ApiError {
    ApiError::new(
        StatusCode::METHOD_NOT_ALLOWED,
        "method_not_allowed",
        format!("{method} is not allowed here (see /api/v1/openapi.json for each route's methods)"),
    )
}

/// `GET /events`: server-sent events, one JSON `ServerEvent` per change (matches queued, started,
/// finished, failed, cancelled; agents registered), with a keep-alive comment every 15 s. A
/// subscriber that falls more than `EVENT_BUFFER` events behind gets an event `lagged` (refresh
/// everything) and goes on from the newest; the publishers never wait for it.
async fn events(
    State(s): State<AppState>,
) -> axum::response::sse::Sse<
    impl futures_util::Stream<Item = Result<axum::response::sse::Event, std::convert::Infallible>>,
> {
    use axum::response::sse::{Event, KeepAlive, Sse};
    use tokio::sync::broadcast::error::RecvError;
    let rx = s.events.subscribe();
    let stream = futures_util::stream::unfold(rx, |mut rx| async move {
        let event = match rx.recv().await {
            Ok(e) => Event::default().json_data(&e).unwrap_or_default(),
            Err(RecvError::Lagged(n)) => Event::default().event("lagged").data(n.to_string()),
            Err(RecvError::Closed) => return None,
        };
        Some((Ok(event), rx))
    });
    Sse::new(stream).keep_alive(KeepAlive::new().interval(std::time::Duration::from_secs(15)))
}

/// Who made a request.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Caller {
    /// The admin token.
    Admin,
    /// A submitter token (its id).
    Submitter(i64),
}

/// Checks the bearer token: the admin token (compared in constant time) or a stored submitter token
/// (compared by its SHA-256).
async fn check_token(s: &AppState, headers: &HeaderMap) -> ApiResult<Caller> {
    let given = headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "))
        .ok_or_else(|| {
            ApiError::new(
                StatusCode::UNAUTHORIZED,
                "unauthorized",
                "missing bearer token (Authorization: Bearer TOKEN)",
            )
        })?;
    let admin = &s.settings.admin_token;
    let is_admin = !admin.is_empty()
        && given.len() == admin.len()
        && given
            .bytes()
            .zip(admin.bytes())
            .fold(0u8, |acc, (x, y)| acc | (x ^ y))
            == 0;
    if is_admin {
        return Ok(Caller::Admin);
    }
    match db::token_id(&s.pool, given).await? {
        Some(id) => Ok(Caller::Submitter(id)),
        None => Err(ApiError::new(
            StatusCode::UNAUTHORIZED,
            "unauthorized",
            "unknown bearer token",
        )),
    }
}

/// Refuses a submitter token that would go over a budget — `max_matches_per_minute` matches queued,
/// `max_rallies_per_hour` rallies asked for, `max_agents_per_hour` agents submitted — with 429 and
/// `Retry-After`; otherwise books every amount of `spend` (all or none). The admin is not limited.
fn charge(s: &AppState, caller: Caller, spend: &[(Budget, u64)]) -> ApiResult<()> {
    let Caller::Submitter(token) = caller else {
        return Ok(());
    };
    let now = std::time::Instant::now();
    let mut log = s.rate.lock().unwrap_or_else(|e| e.into_inner());
    for &(budget, n) in spend {
        over_budget(s, &mut log, token, budget, n, now)?;
    }
    for &(budget, n) in spend {
        log.entry((token, budget)).or_default().push_back((now, n));
    }
    Ok(())
}

/// The 429 for `token` spending `n` more of `budget` now, if it would go over; forgets spending
/// older than the budget's window.
fn over_budget(
    s: &AppState,
    log: &mut crate::state::RateLog,
    token: i64,
    budget: Budget,
    n: u64,
    now: std::time::Instant,
) -> ApiResult<()> {
    // (limit, window in seconds, verb, its past tense, noun, the window in words)
    let settings = &s.settings;
    let (limit, window, verb, done, noun, per) = match budget {
        Budget::Matches => (
            u64::from(settings.max_matches_per_minute),
            60,
            "queue",
            "queued",
            "matches",
            "minute",
        ),
        Budget::Rallies => (
            u64::from(settings.max_rallies_per_hour),
            3600,
            "ask for",
            "asked for",
            "rallies",
            "hour",
        ),
        Budget::Agents => (
            u64::from(settings.max_agents_per_hour),
            3600,
            "submit",
            "submitted",
            "agents",
            "hour",
        ),
    };
    let limited = |message: String, secs: u64| ApiError {
        retry_after: Some(secs),
        field: Some("rate".into()),
        ..ApiError::new(StatusCode::TOO_MANY_REQUESTS, "rate_limited", message)
    };
    if n > limit {
        // Never within the budget, however long it waits: not a 429.
        let setting = match budget {
            Budget::Matches => "max_matches_per_minute",
            Budget::Rallies => "max_rallies_per_hour",
            Budget::Agents => "max_agents_per_hour",
        };
        return Err(ApiError {
            field: Some("rate".into()),
            ..ApiError::new(
                StatusCode::UNPROCESSABLE_ENTITY,
                "over_limit",
                format!(
                    "this request would {verb} {n} {noun}; a token may {verb} at most {limit} per {per} ({setting})"
                ),
            )
        });
    }
    let window_d = std::time::Duration::from_secs(window);
    let mine = log.entry((token, budget)).or_default();
    while mine
        .front()
        .is_some_and(|(t, _)| now.duration_since(*t) >= window_d)
    {
        mine.pop_front();
    }
    let used: u64 = mine.iter().map(|x| x.1).sum();
    if used + n > limit {
        // When enough of the window's spending will have expired.
        let mut freed = 0;
        let mut wait = window;
        for (t, k) in mine.iter() {
            freed += k;
            if used - freed + n <= limit {
                wait = (window_d - now.duration_since(*t)).as_secs() + 1;
                break;
            }
        }
        return Err(limited(
            format!("this token {done} {used} {noun} in the last {per} (limit {limit}); retry in {wait} s"),
            wait,
        ));
    }
    Ok(())
}

/// The submitter token id of a caller (None for the admin).
fn submitter(caller: Caller) -> Option<i64> {
    match caller {
        Caller::Admin => None,
        Caller::Submitter(id) => Some(id),
    }
}

/// The admin may cancel anything; a submitter only what its own token queued.
fn may_cancel(caller: Caller, owner: Option<i64>, what: &str) -> ApiResult<()> {
    owner_or_admin(caller, owner, &format!("{what} was not queued"), "cancel")
}

/// The admin may `act` on anything, a submitter token only on what it made (`owner`); 403
/// `not_owner` otherwise, saying `what` (e.g. "match 3 was not queued").
fn owner_or_admin(caller: Caller, owner: Option<i64>, what: &str, act: &str) -> ApiResult<()> {
    match caller {
        Caller::Admin => Ok(()),
        Caller::Submitter(t) if owner == Some(t) => Ok(()),
        Caller::Submitter(_) => Err(ApiError::new(
            StatusCode::FORBIDDEN,
            "not_owner",
            format!("{what} with this token; only its owner or the admin may {act} it"),
        )),
    }
}

/// The agent `r` names, or 404 naming `field`; 409 if it was retired.
async fn agent_or_404(s: &AppState, r: &AgentRef, field: &'static str) -> ApiResult<db::Agent> {
    let found = match r {
        AgentRef::Id(id) => db::agent(&s.pool, *id).await?,
        // A string that cannot be an agent's name names none (and never reaches the store:
        // PostgreSQL refuses text with NUL bytes).
        AgentRef::Name(name) if check_name(name).is_err() => None,
        AgentRef::Name(name) => db::agent_by_name(&s.pool, name).await?,
    };
    let agent = found.ok_or_else(|| ApiError {
        field: Some(field.into()),
        ..match r {
            AgentRef::Id(id) => ApiError::not_found("agent", *id),
            AgentRef::Name(name) => ApiError::new(
                StatusCode::NOT_FOUND,
                "not_found",
                format!("no agent named '{name}'"),
            ),
        }
    })?;
    match &agent.retired_at {
        Some(when) => Err(ApiError {
            field: Some(field.into()),
            ..ApiError::new(
                StatusCode::CONFLICT,
                "retired",
                format!(
                    "agent {} ('{}') was retired at {when} and plays no new matches",
                    agent.id, agent.name
                ),
            )
        }),
        None => Ok(agent),
    }
}

/// 422 naming `field` unless `b` plays `a`'s robot (agents of different robots never meet), and
/// unless this server plays that robot (a match nobody here can play would wait forever).
fn same_robot(s: &AppState, a: &db::Agent, b: &db::Agent, field: &'static str) -> ApiResult<()> {
    if a.model == b.model {
        return s
            .arenas
            .require(&a.model)
            .map(|_| ())
            .map_err(|e| ApiError {
                field: Some(field.into()),
                ..ApiError::new(StatusCode::UNPROCESSABLE_ENTITY, "unknown_robot", e)
            });
    }
    Err(ApiError {
        field: Some(field.into()),
        ..ApiError::new(
            StatusCode::UNPROCESSABLE_ENTITY,
            "robot_mismatch",
            format!(
                "agent {} ('{}') plays the {} robot and agent {} ('{}') the {} robot: agents meet \
                 only agents of their own robot",
                a.id, a.name, a.model, b.id, b.name, b.model
            ),
        )
    })
}

/// The robot a `?model=` names (none: the default robot), one this server plays; 400 otherwise.
fn robot_of<'s>(s: &'s AppState, q: &wire::ModelQuery) -> ApiResult<&'s crate::arenas::Arena> {
    s.arenas
        .require(q.robot())
        .map_err(|e| ApiError::bad("model", e))
}

/// A seed given, or one from the clock.
fn seed_or_clock(seed: Option<u64>) -> ApiResult<u64> {
    if seed.is_some_and(|x| x > i64::MAX as u64) {
        return Err(ApiError::bad(
            "seed",
            format!("seed must be at most {}", i64::MAX),
        ));
    }
    Ok(seed.unwrap_or_else(|| {
        let t = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap_or_default();
        (t.as_nanos() as u64) & (i64::MAX as u64)
    }))
}
