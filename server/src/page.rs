//! The leaderboard web page (one self-contained HTML file that polls the API) and the OpenAPI
//! document of the API.

/// `GET /`: the leaderboard and the latest matches, refreshed every 5 s.
pub const INDEX: &str = include_str!("index.html");

/// `GET /api/v1/openapi.json`.
pub const OPENAPI: &str = include_str!("openapi.json");

#[cfg(test)]
mod tests {
    #[test]
    fn the_openapi_document_is_json_and_names_every_route() {
        let v: serde_json::Value = serde_json::from_str(super::OPENAPI).expect("valid JSON");
        let paths = v["paths"].as_object().expect("paths");
        for p in [
            "/healthz",
            "/agents",
            "/agents/{id}",
            "/matches",
            "/matches/{id}",
            "/matches/{id}/replay",
            "/leaderboard",
            "/metrics",
            "/tokens",
        ] {
            assert!(paths.contains_key(p), "{p} is not documented");
        }
    }
}
