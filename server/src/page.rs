//! The leaderboard web page (one self-contained HTML file that polls the API) and the OpenAPI
//! document of the API.

/// `GET /`: the leaderboard and the latest matches, refreshed every 5 s.
pub const INDEX: &str = include_str!("index.html");

/// `GET /replay?match=ID&rally=K`: a stored rally drawn from above and from the side, played back.
pub const REPLAY: &str = include_str!("replay.html");

/// `GET /agent?id=N`: one agent — where its returns cross the hitting plane, its rating history, its
/// latest matches.
pub const AGENT: &str = include_str!("agent.html");

/// `GET /api/v1/openapi.json`.
pub const OPENAPI: &str = include_str!("openapi.json");

#[cfg(test)]
mod tests {
    #[test]
    fn the_openapi_document_is_json_and_names_every_route() {
        let v: serde_json::Value = serde_json::from_str(super::OPENAPI).expect("valid JSON");
        let paths = v["paths"].as_object().expect("paths");
        // Every `.route("…"` of the router, read from its source.
        let source = include_str!("api/mod.rs");
        let routes: Vec<&str> = source
            .split(".route(")
            .skip(1)
            .filter_map(|rest| rest.split('"').nth(1))
            .collect();
        assert!(routes.len() >= 14, "{routes:?}");
        // `/`, `/replay` and `/agent` are HTML pages, outside the API.
        for p in routes
            .into_iter()
            .filter(|p| !["/", "/replay", "/agent"].contains(p))
        {
            assert!(paths.contains_key(p), "{p} is not documented");
        }
    }

    /// The document's schemas name exactly the fields the API serialises.
    #[test]
    fn the_schemas_match_the_rows() {
        let v: serde_json::Value = serde_json::from_str(super::OPENAPI).expect("valid JSON");
        let keys = |schema: &str| {
            let mut k: Vec<String> = v["components"]["schemas"][schema]["properties"]
                .as_object()
                .expect("properties")
                .keys()
                .cloned()
                .collect();
            k.sort();
            k
        };
        let fields = |row: serde_json::Value| {
            let mut k: Vec<String> = row
                .as_object()
                .expect("an object")
                .keys()
                .cloned()
                .collect();
            k.sort();
            k
        };
        let m = crate::db::example_match(1, 1, 2);
        assert_eq!(keys("Match"), fields(serde_json::to_value(m).unwrap()));
        let a = crate::db::Agent {
            id: 1,
            name: String::new(),
            kind: crate::db::AgentKind::Scripted,
            spec_hash: String::new(),
            builtin: true,
            created_at: String::new(),
            qual_episodes: None,
            hit_rate: None,
            success_rate: None,
            effort: None,
            retired_at: None,
        };
        assert_eq!(keys("Agent"), fields(serde_json::to_value(a).unwrap()));
    }
}
