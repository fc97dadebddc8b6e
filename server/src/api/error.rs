//! The error contract — every rejected request gets a 4xx (or a 5xx for the server's own failures)
//! with `{"error": {"code", "message", "field"}}` — and the typed reading of paths and query strings
//! that names the part at fault.

use axum::extract::rejection::JsonRejection;
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;

/// A rejected request.
#[derive(Debug)]
pub struct ApiError {
    pub(super) status: StatusCode,
    pub(super) code: &'static str,
    pub(super) message: String,
    pub(super) field: Option<std::borrow::Cow<'static, str>>,
    pub(super) retry_after: Option<u64>,
}

impl ApiError {
    pub(crate) fn new(
        status: StatusCode,
        code: &'static str,
        message: impl Into<String>,
    ) -> ApiError {
        ApiError {
            status,
            code,
            message: message.into(),
            field: None,
            retry_after: None,
        }
    }

    pub(super) fn bad(field: &'static str, message: impl Into<String>) -> ApiError {
        ApiError {
            field: Some(field.into()),
            ..ApiError::new(StatusCode::BAD_REQUEST, "invalid_field", message)
        }
    }

    pub(super) fn name_taken(what: &str, name: &str) -> ApiError {
        ApiError {
            field: Some("name".into()),
            ..ApiError::new(
                StatusCode::CONFLICT,
                "name_taken",
                format!("{what} named '{name}' exists"),
            )
        }
    }

    pub(super) fn not_cancellable(message: String) -> ApiError {
        ApiError::new(StatusCode::CONFLICT, "not_cancellable", message)
    }

    pub(super) fn not_found(what: &str, id: i64) -> ApiError {
        ApiError::new(
            StatusCode::NOT_FOUND,
            "not_found",
            format!("no {what} with id {id}"),
        )
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let body = wire::ErrorBody {
            error: wire::ErrorDetail {
                code: self.code.to_string(),
                message: self.message,
                field: self.field.map(|f| f.into_owned()),
            },
        };
        let mut r = (self.status, Json(body)).into_response();
        if let Some(secs) = self.retry_after {
            r.headers_mut()
                .insert(header::RETRY_AFTER, header::HeaderValue::from(secs));
        }
        r
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

pub(super) type ApiResult<T> = Result<T, ApiError>;

pub(super) fn parse_id(raw: &str, what: &'static str) -> ApiResult<i64> {
    raw.parse::<i64>()
        .ok()
        .filter(|&id| id > 0)
        .ok_or_else(|| ApiError::bad(what, format!("'{raw}' is not a positive integer id")))
}

/// A query string as `T` (one of `wire`'s queries): an unknown parameter or a value of the wrong
/// kind is a 400 naming the parameter.
pub(super) struct Typed<T>(pub(super) T);

impl<S: Send + Sync, T: serde::de::DeserializeOwned> axum::extract::FromRequestParts<S>
    for Typed<T>
{
    type Rejection = ApiError;

    async fn from_request_parts(
        parts: &mut axum::http::request::Parts,
        _: &S,
    ) -> Result<Typed<T>, ApiError> {
        let raw = parts.uri.query().unwrap_or("");
        let de = serde_urlencoded::Deserializer::new(form_urlencoded::parse(raw.as_bytes()));
        serde_path_to_error::deserialize(de)
            .map(Typed)
            .map_err(|e| {
                let path = e.path().to_string();
                let message = match path.as_str() {
                    "." => format!("query: {}", e.inner()),
                    p => format!("query parameter '{p}': {}", e.inner()),
                };
                ApiError {
                    field: Some(if path == "." {
                        "query".into()
                    } else {
                        path.into()
                    }),
                    ..ApiError::new(StatusCode::BAD_REQUEST, "invalid_field", message)
                }
            })
    }
}

/// `?limit=`: from 1 to `max`, `default` when absent.
pub(super) fn limit_of(limit: Option<i64>, default: i64, max: i64) -> ApiResult<i64> {
    match limit {
        None => Ok(default),
        Some(l) if (1..=max).contains(&l) => Ok(l),
        Some(l) => Err(ApiError::bad(
            "limit",
            format!("limit must be an integer from 1 to {max}, not {l}"),
        )),
    }
}
