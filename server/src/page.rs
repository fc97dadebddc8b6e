//! The leaderboard web page (one self-contained HTML file that polls the API) and the OpenAPI
//! document of the API.

/// `GET /`: the leaderboard and the latest matches, refreshed every 5 s.
pub const INDEX: &str = include_str!("index.html");

/// `GET /replay?match=ID&rally=K`: a stored rally drawn from above and from the side, played back.
pub const REPLAY: &str = include_str!("replay.html");

/// `GET /api/v1/openapi.json`.
pub const OPENAPI: &str = include_str!("openapi.json");

#[cfg(test)]
mod tests {
    #[test]
    fn the_openapi_document_is_json_and_names_every_route() {
        let v: serde_json::Value = serde_json::from_str(super::OPENAPI).expect("valid JSON");
        let paths = v["paths"].as_object().expect("paths");
        // Every `.route("…"` of the router, read from its source.
        let source = include_str!("api.rs");
        let routes: Vec<&str> = source
            .split(".route(")
            .skip(1)
            .filter_map(|rest| rest.split('"').nth(1))
            .collect();
        assert!(routes.len() >= 14, "{routes:?}");
        // `/` and `/replay` are HTML pages, outside the API.
        for p in routes.into_iter().filter(|p| !["/", "/replay"].contains(p)) {
            assert!(paths.contains_key(p), "{p} is not documented");
        }
    }
}
