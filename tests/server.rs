//! The real server (`rally serve`, a child process) on a loopback port with a real store (SQLite, or
//! PostgreSQL on CI's second pass): submit and qualify a checkpoint, play matches, read the
//! leaderboard and replays, cancel, kill -9 in the middle of a match and restart (nothing lost,
//! nothing counted twice), and the bad-input table. Requests and answers go through the server's
//! own types (`server::wire`), so a field the server stops sending fails here; the bad-input table
//! sends raw bytes on purpose, and the drawings (arena, model, replay frames) stay JSON.

use std::io::BufRead;
use std::process::Command;
use std::time::{Duration, Instant};

use serde_json::{json, Value};
use server::db::{self, AgentKind, MatchStatus, SprtStatus};
use server::ratings::Leaderboard;
use server::tournament::ProgressState;
use server::wire::{
    AgentCrossings, AgentDetail, AgentList, ErrorBody, Health, IssuedToken, MatchDetail, MatchList,
    NewSprt, NewToken, NewTournament, QualificationRule, QueueMatch, RatingHistory, SprtView,
    SubmitAgent, Submitted, TournamentList, TournamentView,
};

mod common;
use common::*;

fn template(name: &str) -> Value {
    let out = Command::new(env!("CARGO_BIN_EXE_rally"))
        .args(["checkpoint", "template", "--hidden", "16", "--name", name])
        .output()
        .unwrap();
    assert!(out.status.success());
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn submit_qualify_match_leaderboard_replay_cancel() {
    let dir = tempdir("flow");
    let srv = start(&dir, false);
    let a = srv.addr.as_str();

    let h: Health = get_as(a, "/api/v1/healthz");
    assert_eq!(h.status, "ok");
    // The pages draw the simulator's own arena (a drawing's shape: JSON, no wire type).
    let (code, arena) = call(a, "GET", "/api/v1/arena", None, None);
    assert_eq!(code, 200);
    assert_eq!(arena["table"]["y"], json!([-0.72, 0.8]), "{arena}");
    assert_eq!(arena["table"]["top_z"], 0.795);
    assert_eq!(arena["net"]["top_z"], 0.9475);
    assert_eq!(arena["paddle"]["blade"]["radius"], 0.093);
    assert_eq!(arena["sim_version"], h.sim_version.as_str());
    let agents: AgentList = get_as(a, "/api/v1/agents");
    let builtins = agents.agents.len();
    assert!(builtins >= 3, "{agents:?}");
    // Every committed checkpoint is a built-in agent beside the scripted ones, qualified.
    let committed: Vec<String> = std::fs::read_dir("config/checkpoints")
        .unwrap()
        .filter_map(|e| {
            let p = e.unwrap().path();
            (p.extension()? == "json").then(|| p.file_stem().unwrap().to_string_lossy().into())
        })
        .collect();
    assert!(committed.iter().any(|n| n == "kmac"), "{committed:?}");
    for name in &committed {
        let row = agents
            .agents
            .iter()
            .find(|x| &x.name == name)
            .unwrap_or_else(|| panic!("built-in checkpoint {name} missing: {agents:?}"));
        assert_eq!(
            (row.builtin, row.kind),
            (true, AgentKind::Checkpoint),
            "{row:?}"
        );
        assert_eq!(row.qual_episodes, Some(6), "{row:?}");
        assert!(row.hit_rate.is_some() && row.effort.is_some());
        // Its page shows the learning curve the checkpoint carries.
        let one: AgentDetail = get_as(a, &format!("/api/v1/agents/{}", row.id));
        let curve = one.training.as_ref().map(|t| &t["curve"]);
        assert!(
            curve
                .and_then(Value::as_array)
                .is_some_and(|c| !c.is_empty()),
            "{name}: no curve"
        );
        assert!(one.rally_lengths.is_empty());
    }
    assert_eq!(builtins, 3 + committed.len(), "{agents:?}");

    // Submit and qualify a checkpoint.
    let zero = SubmitAgent {
        name: "zero-policy".into(),
        checkpoint: template("zero"),
    };
    let sub: Submitted = post_as(a, "/api/v1/agents", &zero, Some(TOKEN), 201);
    assert_eq!(sub.qualification.episodes, 6);
    let cid = sub.agent.id;
    let got: AgentDetail = get_as(a, &format!("/api/v1/agents/{cid}"));
    assert_eq!(got.row.name, "zero-policy");
    assert!(got.row.hit_rate.unwrap() >= 0.0);

    // The admin issues a submitter token; it can submit but not issue tokens; only its hash is stored.
    let lab = |name: &str| NewToken { name: name.into() };
    let t: IssuedToken = post_as(a, "/api/v1/tokens", &lab("lab-1"), Some(TOKEN), 201);
    let token = t.token;
    let e: ErrorBody = post_as(a, "/api/v1/tokens", &lab("lab-2"), Some(&token), 403);
    assert_eq!(e.error.code, "admin_only");
    let _: ErrorBody = post_as(a, "/api/v1/tokens", &lab("lab-1"), Some(TOKEN), 409);
    let policy = SubmitAgent {
        name: "lab-1-policy".into(),
        checkpoint: template("lab"),
    };
    let _: Submitted = post_as(a, "/api/v1/agents", &policy, Some(&token), 201);
    let needle = token.as_bytes();
    for bytes in stored_bytes(&dir) {
        assert!(
            !bytes.windows(needle.len()).any(|w| w == needle),
            "the token itself is never stored"
        );
    }

    let queue = |x: i64, y: i64, rallies: u32, seed: u64| QueueMatch {
        a: x.into(),
        b: y.into(),
        rallies,
        seed: Some(seed),
    };
    let m: db::Match = post_as(a, "/api/v1/matches", &queue(1, 2, 6, 7), Some(TOKEN), 202);
    let id = m.id;
    wait_for(a, id, "done", Duration::from_secs(120));
    let done: MatchDetail = get_as(a, &format!("/api/v1/matches/{id}"));
    assert_eq!(done.rally_log.len(), 6);
    let cli = Command::new(env!("CARGO_BIN_EXE_rally"))
        .args([
            "match",
            "scripted",
            "scripted-drive",
            "--rallies",
            "6",
            "--seed",
            "7",
            "--json",
        ])
        .output()
        .unwrap();
    let cli: Value = serde_json::from_slice(&cli.stdout).unwrap();
    assert_eq!(cli["points"], json!([done.row.points_a, done.row.points_b]));
    for (x, y) in cli["rallies"]
        .as_array()
        .unwrap()
        .iter()
        .zip(&done.rally_log)
    {
        assert_eq!(x["length"], y.length);
        assert_eq!(x["end"], y.end_reason.as_str());
        assert_eq!(x["duration"], y.duration, "durations are bit-identical");
    }
    assert_eq!(
        cli["drift"]["energy_distance"],
        done.drift.as_ref().unwrap()["energy_distance"]
    );

    // Replay frames, gzip on request.
    let (code, rep) = call(
        a,
        "GET",
        &format!("/api/v1/matches/{id}/replay?rally=1"),
        None,
        None,
    );
    assert_eq!((code, rep["resimulated"].as_bool()), (200, Some(false)));
    assert!(rep["frames"].as_array().unwrap().len() > 10);
    let (code, gz) = raw(
        a,
        "GET",
        &format!("/api/v1/matches/{id}/replay?rally=1"),
        &[("Accept-Encoding", "gzip")],
        b"",
    );
    assert_eq!(code, 200);
    assert_eq!(&gz[..2], &[0x1f, 0x8b], "gzip magic");
    let (code, _) = call(
        a,
        "GET",
        &format!("/api/v1/matches/{id}/replay?rally=6"),
        None,
        None,
    );
    assert_eq!(code, 400);

    // The checkpoint plays too, and everything shows on the leaderboard.
    let m2: db::Match = post_as(a, "/api/v1/matches", &queue(cid, 3, 4, 1), Some(TOKEN), 202);
    wait_for(a, m2.id, "done", Duration::from_secs(120));
    let board: Leaderboard = get_as(a, "/api/v1/leaderboard");
    assert_eq!(board.matches, 2);
    // The agent page's data: its rally lengths, and no training provenance (a template).
    let got: AgentDetail = get_as(a, &format!("/api/v1/agents/{cid}"));
    let total: i64 = got.rally_lengths.iter().map(|r| r.rallies).sum();
    assert_eq!(total, 4, "{got:?}");
    assert!(got.training.is_none(), "{got:?}");
    assert_eq!(board.rows.len(), builtins + 2);
    for r in &board.rows {
        assert_eq!(r.matches > 0, r.glicko2_deviation < 350.0, "{r:?}");
        assert_eq!(r.matches > 0, r.rating_low.is_some(), "{r:?}");
        if let (Some(low), Some(high)) = (r.rating_low, r.rating_high) {
            assert!(low <= r.rating && r.rating <= high, "{r:?}");
        }
    }
    let list: MatchList = get_as(a, &format!("/api/v1/matches?agent={cid}&status=done"));
    assert_eq!(list.matches.len(), 1);

    // Cancelling: a finished match cannot be; a queued or running one can, and stays cancelled.
    let (code, e) = delete(a, &format!("/api/v1/matches/{id}"), Some(TOKEN));
    assert_eq!(
        (code, e["error"]["code"].as_str()),
        (409, Some("not_cancellable"))
    );
    let long: db::Match = post_as(a, "/api/v1/matches", &queue(1, 3, 300, 3), Some(TOKEN), 202);
    let (code, c) = delete(a, &format!("/api/v1/matches/{}", long.id), Some(TOKEN));
    assert_eq!(code, 200, "{c}");
    let c: db::Match = serde_json::from_value(c).unwrap();
    assert_eq!(c.status, MatchStatus::Cancelled);
    std::thread::sleep(Duration::from_millis(300));
    let after: MatchDetail = get_as(a, &format!("/api/v1/matches/{}", long.id));
    assert_eq!(after.row.status, MatchStatus::Cancelled);

    // Metrics and the page.
    let (code, metrics) = raw(a, "GET", "/api/v1/metrics", &[], b"");
    assert_eq!(code, 200);
    assert!(String::from_utf8_lossy(&metrics).contains("rally_matches{status=\"done\"} 2"));
    let (code, page) = raw(a, "GET", "/", &[], b"");
    assert_eq!(code, 200);
    assert!(String::from_utf8_lossy(&page).contains("<table id=\"board\">"));
    let (code, viewer) = raw(a, "GET", "/replay?match=1&rally=0", &[], b"");
    assert_eq!(code, 200);
    assert!(String::from_utf8_lossy(&viewer).contains("<canvas id=\"view\""));
    // What the 3D viewer draws the robots with.
    let (code, robot) = call(a, "GET", "/api/v1/model", None, None);
    assert_eq!(code, 200);
    assert_eq!(robot["muscles"].as_array().unwrap().len(), 75, "{robot}");
    assert!(robot["geoms"].as_array().unwrap().len() >= 10);
    assert!(robot["paddle_body"].is_number());
    let (code, agent_page) = raw(a, "GET", "/agent?id=1", &[], b"");
    assert_eq!(code, 200);
    assert!(String::from_utf8_lossy(&agent_page).contains("<svg id=\"cloud\""));
    let (code, doc) = call(a, "GET", "/api/v1/openapi.json", None, None);
    assert_eq!((code, doc["openapi"].as_str()), (200, Some("3.0.3")));
}

#[test]
fn continuous_mode_fills_the_leaderboard() {
    let dir = tempdir("continuous");
    let srv = start(&dir, true);
    let t0 = Instant::now();
    loop {
        let board: Leaderboard = get_as(&srv.addr, "/api/v1/leaderboard");
        // Two workers queue concurrently, so an agent can be picked twice before another once:
        // after twice as many rated matches as agents (one match in three is cooperative), every
        // built-in has played (the most uncertain agent is picked first).
        if board.matches >= 3 * board.rows.len() {
            assert!(board.rows.iter().all(|r| r.matches > 0), "{board:?}");
            // The first match, and every third, is an agent against itself: the best qualified
            // first. It counts in its rally statistics and rates nothing.
            let all: MatchList = get_as(&srv.addr, "/api/v1/matches?status=done&limit=1000");
            let cooperative: Vec<_> = all
                .matches
                .iter()
                .filter(|m| m.agent_a == m.agent_b)
                .collect();
            assert!(
                cooperative.len() >= board.matches / 3 - 1,
                "{} of {}",
                cooperative.len(),
                board.matches
            );
            let first = all.matches.iter().min_by_key(|m| m.id).unwrap();
            assert_eq!(first.agent_a, first.agent_b, "{first:?}");
            let best = board
                .rows
                .iter()
                .max_by(|p, q| {
                    p.success_rate
                        .unwrap_or(-1.0)
                        .total_cmp(&q.success_rate.unwrap_or(-1.0))
                        .then(q.agent_id.cmp(&p.agent_id))
                })
                .unwrap();
            assert!(
                cooperative.iter().any(|m| m.agent_a == best.agent_id),
                "{best:?}"
            );
            // Continuous-mode matches keep no frames: the replay is re-simulated, and equals the
            // frames `rally match` writes for the same agents and seed.
            let list: MatchList = get_as(&srv.addr, "/api/v1/matches?status=done&limit=1");
            let m = &list.matches[0];
            assert!(!m.keep_replay, "{m:?}");
            let (code, r) = call(
                &srv.addr,
                "GET",
                &format!("/api/v1/matches/{}/replay?rally=1", m.id),
                None,
                None,
            );
            assert_eq!((code, r["resimulated"].as_bool()), (200, Some(true)), "{r}");
            let name = |agent: i64| {
                let a: AgentDetail = get_as(&srv.addr, &format!("/api/v1/agents/{agent}"));
                a.row.name
            };
            let file = dir.join("cli-replay.json");
            let out = Command::new(env!("CARGO_BIN_EXE_rally"))
                .args(["match", &name(m.agent_a), &name(m.agent_b)])
                .args([
                    "--rallies",
                    &m.rallies.to_string(),
                    "--seed",
                    &m.seed.to_string(),
                ])
                .arg("--replay")
                .arg(&file)
                .output()
                .unwrap();
            assert!(
                out.status.success(),
                "{}",
                String::from_utf8_lossy(&out.stderr)
            );
            let cli: Value =
                serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap();
            assert!(!r["frames"].as_array().unwrap().is_empty());
            // The server adds each frame's body poses (for the 3D viewer); the rest is the match's.
            let mut frames = r["frames"].clone();
            for f in frames.as_array_mut().unwrap() {
                let f = f.as_object_mut().unwrap();
                assert_eq!(
                    f["bodies_a"].as_array().unwrap().len(),
                    16,
                    "one pose per body"
                );
                assert!(f.remove("bodies_a").is_some() && f.remove("bodies_b").is_some());
            }
            assert_eq!(
                frames, cli["rallies"][1],
                "server re-simulation vs rally match --replay"
            );
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "the leaderboard did not fill within a minute: {board:?}"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}
#[test]
fn kill_9_in_the_middle_of_a_match_loses_nothing() {
    let dir = tempdir("restart");
    let mut srv = start(&dir, false);
    let q = QueueMatch {
        a: 2.into(),
        b: 3.into(),
        rallies: 150,
        seed: Some(11),
    };
    let m: db::Match = post_as(&srv.addr, "/api/v1/matches", &q, Some(TOKEN), 202);
    wait_for(&srv.addr, m.id, "running", Duration::from_secs(30));
    srv.child.kill().unwrap(); // SIGKILL: no graceful shutdown
    srv.child.wait().unwrap();
    drop(srv);

    let srv = start(&dir, false);
    let again: MatchDetail = get_as(&srv.addr, &format!("/api/v1/matches/{}", m.id));
    assert!(
        [db::MatchStatus::Queued, db::MatchStatus::Running].contains(&again.row.status),
        "re-queued: {again:?}"
    );
    wait_for(&srv.addr, m.id, "done", Duration::from_secs(300));
    let done: MatchDetail = get_as(&srv.addr, &format!("/api/v1/matches/{}", m.id));
    assert_eq!(done.rally_log.len(), 150, "every rally stored exactly once");
    let idx: Vec<i64> = done.rally_log.iter().map(|r| r.idx).collect();
    assert_eq!(idx, (0..150).collect::<Vec<_>>());
    assert!(done.row.points_a.unwrap() + done.row.points_b.unwrap() <= 150);
    let list: MatchList = get_as(&srv.addr, "/api/v1/matches");
    assert_eq!(list.matches.len(), 1, "no duplicate match");
}

#[test]
fn kill_9_during_an_sprt_neither_loses_nor_forks_it() {
    let dir = tempdir("sprt-restart");
    let mut srv = start(&dir, false);
    let test = NewSprt {
        elo1: 400.0,
        rallies_per_match: 40,
        max_matches: 4,
        seed: Some(20),
        ..NewSprt::new(1.into(), 2.into())
    };
    let p: SprtView = post_as(&srv.addr, "/api/v1/sprt", &test, Some(TOKEN), 202);
    let path = format!("/api/v1/sprt/{}", p.row.id);
    // Kill it while its second match is being played.
    let t0 = Instant::now();
    loop {
        let v: SprtView = get_as(&srv.addr, &path);
        if v.matches.len() == 2 && v.matches[1].m.status == MatchStatus::Running {
            break;
        }
        assert_eq!(
            v.row.status,
            SprtStatus::Running,
            "ended before the kill: {v:?}"
        );
        assert!(t0.elapsed() < Duration::from_secs(60), "{v:?}");
        std::thread::sleep(Duration::from_millis(20));
    }
    srv.child.kill().unwrap();
    srv.child.wait().unwrap();
    drop(srv);
    let srv = start(&dir, false);
    let p: SprtView = poll_as(
        &srv.addr,
        &path,
        Duration::from_secs(120),
        |v: &SprtView| v.row.status != SprtStatus::Running,
    );
    // One match per step, seeds 20, 21, … in order, sides alternating, all done: as if never killed.
    assert_eq!(p.matches.len() as i64, p.row.matches_done, "{p:?}");
    for (k, m) in p.matches.iter().enumerate() {
        assert_eq!(m.m.status, MatchStatus::Done, "{p:?}");
        assert_eq!(m.m.seed, 20 + k as i64);
        assert_eq!(m.m.agent_a, if k % 2 == 0 { 1 } else { 2 });
    }
    let all: MatchList = get_as(&srv.addr, "/api/v1/matches");
    assert_eq!(all.matches.len(), p.matches.len(), "no stray match");
}

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
            "/api/v1/matches/5/replay?rally=x",
            vec![],
            vec![],
            404,
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
            400,
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

#[test]
fn junk_below_the_qualification_thresholds_is_refused_and_a_trained_agent_admitted() {
    let dir = tempdir("admission");
    let srv = start_with(
        &dir,
        false,
        "builtin_checkpoints = \"\"\nqualification_min_hit_rate = 0.3\nqualification_max_dropped = 0.5\n\
         max_body_bytes = 8388608\n",
    );
    let a = srv.addr.as_str();
    // The rule is published.
    let h: Health = get_as(a, "/api/v1/healthz");
    let rule = QualificationRule {
        episodes: 6,
        min_hit_rate: 0.3,
        max_dropped: 0.5,
    };
    assert_eq!(h.qualification, Some(rule));
    // An untrained template hits nothing and drops its paddle: 422 with its figures, nothing stored.
    let junk = json!({"name": "junk", "checkpoint": template("junk")});
    let (code, v) = call(a, "POST", "/api/v1/agents", Some(&junk), Some(TOKEN));
    assert_eq!(code, 422, "{v}");
    assert_eq!(v["error"]["code"], "below_qualification", "{v}");
    let msg = v["error"]["message"].as_str().unwrap();
    assert!(
        msg.contains("of 6 P2 serves") && msg.contains("at least 30% qualifies"),
        "{msg}"
    );
    let list: AgentList = get_as(a, "/api/v1/agents");
    assert!(list.agents.iter().all(|x| x.builtin), "{list:?}");
    // The Diff-Muscle built-in's checkpoint, submitted as Mine2, passes; its report bears that name.
    let kmac: Value =
        serde_json::from_str(agents::builtins::checkpoint("kmac").expect("built in")).unwrap();
    let (code, v) = call(
        a,
        "POST",
        "/api/v1/agents",
        Some(&json!({"name": "Mine2", "checkpoint": kmac})),
        Some(TOKEN),
    );
    assert_eq!(code, 201, "{v}");
    let sub: Submitted = serde_json::from_value(v).unwrap();
    assert_eq!(
        (sub.agent.name.as_str(), sub.qualification.agent.as_str()),
        ("Mine2", "Mine2")
    );
    assert!(sub.qualification.hit_rate.value >= 0.3);
}

#[test]
fn a_validation_past_its_budget_is_refused_and_the_server_keeps_answering() {
    // An ONNX checkpoint (tract optimises its graph to validate it) under a 1 ms budget.
    use base64::Engine;
    let dir = tempdir("budget");
    let srv = start_with(
        &dir,
        false,
        "builtin_checkpoints = \"\"\nvalidation_budget_s = 0.001\nmax_body_bytes = 8388608\n",
    );
    let a = srv.addr.as_str();
    let mut ck = template("slow");
    ck.as_object_mut().unwrap().remove("policy");
    ck["onnx"] = json!({"model_base64": base64::engine::general_purpose::STANDARD
        .encode(include_bytes!("../agents/tests/fixtures/policy.onnx"))});
    let body = json!({"name": "slow", "checkpoint": ck});
    let (code, v) = call(a, "POST", "/api/v1/agents", Some(&body), Some(TOKEN));
    assert_eq!(code, 422, "{v}");
    assert_eq!(v["error"]["code"], "over_budget", "{v}");
    assert!(
        v["error"]["message"]
            .as_str()
            .unwrap()
            .contains("validation_budget_s"),
        "{v}"
    );
    let (code, _) = call(a, "GET", "/api/v1/healthz", None, None);
    assert_eq!(code, 200);
    let list: AgentList = get_as(a, "/api/v1/agents");
    assert!(
        list.agents.iter().all(|x| x.builtin),
        "nothing stored: {list:?}"
    );
}

#[test]
fn owners_retire_agents_which_keep_their_matches_and_play_no_new_ones() {
    let dir = tempdir("retire");
    let srv = start_with(&dir, false, "builtin_checkpoints = \"\"\n");
    let a = srv.addr.as_str();
    let lab = |name: &str| NewToken { name: name.into() };
    let owner: IssuedToken = post_as(a, "/api/v1/tokens", &lab("owner"), Some(TOKEN), 201);
    let other: IssuedToken = post_as(a, "/api/v1/tokens", &lab("other"), Some(TOKEN), 201);
    let policy = SubmitAgent {
        name: "old-policy".into(),
        checkpoint: template("old"),
    };
    let sub: Submitted = post_as(a, "/api/v1/agents", &policy, Some(&owner.token), 201);
    let id = sub.agent.id;
    let q = json!({"a": id, "b": "scripted", "rallies": 2, "seed": 3});
    let (code, m) = call(a, "POST", "/api/v1/matches", Some(&q), Some(&owner.token));
    assert_eq!(code, 202, "{m}");
    let played = m["id"].as_i64().unwrap();
    wait_for(a, played, "done", Duration::from_secs(120));
    let path = format!("/api/v1/agents/{id}");
    // Only its owner or the admin may retire it, once.
    let (code, v) = call(a, "DELETE", &path, None, Some(&other.token));
    assert_eq!(
        (code, v["error"]["code"].as_str()),
        (403, Some("not_owner")),
        "{v}"
    );
    let (code, v) = call(a, "DELETE", &path, None, Some(&owner.token));
    assert_eq!(code, 200, "{v}");
    assert!(v["retired_at"].is_string(), "{v}");
    let (code, v) = call(a, "DELETE", &path, None, Some(TOKEN));
    assert_eq!(
        (code, v["error"]["code"].as_str()),
        (409, Some("retired")),
        "{v}"
    );
    // Hidden from the list and the leaderboard; shown with ?all=1; its page and match stay.
    let list: AgentList = get_as(a, "/api/v1/agents");
    assert!(list.agents.iter().all(|x| x.id != id), "{list:?}");
    let all: AgentList = get_as(a, "/api/v1/agents?all=1");
    assert!(all
        .agents
        .iter()
        .any(|x| x.id == id && x.retired_at.is_some()));
    let (code, _) = call(a, "GET", "/api/v1/agents?all=maybe", None, None);
    assert_eq!(code, 400);
    let board: Leaderboard = get_as(a, "/api/v1/leaderboard");
    assert!(board.rows.iter().all(|r| r.agent_id != id), "{board:?}");
    assert!(board.rows.iter().enumerate().all(|(i, r)| r.rank == i + 1));
    let (code, _) = call(a, "GET", &path, None, None);
    assert_eq!(code, 200);
    let (code, _) = call(a, "GET", &format!("/api/v1/matches/{played}"), None, None);
    assert_eq!(code, 200);
    // Naming it in a new match, by id or by name, is refused.
    for named in [json!(id), json!("old-policy")] {
        let q = json!({"a": named, "b": "scripted", "rallies": 2});
        let (code, v) = call(a, "POST", "/api/v1/matches", Some(&q), Some(&owner.token));
        assert_eq!(
            (code, v["error"]["code"].as_str()),
            (409, Some("retired")),
            "{v}"
        );
    }
}

#[test]
fn the_leaderboard_agrees_with_every_agent_page() {
    // A seeded database: rated matches of different lengths and a cooperative one, all finished.
    let dir = tempdir("agree");
    let srv = start_with(&dir, false, "builtin_checkpoints = \"\"\n");
    let a = srv.addr.as_str();
    let plan = [
        ("scripted", "scripted-drive", 4, 1),
        ("scripted-drive", "scripted-soft", 6, 2),
        ("scripted", "scripted", 4, 3),
        ("scripted-soft", "scripted", 2, 4),
    ];
    for (x, y, rallies, seed) in plan {
        let q = json!({"a": x, "b": y, "rallies": rallies, "seed": seed});
        let (code, m) = call(a, "POST", "/api/v1/matches", Some(&q), Some(TOKEN));
        assert_eq!(code, 202, "{m}");
        wait_for(
            a,
            m["id"].as_i64().unwrap(),
            "done",
            Duration::from_secs(120),
        );
    }
    let board: Leaderboard = get_as(a, "/api/v1/leaderboard");
    let all: MatchList = get_as(a, "/api/v1/matches?status=done&limit=1000");
    assert_eq!(board.matches, plan.len());
    for row in &board.rows {
        let page: AgentDetail = get_as(a, &format!("/api/v1/agents/{}", row.agent_id));
        assert_eq!(page.row.name, row.agent);
        let mine = all
            .matches
            .iter()
            .filter(|m| m.agent_a == row.agent_id || m.agent_b == row.agent_id);
        let rated = mine.clone().filter(|m| m.agent_a != m.agent_b).count();
        let own = mine.filter(|m| m.agent_a == m.agent_b).count();
        assert_eq!(
            (row.matches, row.self_play_matches),
            (rated, own),
            "{}",
            row.agent
        );
        // Rally lengths: the page's histogram and the leaderboard's mean and longest.
        let rallies: i64 = page.rally_lengths.iter().map(|r| r.rallies).sum();
        let total: i64 = page
            .rally_lengths
            .iter()
            .map(|r| r.length * r.rallies)
            .sum();
        let mean = (rallies > 0).then(|| total as f64 / rallies as f64);
        let close = |x: Option<f64>, y: Option<f64>| match (x, y) {
            (Some(x), Some(y)) => (x - y).abs() < 1e-9,
            (None, None) => true,
            _ => false,
        };
        assert!(
            close(row.mean_rally_length, mean),
            "{}: {:?} vs {mean:?}",
            row.agent,
            row.mean_rally_length
        );
        assert_eq!(
            row.max_rally_length,
            page.rally_lengths.iter().map(|r| r.length).max(),
            "{}",
            row.agent
        );
        // The in-box fraction pooled over crossings, none without any.
        let drift = &page.drift;
        assert!(
            close(row.in_box_fraction, drift.in_box_fraction),
            "{}: {:?} vs {:?}",
            row.agent,
            row.in_box_fraction,
            drift.in_box_fraction
        );
    }
}

#[test]
fn slow_clients_are_cut_at_the_header_timeout_and_connections_are_capped() {
    // Four connections (the cap) that never finish their headers hold every slot: a fifth client
    // waits until the header-read timeout (1 s) closes them, then is served.
    use std::io::{Read, Write};
    let dir = tempdir("edge");
    let srv = start_with(
        &dir,
        false,
        "max_connections = 4\nheader_read_timeout_s = 1.0\n",
    );
    let a = srv.addr.as_str();
    let t0 = Instant::now();
    let (code, _) = call(a, "GET", "/api/v1/healthz", None, None);
    assert_eq!(code, 200);
    let idle = t0.elapsed();
    let mut slow: Vec<std::net::TcpStream> = (0..4)
        .map(|_| {
            let mut s = std::net::TcpStream::connect(a).unwrap();
            s.write_all(b"GET /api/v1/healthz HTTP/1.1\r\nHost: x\r\n")
                .unwrap();
            s
        })
        .collect();
    std::thread::sleep(Duration::from_millis(200));
    let t0 = Instant::now();
    let (code, _) = call(a, "GET", "/api/v1/healthz", None, None);
    let capped = t0.elapsed();
    assert_eq!(code, 200);
    eprintln!("healthz idle {idle:?}; behind four stalled clients {capped:?}");
    assert!(
        capped >= Duration::from_millis(500) && capped < Duration::from_secs(6),
        "the fifth client waits for the stalled ones' timeout, and no longer: {capped:?}"
    );
    // The stalled connections were closed by the server (end of stream, or a reset).
    for s in &mut slow {
        s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        let mut buf = [0u8; 256];
        match s.read(&mut buf) {
            Ok(n) => assert!(
                n == 0 || buf.starts_with(b"HTTP/1.1 408"),
                "{}",
                String::from_utf8_lossy(&buf[..n])
            ),
            Err(e) => assert!(
                !matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ),
                "a stalled connection is still open: {e}"
            ),
        }
    }
    // An idle keep-alive connection, its request answered, is closed after as long.
    let mut kept = std::net::TcpStream::connect(a).unwrap();
    kept.write_all(b"GET /api/v1/healthz HTTP/1.1\r\nHost: x\r\n\r\n")
        .unwrap();
    kept.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    let mut got = Vec::new();
    let t0 = Instant::now();
    let read = kept.read_to_end(&mut got);
    assert!(
        read.is_ok() && got.starts_with(b"HTTP/1.1 200"),
        "{read:?} after {:?}: {}",
        t0.elapsed(),
        String::from_utf8_lossy(&got)
    );
}

#[test]
fn sigterm_shuts_down_gracefully_and_loses_nothing() {
    let dir = tempdir("sigterm");
    let mut srv = start(&dir, false);
    let q = QueueMatch {
        a: 1.into(),
        b: 2.into(),
        rallies: 40,
        seed: Some(5),
    };
    let m: db::Match = post_as(&srv.addr, "/api/v1/matches", &q, Some(TOKEN), 202);
    wait_for(&srv.addr, m.id, "running", Duration::from_secs(30));
    let status = terminate(&mut srv);
    assert!(status.success(), "exit status {status:?}");
    drop(srv);
    // The running match was finished before exit (or, at worst, is re-queued): never lost.
    let srv = start(&dir, false);
    wait_for(&srv.addr, m.id, "done", Duration::from_secs(120));
    let done: MatchDetail = get_as(&srv.addr, &format!("/api/v1/matches/{}", m.id));
    assert_eq!(done.rally_log.len(), 40);
}

/// A multipart/form-data body with text fields and one file field.
fn multipart(boundary: &str, fields: &[(&str, &str)], file: (&str, &str, &[u8])) -> Vec<u8> {
    let mut out = Vec::new();
    for (k, v) in fields {
        out.extend_from_slice(
            format!("--{boundary}\r\nContent-Disposition: form-data; name=\"{k}\"\r\n\r\n{v}\r\n")
                .as_bytes(),
        );
    }
    out.extend_from_slice(
        format!(
            "--{boundary}\r\nContent-Disposition: form-data; name=\"{}\"; filename=\"{}\"\r\nContent-Type: application/json\r\n\r\n",
            file.0, file.1
        )
        .as_bytes(),
    );
    out.extend_from_slice(file.2);
    out.extend_from_slice(format!("\r\n--{boundary}--\r\n").as_bytes());
    out
}

#[test]
fn tournaments_sprt_rate_limits_multipart_and_rating_history() {
    let dir = tempdir("contests");
    // The three scripted built-ins only: the counts below are theirs.
    let srv = start_with(
        &dir,
        false,
        "max_matches_per_minute = 8\nmax_agents_per_hour = 1\nbuiltin_checkpoints = \"\"\n",
    );
    let a = srv.addr.as_str();
    let lab = |name: &str| NewToken { name: name.into() };
    let t: IssuedToken = post_as(a, "/api/v1/tokens", &lab("lab"), Some(TOKEN), 201);
    let token = t.token;
    let bearer = format!("Bearer {token}");
    let t2: IssuedToken = post_as(a, "/api/v1/tokens", &lab("other-lab"), Some(TOKEN), 201);
    let other = t2.token;

    // A checkpoint uploaded as a multipart form by the submitter token.
    let body = multipart(
        "b0undary",
        &[("name", "uploaded")],
        (
            "checkpoint",
            "uploaded.json",
            template("up").to_string().as_bytes(),
        ),
    );
    let (code, resp) = raw(
        a,
        "POST",
        "/api/v1/agents",
        &[
            ("Content-Type", "multipart/form-data; boundary=b0undary"),
            ("Authorization", bearer.as_str()),
        ],
        &body,
    );
    assert_eq!(code, 201, "{}", String::from_utf8_lossy(&resp));
    let v: Submitted = serde_json::from_slice(&resp).unwrap();
    assert_eq!(v.agent.name, "uploaded");
    assert_eq!(v.qualification.episodes, 6);
    // One agent an hour for this token: a second valid one is refused, before any qualification.
    let second = SubmitAgent {
        name: "second".into(),
        checkpoint: template("second"),
    };
    let e: ErrorBody = post_as(a, "/api/v1/agents", &second, Some(&token), 429);
    assert_eq!(e.error.code, "rate_limited");
    let listed: AgentList = get_as(a, "/api/v1/agents");
    assert_eq!(listed.agents.len(), 4, "{listed:?}");

    // A round robin of the three built-ins, two rounds: 6 matches, charged to the token (6 of 8).
    let rr = NewTournament {
        kind: "round_robin".into(),
        agents: vec!["scripted".into(), 2.into(), "scripted-soft".into()],
        rallies_per_match: 3,
        rounds: 2,
        seed: Some(40),
    };
    let t: TournamentView = post_as(a, "/api/v1/tournaments", &rr, Some(&token), 202);
    let tid = t.summary.id;
    assert_eq!(t.summary.progress.total, 6);
    let seeds: Vec<i64> = t.matches.iter().map(|m| m.seed).collect();
    assert_eq!(seeds, (40..46).collect::<Vec<i64>>());

    // The rate limit: two more matches fit in the minute, the third is refused with Retry-After and
    // writes nothing; the admin is not limited.
    let q = QueueMatch {
        a: 1.into(),
        b: 2.into(),
        rallies: 1,
        seed: Some(1),
    };
    for _ in 0..2 {
        let _: db::Match = post_as(a, "/api/v1/matches", &q, Some(&token), 202);
    }
    let (code, head, resp) = raw_full(
        a,
        "POST",
        "/api/v1/matches",
        &[
            ("Content-Type", "application/json"),
            ("Authorization", bearer.as_str()),
        ],
        &serde_json::to_vec(&q).unwrap(),
    );
    assert_eq!(code, 429, "{}", String::from_utf8_lossy(&resp));
    let e: ErrorBody = serde_json::from_slice(&resp).unwrap();
    assert_eq!(e.error.code, "rate_limited");
    let retry: u64 = head
        .lines()
        .find_map(|l| {
            l.to_ascii_lowercase()
                .strip_prefix("retry-after:")
                .map(|x| x.trim().to_string())
        })
        .expect("a Retry-After header")
        .parse()
        .unwrap();
    assert!((1..=61).contains(&retry), "{retry}");
    let gauntlet = NewTournament {
        kind: "gauntlet".into(),
        agents: vec![1.into(), 2.into()],
        rallies_per_match: 1,
        rounds: 1,
        seed: None,
    };
    let _: ErrorBody = post_as(a, "/api/v1/tournaments", &gauntlet, Some(&token), 429);
    let _: db::Match = post_as(a, "/api/v1/matches", &q, Some(TOKEN), 202);
    let all: MatchList = get_as(a, "/api/v1/matches");
    assert_eq!(all.matches.len(), 9, "6 + 2 + 1 (admin), none refused");
    let ts: TournamentList = get_as(a, "/api/v1/tournaments");
    assert_eq!(ts.tournaments.len(), 1);
    // Paging through the matches with `before`: every one once, newest first.
    let mut seen = vec![];
    let mut path = "/api/v1/matches?limit=4".to_string();
    loop {
        let page: MatchList = get_as(a, &path);
        seen.extend(page.matches.iter().map(|m| m.id));
        match page.next_before {
            Some(b) => path = format!("/api/v1/matches?limit=4&before={b}"),
            None => break,
        }
    }
    assert_eq!(seen, (1..=9).rev().collect::<Vec<i64>>());

    // The tournament finishes; its cross-table and standings agree with its matches.
    let t: TournamentView = poll_as(
        a,
        &format!("/api/v1/tournaments/{tid}"),
        Duration::from_secs(240),
        |v: &TournamentView| v.summary.progress.state == ProgressState::Finished,
    );
    assert_eq!(t.summary.progress.done, 6, "{t:?}");
    assert_eq!(t.summary.progress.fraction, 1.0);
    let ids = [1i64, 2, 3];
    let mut points = [[0i64; 3]; 3];
    for m in &t.matches {
        let i = ids.iter().position(|&x| x == m.agent_a).unwrap();
        let j = ids.iter().position(|&x| x == m.agent_b).unwrap();
        points[i][j] += m.points_a.unwrap();
        points[j][i] += m.points_b.unwrap();
    }
    let table = &t.cross_table;
    for i in 0..3 {
        assert!(table[i][i].is_none());
        for j in 0..3 {
            if i != j {
                let cell = table[i][j].as_ref().unwrap();
                assert_eq!(cell.matches, 2, "{table:?}");
                assert_eq!(cell.points_for, points[i][j]);
                assert_eq!(cell.points_against, points[j][i]);
            }
        }
    }
    let total_for: i64 = t.standings.iter().map(|s| s.record.points_for).sum();
    assert_eq!(total_for, points.iter().flatten().sum::<i64>());
    assert!(t.standings.iter().all(|s| s.record.matches == 4));

    // Each finished match stores both sides' drift; each one between two agents moves both ratings.
    let m: MatchDetail = get_as(a, &format!("/api/v1/matches/{}", t.matches[0].id));
    let sides = &m.drift_by_side;
    assert_eq!(sides.len(), 2, "{m:?}");
    assert_eq!(
        (sides[0].side.as_str(), sides[0].agent_id),
        ("A", m.row.agent_a)
    );
    assert!(sides[1].drift["crossings"].as_u64().is_some());
    for status in ["queued", "running"] {
        poll_as(
            a,
            &format!("/api/v1/matches?status={status}"),
            Duration::from_secs(120),
            |v: &MatchList| v.matches.is_empty(),
        );
    }
    let done: MatchList = get_as(a, "/api/v1/matches?agent=1&status=done");
    let h: RatingHistory = get_as(a, "/api/v1/agents/1/ratings");
    let history = &h.history;
    assert_eq!(history.len(), done.matches.len(), "{h:?}");
    assert!(history.windows(2).all(|w| w[0].seq < w[1].seq));
    assert!(history.windows(2).all(|w| w[1].deviation <= w[0].deviation));
    // The agent's own drift, pooled over the same matches.
    let agent: AgentDetail = get_as(a, "/api/v1/agents/1");
    assert_eq!(agent.drift.matches, history.len() as i64, "{agent:?}");
    assert!(agent.drift.crossings > 0, "{agent:?}");
    // The crossings behind it (SQL over the crossings table) are the same set the match runner's
    // per-side statistics counted.
    let cx: AgentCrossings = get_as(a, "/api/v1/agents/1/crossings");
    assert_eq!(cx.total, agent.drift.crossings, "{cx:?}");
    let list = &cx.crossings;
    assert_eq!(list.len() as i64, cx.total);
    let in_box = list.iter().filter(|c| c.in_box).count() as f64 / list.len() as f64;
    assert!((in_box - agent.drift.in_box_fraction.unwrap()).abs() < 1e-9);
    assert!(list.iter().any(|c| c.exchange == 0));
    let (code, _) = call(a, "GET", "/api/v1/agents/1/crossings?limit=0", None, None);
    assert_eq!(code, 400);
    let (_, metrics) = call(a, "GET", "/api/v1/metrics", None, None);
    assert!(
        metrics.as_str().unwrap().contains("rally_tournaments 1"),
        "{metrics}"
    );
    let board: Leaderboard = get_as(a, "/api/v1/leaderboard");
    let row = board.rows.iter().find(|r| r.agent_id == 1).unwrap();
    assert_eq!(row.glicko2, history.last().unwrap().rating, "{row:?}");
    assert!(
        row.drift.is_some() || row.in_box_fraction.is_some(),
        "{row:?}"
    );

    // An SPRT plays one match at a time, sides swapped and seed + k, until the test decides.
    let test = NewSprt {
        elo1: 100.0,
        rallies_per_match: 4,
        max_matches: 6,
        seed: Some(3),
        ..NewSprt::new(1.into(), 3.into())
    };
    let p: SprtView = post_as(a, "/api/v1/sprt", &test, Some(TOKEN), 202);
    let pid = p.row.id;
    let p: SprtView = poll_as(
        a,
        &format!("/api/v1/sprt/{pid}"),
        Duration::from_secs(240),
        |v: &SprtView| v.row.status != SprtStatus::Running,
    );
    let matches = &p.matches;
    assert_eq!(matches.len() as i64, p.row.matches_done, "{p:?}");
    assert!(matches.len() <= 6);
    let mut shares = vec![];
    for (k, m) in matches.iter().map(|m| &m.m).enumerate() {
        assert_eq!(m.status, MatchStatus::Done);
        assert_eq!(m.seed, 3 + k as i64);
        assert_eq!(m.agent_a, if k % 2 == 0 { 1 } else { 3 });
        let (pa, pb) = (m.points_a.unwrap(), m.points_b.unwrap());
        let mine = if k % 2 == 0 { pa } else { pb };
        if pa + pb > 0 {
            shares.push(mine as f64 / (pa + pb) as f64);
        }
    }
    // The GSPRT recomputed here from the matches' points.
    let n = shares.len() as f64;
    let llr = if shares.len() < 2 {
        0.0
    } else {
        let s0 = 0.5;
        let s1 = 1.0 / (1.0 + 10f64.powf(-100.0 / 400.0));
        let mean = shares.iter().sum::<f64>() / n;
        let var = shares.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
        let mid = 0.5 * (s0 + s1);
        let var = var.max(mid * (1.0 - mid) / 4.0);
        n * (s1 - s0) * (2.0 * mean - s0 - s1) / (2.0 * var)
    };
    assert!((p.row.llr - llr).abs() < 1e-9, "{p:?} vs {llr}");
    let (lo, hi) = (p.bounds.lower, p.bounds.upper);
    match p.row.status {
        SprtStatus::AcceptedH1 => assert!(llr >= hi),
        SprtStatus::AcceptedH0 => assert!(llr <= lo),
        SprtStatus::Inconclusive => assert!(llr > lo && llr < hi && matches.len() == 6),
        other => panic!("SPRT ended {other:?}: {p:?}"),
    }
    // An ended SPRT cannot be cancelled; a running one can, and its queued match with it.
    let (code, _) = delete(a, &format!("/api/v1/sprt/{pid}"), Some(TOKEN));
    assert_eq!(code, 409);
    let long = NewSprt {
        rallies_per_match: 400,
        seed: Some(1),
        ..NewSprt::new(2.into(), 3.into())
    };
    let p2: SprtView = post_as(a, "/api/v1/sprt", &long, Some(TOKEN), 202);
    let pid2 = p2.row.id;
    // A submitter cannot cancel what it did not queue; the admin can cancel anything.
    let (code, e) = delete(a, &format!("/api/v1/sprt/{pid2}"), Some(&token));
    assert_eq!(
        (code, e["error"]["code"].as_str()),
        (403, Some("not_owner")),
        "{e}"
    );
    let (code, e) = delete(a, &format!("/api/v1/tournaments/{tid}"), Some(&other));
    assert_eq!(code, 403, "{e}");
    let (code, e) = delete(a, &format!("/api/v1/tournaments/{tid}"), Some(&token));
    assert_eq!(
        (code, e["error"]["code"].as_str()),
        (409, Some("not_cancellable")),
        "{e}"
    );
    let (code, c) = delete(a, &format!("/api/v1/sprt/{pid2}"), Some(TOKEN));
    assert_eq!(code, 200, "{c}");
    let c: SprtView = serde_json::from_value(c).unwrap();
    assert_eq!(c.row.status, SprtStatus::Cancelled, "{c:?}");
    assert!(
        c.matches
            .iter()
            .all(|m| m.m.status == MatchStatus::Cancelled),
        "{c:?}"
    );
}

#[test]
fn batch_submits_a_plan_follows_it_and_writes_csv() {
    let dir = tempdir("batch");
    let srv = start(&dir, false);
    let url = format!("http://{}", srv.addr);
    let rally = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_rally"))
            .arg("batch")
            .args(args)
            .env_remove("RALLY_TOKEN")
            .output()
            .unwrap()
    };
    // A plan naming an agent the server does not have submits nothing and exits 2.
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "[[match]]\na = \"scripted\"\nb = \"ghost\"\n").unwrap();
    let out = rally(&[bad.to_str().unwrap(), "--server", &url, "--token", TOKEN]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no agent named 'ghost'"));
    let list: MatchList = get_as(&srv.addr, "/api/v1/matches");
    assert!(list.matches.is_empty());

    let plan = dir.join("plan.toml");
    std::fs::write(
        &plan,
        "rallies = 3\nseed = 5\n[[match]]\na = \"scripted\"\nb = 2\nrepeat = 2\n\
         [[tournament]]\nkind = \"gauntlet\"\nagents = [\"scripted-soft\", \"scripted\", \"scripted-drive\"]\nrallies_per_match = 2\n\
         [[sprt]]\na = \"scripted\"\nb = \"scripted-soft\"\nrallies_per_match = 2\nmax_matches = 3\nseed = 50\n",
    )
    .unwrap();
    let csv = dir.join("out.csv");
    let out = rally(&[
        plan.to_str().unwrap(),
        "--server",
        &url,
        "--token",
        TOKEN,
        "--csv",
        csv.to_str().unwrap(),
        "--poll",
        "0.2",
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("won %") && stdout.contains("tournament 1"),
        "{stdout}"
    );
    let text = std::fs::read_to_string(&csv).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let sprt: SprtView = get_as(&srv.addr, "/api/v1/sprt/1");
    let sprt_matches = sprt.matches.len();
    assert!(
        sprt.row.status != SprtStatus::Running && (2..=3).contains(&sprt_matches),
        "{sprt:?}"
    );
    assert!(
        stdout.contains("sprt 1: scripted vs scripted-soft"),
        "{stdout}"
    );
    assert_eq!(
        lines.len(),
        1 + 2 + 2 + sprt_matches,
        "header, two matches, a gauntlet of two, the SPRT's: {text}"
    );
    let header: Vec<&str> = lines[0].split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    for line in &lines[1..] {
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(f[col("status")], "done", "{line}");
        let m: MatchDetail = get_as(
            &srv.addr,
            &format!("/api/v1/matches/{}", f[col("match_id")]),
        );
        assert_eq!(
            f[col("points_a")],
            m.row.points_a.unwrap().to_string(),
            "{line} vs {m:?}"
        );
        assert_eq!(f[col("seed")], m.row.seed.to_string());
    }
    // The repeat swapped sides and took the next seed.
    let second: Vec<&str> = lines[2].split(',').collect();
    assert_eq!(
        (
            second[col("agent_a")],
            second[col("agent_b")],
            second[col("seed")]
        ),
        ("scripted-drive", "scripted", "6")
    );
    assert_eq!(lines[3].split(',').nth(col("tournament_id")), Some("1"));
}

#[test]
fn a_builtin_checkpoint_that_does_not_load_is_skipped_not_fatal() {
    let dir = tempdir("builtins");
    let ck = dir.join("checkpoints");
    std::fs::create_dir_all(&ck).unwrap();
    std::fs::copy("config/checkpoints/kmac.json", ck.join("house-kmac.json")).unwrap();
    std::fs::write(
        ck.join("broken.json"),
        "{\"format\": \"muscle-rally-checkpoint\"",
    )
    .unwrap();
    std::fs::write(ck.join("bad name!.json"), "{}").unwrap();
    let extra = format!("builtin_checkpoints = \"{}\"\n", ck.display());
    let names = |srv: &Server| -> Vec<String> {
        let (_, agents) = call(&srv.addr, "GET", "/api/v1/agents", None, None);
        agents["agents"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x["name"].as_str().unwrap().to_string())
            .collect()
    };
    let srv = start_with(&dir, false, &extra);
    let first = names(&srv);
    assert!(first.iter().any(|n| n == "house-kmac"), "{first:?}");
    assert!(
        !first.iter().any(|n| n == "broken" || n == "bad name!"),
        "{first:?}"
    );
    drop(srv);
    // A restart registers nothing twice.
    let srv = start_with(&dir, false, &extra);
    assert_eq!(names(&srv), first);
}

#[test]
fn the_event_stream_tells_a_match_queued_running_and_done() {
    let dir = tempdir("events");
    let srv = start_with(&dir, false, "builtin_checkpoints = \"\"\n");
    let a = srv.addr.as_str();
    // Subscribe first, then queue a match.
    let (mut reader, head) = subscribe(a, "/api/v1/events");
    assert!(
        head.to_ascii_lowercase().contains("text/event-stream"),
        "{head}"
    );
    let q = QueueMatch {
        a: "scripted".into(),
        b: "scripted-soft".into(),
        rallies: 2,
        seed: Some(3),
    };
    let m: db::Match = post_as(a, "/api/v1/matches", &q, Some(TOKEN), 202);
    let id = m.id;
    let mut seen = Vec::new();
    let started = Instant::now();
    while !seen.contains(&"done".to_string()) {
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "events so far: {seen:?}"
        );
        let mut line = String::new();
        reader.read_line(&mut line).unwrap();
        // Chunked framing lines and keep-alives are skipped; data lines carry the JSON.
        if let Some(data) = line.trim().strip_prefix("data:") {
            let e: server::ServerEvent = serde_json::from_str(data.trim()).unwrap();
            if e.kind == server::EventKind::Match && e.id == id {
                seen.push(e.status.unwrap().to_string());
            }
        }
    }
    // A worker may claim the match before the queueing request has published it: the order of
    // "queued" and "running" is not promised, "done" comes last.
    let mut sorted = seen.clone();
    sorted.sort();
    assert_eq!(sorted, ["done", "queued", "running"], "{seen:?}");
    assert_eq!(seen.last().unwrap(), "done");
    // And the match is stored as done when the event says so.
    let got: MatchDetail = get_as(a, &format!("/api/v1/matches/{id}"));
    assert_eq!(got.row.status, db::MatchStatus::Done);
}

#[test]
fn a_running_match_can_be_watched_live_as_it_is_played() {
    let dir = tempdir("live");
    let srv = start_with(&dir, false, "builtin_checkpoints = \"\"\n");
    let a = srv.addr.as_str();
    // A long match, so that it is still running when we subscribe.
    let (code, m) = call(
        a,
        "POST",
        "/api/v1/matches",
        Some(&json!({"a": "scripted", "b": "scripted-drive", "rallies": 120, "seed": 5})),
        Some(TOKEN),
    );
    assert_eq!(code, 202, "{m}");
    let id = m["id"].as_i64().unwrap();
    wait_for(a, id, "running", Duration::from_secs(30));
    let (mut reader, _) = subscribe(a, &format!("/api/v1/matches/{id}/live"));
    // Rallies arrive as they are played: their frames (with body poses) a few at a time, in order,
    // then their record. Two whole rallies, seen from their first frame, are enough.
    let mut rallies = Vec::new();
    let mut got: std::collections::HashMap<i64, usize> = Default::default();
    let mut event = String::new();
    let started = Instant::now();
    while rallies.len() < 2 {
        assert!(started.elapsed() < Duration::from_secs(60));
        let mut line = String::new();
        reader.read_line(&mut line).unwrap();
        if let Some(name) = line.trim().strip_prefix("event:") {
            event = name.trim().to_string();
        } else if let Some(data) = line.trim().strip_prefix("data:") {
            let r: Value = serde_json::from_str(data.trim()).unwrap();
            assert_eq!(r["match"], id);
            let k = r["rally"].as_i64().unwrap();
            match event.as_str() {
                "frames" => {
                    let frames = r["frames"].as_array().unwrap();
                    assert!(
                        !frames.is_empty() && frames.len() <= server::LIVE_CHUNK,
                        "{} frames",
                        frames.len()
                    );
                    assert!(frames[0]["bodies_a"].is_array());
                    let first = r["first"].as_u64().unwrap() as usize;
                    // Frames of a rally seen from its start come in order, none missing.
                    let seen = got
                        .entry(k)
                        .or_insert(if first == 0 { 0 } else { usize::MAX });
                    if *seen != usize::MAX {
                        assert_eq!(first, *seen, "rally {k}: frames in order");
                        *seen += frames.len();
                    }
                }
                "rally" => {
                    assert!(r["record"]["length"].is_number(), "{r}");
                    if got.get(&k).is_some_and(|&n| n != usize::MAX && n > 10) {
                        rallies.push(k);
                    }
                }
                other => panic!("unexpected event {other}: {r}"),
            }
        }
    }
    assert!(rallies[1] > rallies[0], "{rallies:?}");
    // Cancelling ends the match; its feed ends for the viewer; a finished match has no live feed.
    let (code, _) = call(
        a,
        "DELETE",
        &format!("/api/v1/matches/{id}"),
        None,
        Some(TOKEN),
    );
    assert_eq!(code, 200);
    wait_for(a, id, "cancelled", Duration::from_secs(60));
    let mut ended = false;
    let started = Instant::now();
    while !ended && started.elapsed() < Duration::from_secs(90) {
        let mut line = String::new();
        if reader.read_line(&mut line).unwrap_or(0) == 0 {
            break;
        }
        ended = line.trim() == "event: end" || line.trim() == "event:end";
    }
    assert!(ended, "the feed says the match ended");
    let (code, e) = call(a, "GET", &format!("/api/v1/matches/{id}/live"), None, None);
    assert_eq!(
        (code, e["error"]["code"].as_str()),
        (409, Some("not_running")),
        "{e}"
    );
}

/// Everything the store of `dir` holds, as bytes to search: the SQLite file and its WAL, or on
/// PostgreSQL every row of every table as text.
fn stored_bytes(dir: &std::path::Path) -> Vec<Vec<u8>> {
    if postgres_admin().is_none() {
        return ["rally.db", "rally.db-wal"]
            .iter()
            .map(|f| std::fs::read(dir.join(f)).unwrap_or_default())
            .collect();
    }
    let location: server::db::Location = db(dir).parse().unwrap();
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap()
        .block_on(async {
            let pool = server::db::open(&location).await.unwrap();
            let tables: Vec<String> = sqlx::query_scalar(
                "SELECT table_name::text FROM information_schema.tables WHERE table_schema = 'public'",
            )
            .fetch_all(&pool)
            .await
            .unwrap();
            let mut out = Vec::new();
            for t in tables {
                let rows: Vec<String> =
                    sqlx::query_scalar(&format!("SELECT CAST(t.* AS TEXT) FROM {t} t"))
                        .fetch_all(&pool)
                        .await
                        .unwrap();
                out.extend(rows.into_iter().map(String::into_bytes));
            }
            pool.close().await;
            out
        })
}
