//! Tournaments, SPRTs and rating history: `/tournaments`, `/sprt`, `/agents/{id}/ratings`.

use axum::extract::rejection::JsonRejection;
use axum::extract::{Path, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;

use super::{
    agent_or_404, charge, check_token, limit_of, may_cancel, parse_id, same_robot, seed_or_clock,
    submitter, ApiError, ApiResult, Typed,
};
use crate::state::{AppState, Budget};
use crate::tournament;
use crate::{db, ratings};
use wire::{self, ContestMatch, NamedAgent};

pub(super) async fn create_tournament(
    State(s): State<AppState>,
    headers: HeaderMap,
    body: Result<Json<wire::NewTournament>, JsonRejection>,
) -> ApiResult<Response> {
    let caller = check_token(&s, &headers).await?;
    let Json(t) = body?;
    let kind = t.kind;
    if t.agents.len() < 2 || t.agents.len() > 64 {
        return Err(ApiError::bad("agents", "a tournament needs 2 to 64 agents"));
    }
    if t.rallies_per_match == 0 || t.rallies_per_match > s.settings.max_rallies {
        return Err(ApiError::bad(
            "rallies_per_match",
            format!(
                "rallies_per_match must be between 1 and {}",
                s.settings.max_rallies
            ),
        ));
    }
    if t.rounds == 0 || t.rounds > 100 {
        return Err(ApiError::bad("rounds", "rounds must be between 1 and 100"));
    }
    let pairs = tournament::pairs(kind, t.agents.len(), t.rounds);
    if pairs.len() > s.settings.max_tournament_matches as usize {
        return Err(ApiError::bad(
            "agents",
            format!(
                "this tournament would queue {} matches; the limit is {}",
                pairs.len(),
                s.settings.max_tournament_matches
            ),
        ));
    }
    let seed = seed_or_clock(t.seed)?;
    let mut agents = Vec::with_capacity(t.agents.len());
    for r in &t.agents {
        agents.push(agent_or_404(&s, r, "agents").await?);
    }
    // Names and ids may both be given: the same agent twice is caught once resolved.
    let mut resolved = std::collections::HashSet::new();
    if let Some(dup) = agents.iter().find(|a| !resolved.insert(a.id)) {
        return Err(ApiError::bad(
            "agents",
            format!("agent '{}' is listed twice", dup.name),
        ));
    }
    if let Some(first) = agents.first() {
        for other in &agents {
            same_robot(&s, first, other, "agents")?;
        }
    }
    let rallies = pairs.len() as u64 * u64::from(t.rallies_per_match);
    charge(
        &s,
        caller,
        &[
            (Budget::Matches, pairs.len() as u64),
            (Budget::Rallies, rallies),
        ],
    )?;
    let plan = db::TournamentPlan {
        kind,
        agents: &agents,
        pairs: &pairs,
        rallies: t.rallies_per_match,
        rounds: t.rounds,
        seed,
        created_by: submitter(caller),
    };
    let id = db::create_tournament(&s.pool, plan).await?;
    s.wake.notify_waiters();
    tracing::info!(
        id,
        kind = kind.as_str(),
        matches = pairs.len(),
        "tournament queued"
    );
    let v = tournament_view(&s, tournament_or_404(&s, id).await?).await?;
    Ok((
        StatusCode::ACCEPTED,
        [(header::LOCATION, format!("/api/v1/tournaments/{id}"))],
        Json(v),
    )
        .into_response())
}

/// The tournament with id `id`, or 404.
async fn tournament_or_404(s: &AppState, id: i64) -> ApiResult<db::Tournament> {
    db::tournament(&s.pool, id)
        .await?
        .ok_or_else(|| ApiError::not_found("tournament", id))
}

/// A tournament with its progress, standings, cross-table and matches.
async fn tournament_view(s: &AppState, t: db::Tournament) -> ApiResult<wire::TournamentView> {
    let id = t.id;
    let ids: Vec<i64> = serde_json::from_str(&t.agents_json)
        .map_err(|e| anyhow::anyhow!("tournament {id}: stored agents unreadable: {e}"))?;
    let mut agents = Vec::with_capacity(ids.len());
    for aid in ids {
        let name = db::agent(&s.pool, aid)
            .await?
            .map(|a| a.name)
            .unwrap_or_else(|| format!("#{aid}"));
        agents.push((aid, name));
    }
    let kind = t.kind;
    let matches = db::tournament_matches(&s.pool, id).await?;
    let view = tournament::view(kind, &agents, &matches);
    Ok(wire::TournamentView {
        summary: wire::TournamentSummary {
            id: t.id,
            kind: t.kind,
            agents: agents
                .into_iter()
                .map(|(id, name)| NamedAgent { id, name })
                .collect(),
            rallies_per_match: t.rallies_per_match,
            rounds: t.rounds,
            created_at: t.created_at,
            progress: view.progress,
        },
        seed: t.seed,
        standings: view.standings,
        cross_table_agents: view.cross_table_agents,
        cross_table: view.cross_table,
        matches: matches.iter().map(ContestMatch::of).collect(),
    })
}

pub(super) async fn get_tournament(
    State(s): State<AppState>,
    Path(id): Path<String>,
) -> ApiResult<Json<wire::TournamentView>> {
    let id = parse_id(&id, "id")?;
    Ok(Json(
        tournament_view(&s, tournament_or_404(&s, id).await?).await?,
    ))
}

pub(super) async fn list_tournaments(
    State(s): State<AppState>,
    Typed(q): Typed<wire::LimitQuery>,
) -> ApiResult<Json<wire::TournamentList>> {
    let limit = limit_of(q.limit, 100, 1000)?;
    let mut tournaments = Vec::new();
    for t in db::tournaments(&s.pool, limit).await? {
        tournaments.push(tournament_view(&s, t).await?.summary);
    }
    Ok(Json(wire::TournamentList { tournaments }))
}

pub(super) async fn cancel_tournament(
    State(s): State<AppState>,
    headers: HeaderMap,
    Path(id): Path<String>,
) -> ApiResult<Json<wire::TournamentView>> {
    let caller = check_token(&s, &headers).await?;
    let id = parse_id(&id, "id")?;
    let t = tournament_or_404(&s, id).await?;
    may_cancel(caller, t.created_by, &format!("tournament {id}"))?;
    if db::cancel_tournament(&s.pool, id).await? == 0 {
        return Err(ApiError::not_cancellable(format!(
            "tournament {id} has no queued or running match left"
        )));
    }
    Ok(Json(tournament_view(&s, t).await?))
}

pub(super) async fn create_sprt(
    State(s): State<AppState>,
    headers: HeaderMap,
    body: Result<Json<wire::NewSprt>, JsonRejection>,
) -> ApiResult<Response> {
    let caller = check_token(&s, &headers).await?;
    let Json(t) = body?;
    if t.a == t.b {
        return Err(ApiError::bad("b", "an SPRT needs two different agents"));
    }
    for (field, v) in [("elo0", t.elo0), ("elo1", t.elo1)] {
        if !(v.is_finite() && v.abs() <= 1000.0) {
            return Err(ApiError::bad(
                field,
                format!("{field} must be a number of Elo within ±1000"),
            ));
        }
    }
    if t.elo0 >= t.elo1 {
        return Err(ApiError::bad("elo1", "elo1 must be greater than elo0"));
    }
    for (field, v) in [("alpha", t.alpha), ("beta", t.beta)] {
        if !(v > 0.0 && v < 0.5) {
            return Err(ApiError::bad(field, format!("{field} must be in (0, 0.5)")));
        }
    }
    if t.rallies_per_match == 0 || t.rallies_per_match > s.settings.max_rallies {
        return Err(ApiError::bad(
            "rallies_per_match",
            format!(
                "rallies_per_match must be between 1 and {}",
                s.settings.max_rallies
            ),
        ));
    }
    if !(2..=10_000).contains(&t.max_matches) {
        return Err(ApiError::bad(
            "max_matches",
            "max_matches must be between 2 and 10000",
        ));
    }
    let seed = seed_or_clock(t.seed)?;
    let a = agent_or_404(&s, &t.a, "a").await?;
    let b = agent_or_404(&s, &t.b, "b").await?;
    if a.id == b.id {
        return Err(ApiError::bad("b", "an SPRT needs two different agents"));
    }
    same_robot(&s, &a, &b, "b")?;
    // Its first match is queued now; it may play up to max_matches of them.
    let most = u64::from(t.max_matches) * u64::from(t.rallies_per_match);
    charge(&s, caller, &[(Budget::Matches, 1), (Budget::Rallies, most)])?;
    let params = db::SprtParams {
        elo0: t.elo0,
        elo1: t.elo1,
        alpha: t.alpha,
        beta: t.beta,
        rallies: t.rallies_per_match,
        max_matches: t.max_matches,
        seed,
    };
    let id = db::create_sprt(&s.pool, &a, &b, params, submitter(caller)).await?;
    s.wake.notify_one();
    Ok((
        StatusCode::ACCEPTED,
        [(header::LOCATION, format!("/api/v1/sprt/{id}"))],
        Json(sprt_view(&s, id).await?),
    )
        .into_response())
}

/// An SPRT with its bounds, the point share and Elo estimate so far, and its matches.
async fn sprt_view(s: &AppState, id: i64) -> ApiResult<wire::SprtView> {
    let t = db::sprt(&s.pool, id)
        .await?
        .ok_or_else(|| ApiError::not_found("SPRT", id))?;
    let matches = db::sprt_matches(&s.pool, id).await?;
    let (lower, upper) = ratings::sprt_bounds(t.alpha, t.beta);
    let mut shares = Vec::new();
    let list: Vec<wire::SprtMatch> = matches
        .iter()
        .map(|m| {
            let share = match (m.points_a, m.points_b) {
                (Some(pa), Some(pb)) => ratings::share_of(t.agent_a, m.agent_a, pa, pb),
                _ => None,
            };
            shares.extend(share);
            wire::SprtMatch {
                m: ContestMatch::of(m),
                share_of_a: share,
            }
        })
        .collect();
    let mean = (!shares.is_empty()).then(|| shares.iter().sum::<f64>() / shares.len() as f64);
    let elo = mean
        .filter(|m| *m > 0.0 && *m < 1.0)
        .map(|m| -400.0 * (1.0 / m - 1.0).log10());
    let name = |aid: i64| async move {
        db::agent(&s.pool, aid)
            .await
            .map(|a| a.map(|a| a.name).unwrap_or_else(|| format!("#{aid}")))
    };
    Ok(wire::SprtView {
        agent_a_name: name(t.agent_a).await?,
        agent_b_name: name(t.agent_b).await?,
        bounds: wire::Bounds { lower, upper },
        mean_share_of_a: mean,
        elo_estimate: elo,
        matches: list,
        row: t,
    })
}

pub(super) async fn get_sprt(
    State(s): State<AppState>,
    Path(id): Path<String>,
) -> ApiResult<Json<wire::SprtView>> {
    let id = parse_id(&id, "id")?;
    Ok(Json(sprt_view(&s, id).await?))
}

pub(super) async fn list_sprts(
    State(s): State<AppState>,
    Typed(q): Typed<wire::LimitQuery>,
) -> ApiResult<Json<wire::SprtList>> {
    let limit = limit_of(q.limit, 100, 1000)?;
    Ok(Json(wire::SprtList {
        sprts: db::sprts(&s.pool, limit).await?,
    }))
}

pub(super) async fn cancel_sprt(
    State(s): State<AppState>,
    headers: HeaderMap,
    Path(id): Path<String>,
) -> ApiResult<Json<wire::SprtView>> {
    let caller = check_token(&s, &headers).await?;
    let id = parse_id(&id, "id")?;
    let t = db::sprt(&s.pool, id)
        .await?
        .ok_or_else(|| ApiError::not_found("SPRT", id))?;
    may_cancel(caller, t.created_by, &format!("SPRT {id}"))?;
    if !db::cancel_sprt(&s.pool, id).await? {
        return Err(ApiError::not_cancellable(format!(
            "SPRT {id} has ended ({})",
            t.status
        )));
    }
    Ok(Json(sprt_view(&s, id).await?))
}

pub(super) async fn get_rating_history(
    State(s): State<AppState>,
    Path(id): Path<String>,
    Typed(q): Typed<wire::LimitQuery>,
) -> ApiResult<Json<wire::RatingHistory>> {
    let id = parse_id(&id, "id")?;
    let limit = limit_of(q.limit, 1000, 10_000)?;
    let a = db::agent(&s.pool, id)
        .await?
        .ok_or_else(|| ApiError::not_found("agent", id))?;
    let (total, history) = db::rating_history(&s.pool, id, limit).await?;
    Ok(Json(wire::RatingHistory {
        agent_id: id,
        agent: a.name,
        system: "glicko2".into(),
        total,
        history,
    }))
}

pub(super) async fn get_agent_crossings(
    State(s): State<AppState>,
    Path(id): Path<String>,
    Typed(q): Typed<wire::LimitQuery>,
) -> ApiResult<Json<wire::AgentCrossings>> {
    let id = parse_id(&id, "id")?;
    let limit = limit_of(q.limit, 2000, 20_000)?;
    let a = db::agent(&s.pool, id)
        .await?
        .ok_or_else(|| ApiError::not_found("agent", id))?;
    let (total, crossings) = db::agent_crossings(&s.pool, id, limit).await?;
    Ok(Json(wire::AgentCrossings {
        agent_id: id,
        agent: a.name,
        serve_box: wire::ServeBox {
            half_width: sim::arena::SERVE_BOX_HALF_WIDTH,
            z_low: sim::arena::SERVE_BOX_Z.0,
            z_high: sim::arena::SERVE_BOX_Z.1,
        },
        total,
        crossings,
    }))
}
