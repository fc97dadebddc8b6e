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

    /// Every JSON answer of the document has a schema, and the schemas are the `wire` types' own
    /// (`RALLY_UPDATE_OPENAPI=1 cargo test -p server every_answer` rewrites them from the types).
    #[test]
    fn every_answer_has_a_schema_and_the_schemas_are_the_wire_types() {
        let mut v: serde_json::Value = serde_json::from_str(super::OPENAPI).expect("valid JSON");
        let generated = wire::answer_schemas();
        if std::env::var_os("RALLY_UPDATE_OPENAPI").is_some() {
            let schemas = v["components"]["schemas"].as_object_mut().expect("schemas");
            for (name, schema) in &generated {
                schemas.insert(name.clone(), schema.clone());
            }
            let path = concat!(env!("CARGO_MANIFEST_DIR"), "/src/openapi.json");
            let text = serde_json::to_string_pretty(&v).expect("JSON") + "\n";
            std::fs::write(path, text).expect("openapi.json written");
            return;
        }
        for (name, schema) in &generated {
            assert_eq!(
                &v["components"]["schemas"][name], schema,
                "the schema of {name} is not the wire type's: RALLY_UPDATE_OPENAPI=1 cargo test -p server every_answer rewrites it"
            );
        }
        let mut missing = Vec::new();
        for (path, ops) in v["paths"].as_object().expect("paths") {
            for (method, op) in ops.as_object().expect("operations") {
                for (code, answer) in op["responses"].as_object().expect("responses") {
                    let described = answer["content"]
                        .as_object()
                        .is_some_and(|c| c.values().all(|m| m.get("schema").is_some()));
                    if !described {
                        missing.push(format!("{method} {path} {code}"));
                    }
                }
            }
        }
        assert!(missing.is_empty(), "answers without a schema: {missing:?}");
    }
}
