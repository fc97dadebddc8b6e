//! `/agents`: the list, one agent, submissions (JSON or multipart, qualified before they are stored).

use super::*;

/// `GET /agents`: the agents that play; `?all=1` the retired ones too; `?model=` one robot's.
pub(super) async fn list_agents(
    State(s): State<AppState>,
    Typed(q): Typed<wire::AgentsQuery>,
) -> ApiResult<Json<wire::AgentList>> {
    let all = q.all;
    let mut agents = match &q.model {
        Some(robot) => {
            s.arenas
                .require(robot)
                .map_err(|e| ApiError::bad("model", e))?;
            db::agents_of(&s.pool, robot).await?
        }
        None => db::agents(&s.pool).await?,
    };
    agents.retain(|a| all || a.retired_at.is_none());
    Ok(Json(wire::AgentList { agents }))
}

/// `DELETE /agents/{id}`: retires the agent (its owner's token or the admin's). It keeps its row,
/// matches and replays; it is no longer scheduled, named in new matches, or listed by default.
pub(super) async fn retire_agent(
    State(s): State<AppState>,
    headers: HeaderMap,
    Path(id): Path<String>,
) -> ApiResult<Json<db::Agent>> {
    let caller = check_token(&s, &headers).await?;
    let id = parse_id(&id, "id")?;
    let agent = db::agent(&s.pool, id)
        .await?
        .ok_or_else(|| ApiError::not_found("agent", id))?;
    let owner = db::agent_owner(&s.pool, id).await?;
    owner_or_admin(
        caller,
        owner,
        &format!("agent {id} was not submitted"),
        "retire",
    )?;
    if !db::retire_agent(&s.pool, id).await? {
        return Err(ApiError::new(
            StatusCode::CONFLICT,
            "retired",
            format!("agent {id} ('{}') was retired already", agent.name),
        ));
    }
    tracing::info!(id, name = %agent.name, "agent retired");
    let agent = db::agent(&s.pool, id)
        .await?
        .ok_or_else(|| anyhow::anyhow!("agent {id} vanished after its retirement"))?;
    Ok(Json(agent))
}

pub(super) async fn get_agent(
    State(s): State<AppState>,
    Path(id): Path<String>,
) -> ApiResult<Json<wire::AgentDetail>> {
    let id = parse_id(&id, "id")?;
    let a = db::agent(&s.pool, id)
        .await?
        .ok_or_else(|| ApiError::not_found("agent", id))?;
    // A trained checkpoint's provenance and learning curve, as the checkpoint carries them (kept
    // apart from its weights: a few kilobytes to read, not the checkpoint).
    let training = db::agent_training(&s.pool, id).await?;
    Ok(Json(wire::AgentDetail {
        row: a,
        drift: db::agent_drift_summary(&s.pool, id).await?,
        rally_lengths: db::agent_rally_lengths(&s.pool, id)
            .await?
            .into_iter()
            .map(|(length, rallies)| wire::RallyCount { length, rallies })
            .collect(),
        training,
    }))
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

/// `POST /agents` as the server reads it: [`wire::SubmitAgent`] with the checkpoint kept as the text
/// it was sent (checked to be JSON, but no tree of it built: its admission process parses it).
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct Submission {
    name: String,
    checkpoint: Box<serde_json::value::RawValue>,
}

/// Reads a multipart submission: a `name` text field and a `checkpoint` file (the checkpoint JSON).
pub(super) async fn read_multipart(mut form: Multipart) -> ApiResult<Submission> {
    let bad_part = |e: MultipartError| ApiError::new(e.status(), "bad_multipart", e.body_text());
    let (mut name, mut checkpoint) = (None, None);
    while let Some(field) = form.next_field().await.map_err(bad_part)? {
        match field.name().unwrap_or("") {
            "name" => name = Some(field.text().await.map_err(bad_part)?),
            "checkpoint" => {
                let bytes = field.bytes().await.map_err(bad_part)?;
                let v: Box<serde_json::value::RawValue> =
                    serde_json::from_slice(&bytes).map_err(|e| ApiError {
                        field: Some("checkpoint".into()),
                        ..ApiError::new(
                            StatusCode::UNPROCESSABLE_ENTITY,
                            "invalid_checkpoint",
                            format!("the checkpoint file is not JSON: {e}"),
                        )
                    })?;
                checkpoint = Some(v);
            }
            other => {
                return Err(ApiError::bad(
                    "multipart",
                    format!("unknown form field '{other}' (name, checkpoint)"),
                ))
            }
        }
    }
    let missing = |f: &'static str| ApiError {
        field: Some(f.into()),
        ..ApiError::new(
            StatusCode::UNPROCESSABLE_ENTITY,
            "missing_field",
            format!("the form has no '{f}' field"),
        )
    };
    Ok(Submission {
        name: name.ok_or_else(|| missing("name"))?,
        checkpoint: checkpoint.ok_or_else(|| missing("checkpoint"))?,
    })
}

