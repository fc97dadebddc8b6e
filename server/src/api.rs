//! The REST API under `/api/v1` (JSON), the leaderboard page at `/`, and the error contract: every
//! rejected request gets a 4xx with `{"error": {"code", "message", "field"}}` and writes nothing.

use std::collections::HashMap;
use std::sync::Arc;

use axum::extract::rejection::JsonRejection;
use axum::extract::{DefaultBodyLimit, Path, Query, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::get;
use axum::{Json, Router};
use serde::Deserialize;
use serde_json::{json, Value};

use crate::{db, ratings, AppState};

/// A rejected request.
#[derive(Debug)]
pub struct ApiError {
    status: StatusCode,
    code: &'static str,
    message: String,
    field: Option<&'static str>,
}

impl ApiError {
    fn new(status: StatusCode, code: &'static str, message: impl Into<String>) -> ApiError {
        ApiError {
            status,
            code,
            message: message.into(),
            field: None,
        }
    }

    fn bad(field: &'static str, message: impl Into<String>) -> ApiError {
        ApiError {
            field: Some(field),
            ..ApiError::new(StatusCode::BAD_REQUEST, "invalid_field", message)
        }
    }

    fn name_taken(what: &str, name: &str) -> ApiError {
        ApiError {
            field: Some("name"),
            ..ApiError::new(
                StatusCode::CONFLICT,
                "name_taken",
                format!("{what} named '{name}' exists"),
            )
        }
    }

    fn not_found(what: &str, id: i64) -> ApiError {
        ApiError::new(
            StatusCode::NOT_FOUND,
            "not_found",
            format!("no {what} with id {id}"),
        )
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let body =
            json!({"error": {"code": self.code, "message": self.message, "field": self.field}});
        (self.status, Json(body)).into_response()
    }
}

impl From<sqlx::Error> for ApiError {
    fn from(e: sqlx::Error) -> ApiError {
        tracing::error!(error = %e, "database error");
        ApiError::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            "database",
            "database error (see the server log)",
        )
    }
}

impl From<anyhow::Error> for ApiError {
    fn from(e: anyhow::Error) -> ApiError {
        tracing::error!(error = %e, "internal error");
        ApiError::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            "internal",
            "internal error (see the server log)",
        )
    }
}

impl From<JsonRejection> for ApiError {
    fn from(r: JsonRejection) -> ApiError {
        let code = match &r {
            JsonRejection::MissingJsonContentType(_) => "content_type",
            JsonRejection::JsonSyntaxError(_) => "malformed_json",
            JsonRejection::JsonDataError(_) => "invalid_body",
            _ => "bad_body",
        };
        ApiError::new(r.status(), code, r.body_text())
    }
}

type ApiResult<T> = Result<T, ApiError>;

fn parse_id(raw: &str, what: &'static str) -> ApiResult<i64> {
    raw.parse::<i64>()
        .ok()
        .filter(|&id| id > 0)
        .ok_or_else(|| ApiError::bad(what, format!("'{raw}' is not a positive integer id")))
}

/// The router: API, page, limits, compression.
pub fn router(state: AppState) -> Router {
    let api = Router::new()
        .route("/healthz", get(healthz))
        .route("/agents", get(list_agents).post(submit_agent))
        .route("/agents/{id}", get(get_agent))
        .route("/matches", get(list_matches).post(queue_match))
        .route("/matches/{id}", get(get_match).delete(cancel_match))
        .route("/matches/{id}/replay", get(get_replay))
        .route("/leaderboard", get(leaderboard))
        .route("/tokens", axum::routing::post(issue_token))
        .route("/metrics", get(metrics))
        .route("/openapi.json", get(openapi))
        .fallback(|| async {
            ApiError::new(
                StatusCode::NOT_FOUND,
                "no_route",
                "no such endpoint (see /api/v1/openapi.json)",
            )
        });
    Router::new()
        .route("/", get(|| async { Html(crate::page::INDEX) }))
        .nest("/api/v1", api)
        .layer(DefaultBodyLimit::max(state.settings.max_body_bytes))
        .layer(tower_http::compression::CompressionLayer::new())
        .with_state(state)
}

async fn healthz(State(s): State<AppState>) -> ApiResult<Json<Value>> {
    sqlx::query("SELECT 1").execute(&s.pool).await?;
    Ok(Json(
        json!({"status": "ok", "sim_version": sim::SIM_VERSION}),
    ))
}

async fn list_agents(State(s): State<AppState>) -> ApiResult<Json<Value>> {
    Ok(Json(json!({ "agents": db::agents(&s.pool).await? })))
}

