//! The bad-input table: every malformed request gets a JSON 4xx naming what is wrong, and the store
//! holds nothing of it.

use super::*;

/// What, method, path, headers, body, expected status.
type Case<'a> = (
    &'a str,
    &'a str,
    &'a str,
    Vec<(&'a str, &'a str)>,
    Vec<u8>,
    u16,
);

#[test]
fn bad_input_gets_a_json_4xx_and_writes_nothing() {
    let dir = tempdir("bad");
    let srv = start(&dir, false);
    let a = srv.addr.as_str();
    let good = template("ok");
    let mut nan_dims = good.clone();
    // Wrong dimensions: drop one output row of the last layer.
    let layers = nan_dims["policy"]["layers"].as_array_mut().expect("layers");
    layers.last_mut().unwrap()["bias"]
        .as_array_mut()
        .unwrap()
        .pop();
    let json_ct = [("Content-Type", "application/json")];
    let auth = format!("Bearer {TOKEN}");
    let authed = [
        ("Content-Type", "application/json"),
        ("Authorization", auth.as_str()),
    ];
    let big = vec![b'x'; 70_000];
    let long_target = format!("/api/v1/agents?x={}", "a".repeat(9000));
    let long_header = "p".repeat(40_000);
    let cases: Vec<Case> = vec![
        (
            "method not allowed",
            "DELETE",
            "/api/v1/leaderboard",
            vec![],
            vec![],
            405,
        ),
        ("method not allowed on a page", "POST", "/", vec![], vec![], 405),
        ("no such page", "GET", "/nope", vec![], vec![], 404),
        (
            "an agent name no agent can have (a NUL byte: PostgreSQL refuses it)",
            "POST",
            "/api/v1/sprt",
            authed.to_vec(),
            b"{\"a\": \"k\\u0000\", \"b\": \"scripted\", \"elo0\": 0, \"elo1\": 50}".to_vec(),
            404,
        ),
        (
            "an id that is not UTF-8",
            "GET",
            "/api/v1/agents/%FF",
            vec![],
            vec![],
            400,
        ),
        (
            "request target too long",
            "GET",
            long_target.as_str(),
            vec![],
            vec![],
            414,
        ),
        (
            "headers too large",
            "GET",
            "/api/v1/healthz",
            vec![("X-Pad", long_header.as_str())],
            vec![],
            431,
        ),
        (
            "malformed JSON",
            "POST",
            "/api/v1/matches",
            authed.to_vec(),
            b"{\"a\": 1,".to_vec(),
            400,
        ),
        (
            "wrong content type",
            "POST",
            "/api/v1/matches",
            vec![("Content-Type", "text/plain"), ("Authorization", auth.as_str())],
            br#"{"a":1,"b":2,"rallies":3}"#.to_vec(),
            415,
        ),
        (
            "missing field",
            "POST",
            "/api/v1/matches",
            authed.to_vec(),
            br#"{"a":1,"b":2}"#.to_vec(),
            422,
        ),
        (
            "unknown agent",
            "POST",
            "/api/v1/matches",
            authed.to_vec(),
            br#"{"a":1,"b":999,"rallies":3}"#.to_vec(),
            404,
        ),
        (
            "zero rallies",
            "POST",
            "/api/v1/matches",
            authed.to_vec(),
            br#"{"a":1,"b":2,"rallies":0}"#.to_vec(),
            400,
        ),
        (
            "too many rallies",
            "POST",
            "/api/v1/matches",
            authed.to_vec(),
            br#"{"a":1,"b":2,"rallies":1001}"#.to_vec(),
            400,
        ),
        (
            "negative seed",
            "POST",
            "/api/v1/matches",
            authed.to_vec(),
            br#"{"a":1,"b":2,"rallies":3,"seed":-1}"#.to_vec(),
            422,
        ),
        (
            "non-numeric id",
            "GET",
            "/api/v1/matches/abc",
            vec![],
            vec![],
            400,
        ),
        (
            "unknown match",
            "GET",
            "/api/v1/matches/12345",
            vec![],
            vec![],
            404,
        ),
        (
            "unknown agent id",
            "GET",
            "/api/v1/agents/77",
            vec![],
            vec![],
            404,
        ),
        (
            "bad status filter",
            "GET",
            "/api/v1/matches?status=bogus",
            vec![],
            vec![],
            400,
        ),
        (
            "bad page cursor",
            "GET",
            "/api/v1/matches?before=abc",
            vec![],
            vec![],
            400,
        ),
        (
            "bad limit",
            "GET",
            "/api/v1/matches?limit=0",
            vec![],
            vec![],
            400,
        ),
        (
            "cancel unknown",
            "DELETE",
            "/api/v1/matches/999",
            authed.to_vec(),
            vec![],
            404,
        ),
        (
            "replay of unknown",
            "GET",
            "/api/v1/matches/5/replay?rally=0",
            vec![],
            vec![],
            404,
        ),
        (
            "replay of a rally that is no index",
            "GET",
            "/api/v1/matches/5/replay?rally=x",
            vec![],
            vec![],
            400,
        ),
        (
            "matches of a status that does not exist",
            "GET",
            "/api/v1/matches?status=lost",
            vec![],
            vec![],
            400,
        ),
        (
            "no token",
            "POST",
            "/api/v1/agents",
            json_ct.to_vec(),
            json!({"name": "x", "checkpoint": good})
                .to_string()
                .into_bytes(),
            401,
        ),
        (
            "bad token",
            "POST",
            "/api/v1/agents",
            vec![
                ("Content-Type", "application/json"),
                ("Authorization", "Bearer nope"),
            ],
            json!({"name": "x", "checkpoint": good})
                .to_string()
                .into_bytes(),
            401,
        ),
        (
            "SQL in name",
            "POST",
            "/api/v1/agents",
            authed.to_vec(),
            json!({"name": "x'; DROP TABLE agents;--", "checkpoint": good})
                .to_string()
                .into_bytes(),
            400,
        ),
        (
            "path traversal name",
            "POST",
            "/api/v1/agents",
            authed.to_vec(),
            json!({"name": "../../etc/passwd", "checkpoint": good})
                .to_string()
                .into_bytes(),
            400,
        ),
        (
            "empty name",
            "POST",
            "/api/v1/agents",
            authed.to_vec(),
            json!({"name": "", "checkpoint": good})
                .to_string()
                .into_bytes(),
            400,
        ),
        (
            "long name",
            "POST",
            "/api/v1/agents",
            authed.to_vec(),
            json!({"name": "n".repeat(65), "checkpoint": good})
                .to_string()
                .into_bytes(),
            400,
        ),
        (
            "taken name",
            "POST",
            "/api/v1/agents",
            authed.to_vec(),
            json!({"name": "scripted", "checkpoint": good})
                .to_string()
                .into_bytes(),
            409,
        ),
        (
            "taken name in other case",
            "POST",
            "/api/v1/agents",
            authed.to_vec(),
            json!({"name": "SCRIPTED", "checkpoint": good})
                .to_string()
                .into_bytes(),
            409,
        ),
        (
            "NaN weight",
            "POST",
            "/api/v1/agents",
            authed.to_vec(),
            json!({"name": "nan", "checkpoint": good})
                .to_string()
                .replacen("0.0", "NaN", 1)
                .into_bytes(),
            400,
        ),
        (
            "wrong dimensions",
            "POST",
            "/api/v1/agents",
            authed.to_vec(),
            json!({"name": "dims", "checkpoint": nan_dims})
                .to_string()
                .into_bytes(),
            422,
        ),
        (
            "not a checkpoint",
            "POST",
            "/api/v1/agents",
            authed.to_vec(),
            br#"{"name":"y","checkpoint":{"hello":1}}"#.to_vec(),
            422,
        ),
        (
            "oversize body",
            "POST",
            "/api/v1/agents",
            authed.to_vec(),
            [br#"{"name":"big","checkpoint":""#.as_slice(), &big, b"\"}"].concat(),
            413,
        ),
        (
            "match without a token",
            "POST",
            "/api/v1/matches",
            json_ct.to_vec(),
            br#"{"a":1,"b":2,"rallies":3}"#.to_vec(),
            401,
        ),
        (
            "cancel without a token",
            "DELETE",
            "/api/v1/matches/1",
            vec![],
            vec![],
            401,
        ),
        (
            "tournament of an unknown kind",
            "POST",
            "/api/v1/tournaments",
            authed.to_vec(),
            br#"{"kind":"swiss","agents":[1,2],"rallies_per_match":2}"#.to_vec(),
            422,
        ),
        (
            "tournament of one agent",
            "POST",
            "/api/v1/tournaments",
            authed.to_vec(),
            br#"{"kind":"round_robin","agents":[1],"rallies_per_match":2}"#.to_vec(),
            400,
        ),
        (
            "tournament listing an agent twice",
            "POST",
            "/api/v1/tournaments",
            authed.to_vec(),
            br#"{"kind":"round_robin","agents":[1,2,1],"rallies_per_match":2}"#.to_vec(),
            400,
        ),
        (
            "tournament naming an agent by id and by name",
            "POST",
            "/api/v1/tournaments",
            authed.to_vec(),
            br#"{"kind":"round_robin","agents":[1,"scripted"],"rallies_per_match":2}"#.to_vec(),
            400,
        ),
        (
            "match against an unknown name",
            "POST",
            "/api/v1/matches",
            authed.to_vec(),
            br#"{"a":"scripted","b":"nobody","rallies":2}"#.to_vec(),
            404,
        ),
        (
            "tournament with an unknown agent",
            "POST",
            "/api/v1/tournaments",
            authed.to_vec(),
            br#"{"kind":"gauntlet","agents":[1,999],"rallies_per_match":2}"#.to_vec(),
            404,
        ),
        (
            "tournament of 0 rounds",
            "POST",
            "/api/v1/tournaments",
            authed.to_vec(),
            br#"{"kind":"gauntlet","agents":[1,2],"rallies_per_match":2,"rounds":0}"#.to_vec(),
            400,
        ),
        (
            "tournament over the match limit",
            "POST",
            "/api/v1/tournaments",
            authed.to_vec(),
            json!({"kind": "round_robin", "agents": (1..=64).collect::<Vec<i64>>(), "rallies_per_match": 2, "rounds": 100})
                .to_string()
                .into_bytes(),
            400,
        ),
        (
            "tournament without a token",
            "POST",
            "/api/v1/tournaments",
            json_ct.to_vec(),
            br#"{"kind":"gauntlet","agents":[1,2],"rallies_per_match":2}"#.to_vec(),
            401,
        ),
        (
            "unknown tournament",
            "GET",
            "/api/v1/tournaments/999",
            vec![],
            vec![],
            404,
        ),
        (
            "cancel unknown tournament",
            "DELETE",
            "/api/v1/tournaments/999",
            authed.to_vec(),
            vec![],
            404,
        ),
        (
            "SPRT of an agent against itself",
            "POST",
            "/api/v1/sprt",
            authed.to_vec(),
            br#"{"a":1,"b":1}"#.to_vec(),
            400,
        ),
        (
            "SPRT with elo0 above elo1",
            "POST",
            "/api/v1/sprt",
            authed.to_vec(),
            br#"{"a":1,"b":2,"elo0":10,"elo1":5}"#.to_vec(),
            400,
        ),
        (
            "SPRT with alpha 0.7",
            "POST",
            "/api/v1/sprt",
            authed.to_vec(),
            br#"{"a":1,"b":2,"alpha":0.7}"#.to_vec(),
            400,
        ),
        (
            "SPRT with an unknown agent",
            "POST",
            "/api/v1/sprt",
            authed.to_vec(),
            br#"{"a":1,"b":77}"#.to_vec(),
            404,
        ),
        (
            "non-numeric SPRT id",
            "GET",
            "/api/v1/sprt/abc",
            vec![],
            vec![],
            400,
        ),
        (
            "rating history of an unknown agent",
            "GET",
            "/api/v1/agents/999/ratings",
            vec![],
            vec![],
            404,
        ),
        (
            "multipart without a checkpoint",
            "POST",
            "/api/v1/agents",
            vec![
                ("Content-Type", "multipart/form-data; boundary=XyZ"),
                ("Authorization", auth.as_str()),
            ],
            b"--XyZ\r\nContent-Disposition: form-data; name=\"name\"\r\n\r\nmp\r\n--XyZ--\r\n".to_vec(),
            422,
        ),
        (
            "multipart with a non-JSON checkpoint",
            "POST",
            "/api/v1/agents",
            vec![
                ("Content-Type", "multipart/form-data; boundary=XyZ"),
                ("Authorization", auth.as_str()),
            ],
            b"--XyZ\r\nContent-Disposition: form-data; name=\"name\"\r\n\r\nmp\r\n--XyZ\r\nContent-Disposition: form-data; name=\"checkpoint\"; filename=\"c.json\"\r\n\r\nnot json\r\n--XyZ--\r\n".to_vec(),
            422,
        ),
        ("no such route", "GET", "/api/v1/nope", vec![], vec![], 404),
        (
            "token without admin",
            "POST",
            "/api/v1/tokens",
            json_ct.to_vec(),
            br#"{"name":"t"}"#.to_vec(),
            401,
        ),
        (
            "token with a bad name",
            "POST",
            "/api/v1/tokens",
            authed.to_vec(),
            br#"{"name":"a b"}"#.to_vec(),
            400,
        ),
    ];
    for (what, method, path, headers, body, want) in &cases {
        let (code, resp) = raw(a, method, path, headers, body);
        assert_eq!(code, *want, "{what}: {}", String::from_utf8_lossy(&resp));
        let v: Value = serde_json::from_slice(&resp)
            .unwrap_or_else(|_| panic!("{what}: not JSON: {}", String::from_utf8_lossy(&resp)));
        assert!(
            v["error"]["message"]
                .as_str()
                .is_some_and(|m| !m.is_empty()),
            "{what}: {v}"
        );
    }
    // A query string is read as its type: the parameter at fault is named.
    for (path, field, says) in [
        ("/api/v1/matches?limit=abc", "limit", "invalid digit"),
        (
            "/api/v1/matches?status=lost",
            "status",
            "unknown variant `lost`",
        ),
        ("/api/v1/agents?all=2", "all", "must be 1 or 0"),
        (
            "/api/v1/tournaments?bogus=1",
            "bogus",
            "unknown field `bogus`",
        ),
    ] {
        let (code, v) = call(a, "GET", path, None, None);
        assert_eq!(code, 400, "{path}: {v}");
        assert_eq!(v["error"]["field"], field, "{path}: {v}");
        let message = v["error"]["message"].as_str().unwrap_or_default();
        assert!(message.contains(says), "{path}: {v}");
    }
    // Nothing was written.
    let (_, agents) = call(a, "GET", "/api/v1/agents", None, None);
    assert!(
        agents["agents"]
            .as_array()
            .unwrap()
            .iter()
            .all(|x| x["builtin"] == true),
        "{agents}"
    );
    let (_, matches) = call(a, "GET", "/api/v1/matches", None, None);
    assert_eq!(matches["matches"].as_array().unwrap().len(), 0);
    let (_, t) = call(a, "GET", "/api/v1/tournaments", None, None);
    assert_eq!(t["tournaments"].as_array().unwrap().len(), 0, "{t}");
    let (_, p) = call(a, "GET", "/api/v1/sprt", None, None);
    assert_eq!(p["sprts"].as_array().unwrap().len(), 0, "{p}");
    // And the server is still up.
    let (code, _) = call(a, "GET", "/api/v1/healthz", None, None);
    assert_eq!(code, 200);
}