pub(super) async fn submit_agent(State(s): State<AppState>, req: Request) -> ApiResult<Response> {
    let caller = check_token(&s, req.headers()).await?;
    let multipart = req
        .headers()
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.starts_with("multipart/form-data"));
    let body = if multipart {
        let form = Multipart::from_request(req, &s)
            .await
            .map_err(|e| ApiError::new(e.status(), "bad_multipart", e.body_text()))?;
        read_multipart(form).await?
    } else {
        let Json(body) = Json::<Submission>::from_request(req, &s).await?;
        body
    };
    check_name(&body.name).map_err(|m| ApiError::bad("name", m))?;
    if let Some(why) = crate::arenas::reserved_name(&body.name) {
        return Err(ApiError::bad("name", why));
    }
    // Names are unique regardless of case: `SCRIPTED` is not a second `scripted`.
    if let Some(a) = db::agent_by_name(&s.pool, &body.name).await? {
        return Err(ApiError::name_taken("an agent", &a.name));
    }
    let busy = || ApiError {
        retry_after: Some(30),
        ..ApiError::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "busy",
            format!(
                "{} submissions already wait for their admission (admission_queue); retry later",
                s.settings.admission_queue
            ),
        )
    };
    if s.admit_waiting.load(std::sync::atomic::Ordering::SeqCst) >= s.settings.admission_queue {
        return Err(busy());
    }
    // The robot it plays (`model`; none: the default robot's), one this server plays. A text that
    // is no checkpoint's JSON gets its admission's precise message.
    let robot = db::model_of(body.checkpoint.get())
        .unwrap_or_else(|| sim::config::DEFAULT_ROBOT.to_string());
    s.arenas.require(&robot).map_err(|e| ApiError {
        field: Some("checkpoint.model".into()),
        ..ApiError::new(StatusCode::UNPROCESSABLE_ENTITY, "unknown_robot", e)
    })?;
    charge(&s, caller, &[(Budget::Agents, 1)])?;
    let text = body.checkpoint.get().to_string();
    drop(body.checkpoint);
    let refused = |code: &'static str, message: String| ApiError {
        field: Some("checkpoint".into()),
        ..ApiError::new(StatusCode::UNPROCESSABLE_ENTITY, code, message)
    };
    use crate::admission::Refused;
    let mut report =
        match crate::admission::admit_submission(&s, &robot, text.clone()).await? {
            Err(Refused::Busy) => return Err(busy()),
            Ok(report) => report,
            Err(Refused::Invalid(e)) => return Err(refused("invalid_checkpoint", e)),
            Err(Refused::Failed(e)) => return Err(refused("qualification_failed", e)),
            Err(Refused::Crashed(e)) => return Err(refused("invalid_checkpoint", e)),
            Err(Refused::OverCpu(budget)) => {
                return Err(refused(
                    "over_budget",
                    format!(
                    "admitting the checkpoint (validating it, building its network, playing its \
                     qualification) used more than the server's admission_cpu_s ({budget} s of CPU \
                     time)"
                ),
                ))
            }
            Err(Refused::Killed) => return Err(refused(
                "over_budget",
                "admitting the checkpoint got its process killed: past its hard CPU-time limit \
                 (admission_cpu_s) or by the kernel's out-of-memory killer (admission_memory_mb)"
                    .into(),
            )),
            Err(Refused::OverMemory(budget, what)) => {
                return Err(refused(
                    "over_budget",
                    format!(
                        "admitting the checkpoint asked for more memory than the server's \
                     admission_memory_mb ({budget} MiB): {what}"
                    ),
                ))
            }
        };
    // The report names the agent as submitted (not the checkpoint's inner name).
    report.agent = body.name.clone();
    crate::admission::admits(&s.settings, &report)
        .map_err(|e| refused("below_qualification", e))?;
    let qual = (
        report.episodes,
        report.hit_rate.value,
        report.success_rate.value,
        report.effort.value,
    );
    let id = match db::insert_checkpoint_agent(
        &s.pool,
        &body.name,
        &robot,
        &text,
        qual,
        false,
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
    s.publish_agent(id);
    let agent = db::agent(&s.pool, id)
        .await?
        .ok_or_else(|| anyhow::anyhow!("agent {id} vanished after its insert"))?;
    Ok((
        StatusCode::CREATED,
        Json(wire::Submitted {
            agent,
            qualification: qualification(report),
        }),
    )
        .into_response())
}

/// A qualification's report as the API shows it.
fn qualification(r: ::agents::eval::EvalReport) -> wire::Qualification {
    let rate = |r: ::agents::eval::Rate| wire::Interval {
        value: r.value,
        low: r.low,
        high: r.high,
    };
    let mean = |m: ::agents::eval::Mean| wire::Interval {
        value: m.value,
        low: m.low,
        high: m.high,
    };
    wire::Qualification {
        agent: r.agent,
        serve: r.serve,
        seed: r.seed,
        episodes: r.episodes,
        hit_rate: rate(r.hit_rate),
        success_rate: rate(r.success_rate),
        effort: mean(r.effort),
        mean_activation: mean(r.mean_activation),
        activation_to_contact: r.activation_to_contact.map(mean),
        activation_after_contact: r.activation_after_contact.map(mean),
        after_contact_steps: r.after_contact_steps,
        ends: r.ends,
    }
}