async fn get_agent(State(s): State<AppState>, Path(id): Path<String>) -> ApiResult<Json<Value>> {
    let id = parse_id(&id, "id")?;
    let a = db::agent(&s.pool, id)
        .await?
        .ok_or_else(|| ApiError::not_found("agent", id))?;
    Ok(Json(json!(a)))
}

/// Agent names: 1–64 characters of `A–Z a–z 0–9 _ . -`, not starting with `.` or `-`.
pub fn check_name(name: &str) -> Result<(), String> {
    if name.is_empty() || name.chars().count() > 64 {
        return Err("name must have 1 to 64 characters".into());
    }
    if !name
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || "_.-".contains(c))
    {
        return Err("name may contain only letters, digits, '_', '.' and '-'".into());
    }
    if name.starts_with(['.', '-']) {
        return Err("name must not start with '.' or '-'".into());
    }
    Ok(())
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

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct NewToken {
    name: String,
}

async fn issue_token(
    State(s): State<AppState>,
    headers: HeaderMap,
    body: Result<Json<NewToken>, JsonRejection>,
) -> ApiResult<Response> {
    if check_token(&s, &headers).await? != Caller::Admin {
        return Err(ApiError::new(
            StatusCode::FORBIDDEN,
            "admin_only",
            "only the admin token can issue tokens",
        ));
    }
    let Json(body) = body?;
    check_name(&body.name).map_err(|m| ApiError::bad("name", m))?;
    let mut raw = [0u8; 32];
    getrandom::getrandom(&mut raw).map_err(|e| anyhow::anyhow!("no randomness: {e}"))?;
    let token: String = std::iter::once("rt_".to_string())
        .chain(raw.iter().map(|b| format!("{b:02x}")))
        .collect();
    let id = match db::insert_token(&s.pool, &body.name, &token).await {
        Ok(id) => id,
        Err(sqlx::Error::Database(e)) if e.is_unique_violation() => {
            return Err(ApiError::name_taken("a token", &body.name))
        }
        Err(e) => return Err(e.into()),
    };
    Ok((
        StatusCode::CREATED,
        Json(json!({"id": id, "name": body.name, "token": token, "note": "shown once: only its SHA-256 is stored"})),
    )
        .into_response())
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SubmitAgent {
    name: String,
    checkpoint: Value,
}

async fn submit_agent(
    State(s): State<AppState>,
    headers: HeaderMap,
    body: Result<Json<SubmitAgent>, JsonRejection>,
) -> ApiResult<Response> {
    let caller = check_token(&s, &headers).await?;
    let Json(body) = body?;
    check_name(&body.name).map_err(|m| ApiError::bad("name", m))?;
    if db::agents(&s.pool)
        .await?
        .iter()
        .any(|a| a.name == body.name)
    {
        return Err(ApiError::name_taken("an agent", &body.name));
    }
    let text = body.checkpoint.to_string();
    let checkpoint =
        agents::checkpoint::Checkpoint::from_json(&text, &s.model).map_err(|e| ApiError {
            field: Some("checkpoint"),
            ..ApiError::new(
                StatusCode::UNPROCESSABLE_ENTITY,
                "invalid_checkpoint",
                e.to_string(),
            )
        })?;
    let spec = agents::player::PlayerSpec::Checkpoint(Arc::new(checkpoint));
    let eval = agents::eval::Evaluation {
        model: s.model.clone(),
        config: s.arena.clone(),
        preset: sim::arena::MYOCHALLENGE,
        kind: sim::serve::ServeKind::P2,
        episodes: s.settings.qualification_episodes,
        seed: 0,
    };
    let report = tokio::task::spawn_blocking(move || agents::eval::evaluate(&eval, &spec, &|| {}))
        .await
        .map_err(|e| anyhow::anyhow!("qualification panicked: {e}"))?
        .map_err(|e| ApiError {
            field: Some("checkpoint"),
            ..ApiError::new(StatusCode::UNPROCESSABLE_ENTITY, "qualification_failed", e)
        })?;
    let qual = (
        report.episodes,
        report.hit_rate.value,
        report.success_rate.value,
        report.effort.value,
    );
    let id = match db::insert_checkpoint_agent(
        &s.pool,
        &body.name,
        &text,
        qual,
        match caller {
            Caller::Admin => None,
            Caller::Submitter(id) => Some(id),
        },
    )
    .await
    {
        Ok(id) => id,
        Err(sqlx::Error::Database(e)) if e.is_unique_violation() => {
            return Err(ApiError::name_taken("an agent", &body.name))
        }
        Err(e) => return Err(e.into()),
    };
    tracing::info!(id, name = %body.name, hit = qual.1, success = qual.2, "agent submitted");
    let agent = db::agent(&s.pool, id).await?;
    Ok((
        StatusCode::CREATED,
        Json(json!({"agent": agent, "qualification": report})),
    )
        .into_response())
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct QueueMatch {
    a: i64,
    b: i64,
    rallies: u32,
    seed: Option<u64>,
}

async fn queue_match(
    State(s): State<AppState>,
    body: Result<Json<QueueMatch>, JsonRejection>,
) -> ApiResult<Response> {
    let Json(q) = body?;
    if q.rallies == 0 || q.rallies > s.settings.max_rallies {
        return Err(ApiError::bad(
            "rallies",
            format!("rallies must be between 1 and {}", s.settings.max_rallies),
        ));
    }
    if q.seed.is_some_and(|x| x > i64::MAX as u64) {
        return Err(ApiError::bad(
            "seed",
            format!("seed must be at most {}", i64::MAX),
        ));
    }
    let a = db::agent(&s.pool, q.a).await?.ok_or_else(|| ApiError {
        field: Some("a"),
        ..ApiError::not_found("agent", q.a)
    })?;
    let b = db::agent(&s.pool, q.b).await?.ok_or_else(|| ApiError {
        field: Some("b"),
        ..ApiError::not_found("agent", q.b)
    })?;
    let seed = q.seed.unwrap_or_else(|| {
        let t = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap_or_default();
        (t.as_nanos() as u64) & (i64::MAX as u64)
    });
    let id = db::queue_match(&s.pool, &a, &b, q.rallies, seed, true).await?;
    s.wake.notify_one();
    let m = db::match_row(&s.pool, id).await?;
    Ok((
        StatusCode::ACCEPTED,
        [(header::LOCATION, format!("/api/v1/matches/{id}"))],
        Json(json!(m)),
    )
        .into_response())
}

async fn list_matches(
    State(s): State<AppState>,
    Query(q): Query<HashMap<String, String>>,
) -> ApiResult<Json<Value>> {
    for k in q.keys() {
        if !["agent", "status", "limit"].contains(&k.as_str()) {
            return Err(ApiError::bad(
                "query",
                format!("unknown query parameter '{k}' (agent, status, limit)"),
            ));
        }
    }
    let agent = q.get("agent").map(|a| parse_id(a, "agent")).transpose()?;
    let status = q.get("status").map(String::as_str);
    if let Some(st) = status {
        if !["queued", "running", "done", "failed", "cancelled"].contains(&st) {
            return Err(ApiError::bad(
                "status",
                "status must be one of queued, running, done, failed, cancelled",
            ));
        }
    }
    let limit = match q.get("limit") {
        None => 100,
        Some(l) => l
            .parse::<i64>()
            .ok()
            .filter(|l| (1..=1000).contains(l))
            .ok_or_else(|| ApiError::bad("limit", "limit must be an integer from 1 to 1000"))?,
    };
    Ok(Json(
        json!({ "matches": db::matches(&s.pool, agent, status, limit).await? }),
    ))
}

async fn get_match(State(s): State<AppState>, Path(id): Path<String>) -> ApiResult<Json<Value>> {
    let id = parse_id(&id, "id")?;
    let m = db::match_row(&s.pool, id)
        .await?
        .ok_or_else(|| ApiError::not_found("match", id))?;
    let rallies = db::rallies(&s.pool, id).await?;
    let drift: Option<Value> = db::drift(&s.pool, id)
        .await?
        .and_then(|d| serde_json::from_str(&d).ok());
    let mut v = json!(m);
    v["rally_log"] = json!(rallies);
    v["drift"] = drift.unwrap_or(Value::Null);
    Ok(Json(v))
}

async fn cancel_match(State(s): State<AppState>, Path(id): Path<String>) -> ApiResult<Json<Value>> {
    let id = parse_id(&id, "id")?;
    let m = db::match_row(&s.pool, id)
        .await?
        .ok_or_else(|| ApiError::not_found("match", id))?;
    if !db::cancel(&s.pool, id).await? {
        return Err(ApiError::new(
            StatusCode::CONFLICT,
            "not_cancellable",
            format!("match {id} is {} and can no longer be cancelled", m.status),
        ));
    }
    Ok(Json(json!(db::match_row(&s.pool, id).await?)))
}

async fn get_replay(
    State(s): State<AppState>,
    Path(id): Path<String>,
    Query(q): Query<HashMap<String, String>>,
) -> ApiResult<Response> {
    let id = parse_id(&id, "id")?;
    let m = db::match_row(&s.pool, id)
        .await?
        .ok_or_else(|| ApiError::not_found("match", id))?;
    let rally = match q.get("rally") {
        None => 0,
        Some(r) => r
            .parse::<i64>()
            .ok()
            .filter(|&r| r >= 0)
            .ok_or_else(|| ApiError::bad("rally", format!("'{r}' is not a rally index")))?,
    };
    if m.status != "done" {
        return Err(ApiError::new(
            StatusCode::CONFLICT,
            "not_done",
            format!("match {id} is {}; replays exist once it is done", m.status),
        ));
    }
    if !m.keep_replay {
        let names = (
            db::agent(&s.pool, m.agent_a).await?,
            db::agent(&s.pool, m.agent_b).await?,
        );
        let (na, nb) = (
            names.0.map(|a| a.name).unwrap_or_default(),
            names.1.map(|a| a.name).unwrap_or_default(),
        );
        return Err(ApiError::new(
            StatusCode::NOT_FOUND,
            "no_replay",
            format!(
                "match {id} was scheduled by the continuous mode and keeps no replay; re-simulate it bit for bit with `rally match {na} {nb} --rallies {} --seed {} --replay replay.json`",
                m.rallies, m.seed
            ),
        ));
    }
    if rally >= m.rallies {
        return Err(ApiError::bad(
            "rally",
            format!("match {id} has rallies 0 to {}", m.rallies - 1),
        ));
    }
    let frames = db::replay(&s.pool, id, rally).await?.ok_or_else(|| {
        ApiError::new(
            StatusCode::NOT_FOUND,
            "not_found",
            "no replay stored for that rally",
        )
    })?;
    let body = format!(
        "{{\"match\":{id},\"rally\":{rally},\"hz\":{},\"frames\":{frames}}}",
        agents::matchrun::REPLAY_HZ
    );
    Ok(([(header::CONTENT_TYPE, "application/json")], body).into_response())
}

/// The leaderboard, recomputed when an agent or a finished match was added.
pub async fn current_board(s: &AppState) -> ApiResult<Arc<ratings::Leaderboard>> {
    let (agents_n, done): (i64, i64) = sqlx::query_as("SELECT (SELECT COUNT(*) FROM agents), (SELECT COUNT(*) FROM matches WHERE status = 'done')")
        .fetch_one(&s.pool)
        .await?;
    let mut cache = s.board.lock().await;
    if let Some((a, d, b)) = cache.as_ref() {
        if *a == agents_n as usize && *d == done {
            return Ok(b.clone());
        }
    }
    let agents = db::agents(&s.pool).await?;
    let outcomes = db::outcomes(&s.pool).await?;
    let board = Arc::new(
        tokio::task::spawn_blocking(move || ratings::leaderboard(&agents, &outcomes))
            .await
            .map_err(|e| anyhow::anyhow!("{e}"))?,
    );
    *cache = Some((agents_n as usize, done, board.clone()));
    Ok(board)
}

async fn leaderboard(State(s): State<AppState>) -> ApiResult<Json<Value>> {
    Ok(Json(json!(*current_board(&s).await?)))
}

async fn metrics(State(s): State<AppState>) -> ApiResult<Response> {
    let by_status: Vec<(String, i64)> =
        sqlx::query_as("SELECT status, COUNT(*) FROM matches GROUP BY status")
            .fetch_all(&s.pool)
            .await?;
    let (agents_n, rallies_n): (i64, i64) =
        sqlx::query_as("SELECT (SELECT COUNT(*) FROM agents), (SELECT COUNT(*) FROM rallies)")
            .fetch_one(&s.pool)
            .await?;
    let mut out = String::new();
    out.push_str("# HELP rally_matches Matches by status.\n# TYPE rally_matches gauge\n");
    for st in ["queued", "running", "done", "failed", "cancelled"] {
        let n = by_status.iter().find(|(k, _)| k == st).map_or(0, |x| x.1);
        out.push_str(&format!("rally_matches{{status=\"{st}\"}} {n}\n"));
    }
    out.push_str(&format!("# HELP rally_agents Registered agents.\n# TYPE rally_agents gauge\nrally_agents {agents_n}\n"));
    out.push_str(&format!("# HELP rally_rallies_total Rallies stored.\n# TYPE rally_rallies_total counter\nrally_rallies_total {rallies_n}\n"));
    out.push_str(&format!(
        "# HELP rally_workers Match workers.\n# TYPE rally_workers gauge\nrally_workers {}\n",
        s.settings.workers
    ));
    Ok(([(header::CONTENT_TYPE, "text/plain; version=0.0.4")], out).into_response())
}

async fn openapi() -> Response {
    (
        [(header::CONTENT_TYPE, "application/json")],
        crate::page::OPENAPI,
    )
        .into_response()
}
