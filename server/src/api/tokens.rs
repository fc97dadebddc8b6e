//! `/tokens`: submitter tokens, issued by the admin.

use super::*;

pub(super) async fn issue_token(
    State(s): State<AppState>,
    headers: HeaderMap,
    body: Result<Json<wire::NewToken>, JsonRejection>,
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
        Json(wire::IssuedToken {
            id,
            name: body.name,
            token,
            note: "shown once: only its SHA-256 is stored".into(),
        }),
    )
        .into_response())
}
