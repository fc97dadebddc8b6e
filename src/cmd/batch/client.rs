//! The HTTP side of `rally batch`: JSON requests with the bearer token, refusals turned into the
//! server's message, rate limits waited out.

use std::time::Duration;

use anyhow::anyhow;
use serde::de::DeserializeOwned;
use serde::Serialize;
use serde_json::Value;

/// The HTTP side: JSON requests with the bearer token, 4xx/5xx turned into the server's message.
pub(super) struct Client {
    base: String,
    token: String,
    http: ureq::Agent,
}

/// A refused request: status and the server's `error.message` (and field).
#[derive(Debug)]
struct Refused {
    status: u16,
    message: String,
    retry_after: Option<u64>,
}

impl std::fmt::Display for Refused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "HTTP {}: {}", self.status, self.message)
    }
}

impl std::error::Error for Refused {}

impl Client {
    pub(super) fn new(base: &str, token: String) -> Client {
        let http: ureq::Agent = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .timeout_global(Some(Duration::from_secs(300)))
            .build()
            .into();
        Client {
            base: base.trim_end_matches('/').to_string(),
            token,
            http,
        }
    }

    /// One request; Ok(body) on 2xx, Err(Refused) on a refusal (the server's `wire::ErrorBody`),
    /// Err(other) when the server could not be reached or answered something that is not the
    /// expected body.
    pub(super) fn call<T: DeserializeOwned>(
        &self,
        method: &str,
        path: &str,
        body: Option<&Value>,
    ) -> anyhow::Result<T> {
        let url = format!("{}/api/v1{path}", self.base);
        let auth = format!("Bearer {}", self.token);
        let resp = match (method, body) {
            ("GET", _) => self.http.get(&url).header("Authorization", &auth).call(),
            ("POST", Some(b)) => self
                .http
                .post(&url)
                .header("Authorization", &auth)
                .send_json(b),
            ("DELETE", _) => self.http.delete(&url).header("Authorization", &auth).call(),
            _ => return Err(anyhow!("unsupported request {method} {path}")),
        };
        let mut resp = resp.map_err(|e| anyhow!("could not reach the server at {url}: {e}"))?;
        let status = resp.status().as_u16();
        let retry_after = resp
            .headers()
            .get("retry-after")
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.trim().parse().ok());
        let v: Value = resp
            .body_mut()
            .read_json()
            .map_err(|e| anyhow!("{method} {url}: HTTP {status}, the answer is not JSON: {e}"))?;
        if (200..300).contains(&status) {
            return serde_json::from_value(v)
                .map_err(|e| anyhow!("{method} {url}: an unexpected answer: {e}"));
        }
        let message = match serde_json::from_value::<wire::ErrorBody>(v.clone()) {
            Ok(wire::ErrorBody { error }) => match error.field {
                Some(field) => format!("{} (field '{field}')", error.message),
                None => error.message,
            },
            Err(_) => v.to_string(),
        };
        Err(Refused {
            status,
            message,
            retry_after,
        }
        .into())
    }

    /// A POST of `body` that waits out rate limits (429 + Retry-After), telling `say` why it waits.
    pub(super) fn post_patiently<B: Serialize, T: DeserializeOwned>(
        &self,
        path: &str,
        body: &B,
        say: &dyn Fn(String),
    ) -> anyhow::Result<T> {
        let body = serde_json::to_value(body)?;
        let mut waited = 0u64;
        loop {
            match self.call("POST", path, Some(&body)) {
                Err(e) => match e.downcast_ref::<Refused>() {
                    Some(r) if r.status == 429 && waited < 600 => {
                        let secs = r.retry_after.unwrap_or(5).clamp(1, 60);
                        say(format!("rate limited; waiting {secs} s ({})", r.message));
                        std::thread::sleep(Duration::from_secs(secs));
                        waited += secs;
                    }
                    _ => return Err(e),
                },
                ok => return ok,
            }
        }
    }
}
