//! Scale-out: `rally serve --workers 0` (the API alone) and `rally worker` processes on one store.
//! Workers are killed with -9 and stopped with SIGTERM in the middle of matches: every match is
//! played and stored exactly once, with the result `rally match` gives for the same seed.
//!
//! On SQLite (one file): 12 matches, two workers at a time (a third replaces the two). On
//! PostgreSQL (`RALLY_TEST_POSTGRES`, CI's second pass): 30 matches, three workers from the start.

use std::io::BufRead;
use std::process::Command;
use std::time::{Duration, Instant};

use serde_json::{json, Value};

mod common;
use common::*;

const RALLIES: i64 = 6;

/// The matches `name` holds the lease of, per `GET /workers`.
fn holding(addr: &str, name: &str) -> Vec<i64> {
    let (code, w) = call(addr, "GET", "/api/v1/workers", None, None);
    assert_eq!(code, 200, "{w}");
    w["workers"]
        .as_array()
        .unwrap()
        .iter()
        .find(|x| x["name"] == name)
        .map(|x| {
            x["matches_running"]
                .as_array()
                .unwrap()
                .iter()
                .map(|i| i.as_i64().unwrap())
                .collect()
        })
        .unwrap_or_default()
}

/// Waits until worker `name` holds a match and returns it.
fn wait_holding(addr: &str, name: &str) -> i64 {
    let t0 = Instant::now();
    loop {
        if let Some(&id) = holding(addr, name).first() {
            return id;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "{name} never held a match"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// `rally match` for the same agents and seed: (points, rally lengths).
fn played_alone(a: &str, b: &str, seed: i64) -> (Value, Vec<i64>) {
    let out = Command::new(env!("CARGO_BIN_EXE_rally"))
        .args(["match", a, b, "--json", "--rallies", &RALLIES.to_string()])
        .args(["--seed", &seed.to_string()])
        .output()
        .unwrap();
    assert!(out.status.success());
    let r: Value = serde_json::from_slice(&out.stdout).unwrap();
    let lengths = r["rallies"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x["length"].as_i64().unwrap())
        .collect();
    (r["points"].clone(), lengths)
}

#[test]
fn workers_killed_and_stopped_mid_match_lose_nothing_and_store_nothing_twice() {
    let postgres = postgres_admin().is_some();
    let matches: i64 = if postgres { 30 } else { 12 };
    let dir = tempdir("workers");
    let srv = start_serve(&dir, 0, false, "builtin_checkpoints = \"\"\n");
    let a = srv.addr.as_str();
    let pairs = [
        ("scripted", "scripted-drive"),
        ("scripted-soft", "scripted"),
    ];
    let mut ids = Vec::new();
    for k in 0..matches {
        let (x, y) = pairs[k as usize % 2];
        let (code, m) = call(
            a,
            "POST",
            "/api/v1/matches",
            Some(&json!({"a": x, "b": y, "rallies": RALLIES, "seed": 100 + k})),
            Some(TOKEN),
        );
        assert_eq!(code, 202, "{m}");
        ids.push(m["id"].as_i64().unwrap());
    }
    // The API alone plays nothing.
    std::thread::sleep(Duration::from_millis(1500));
    let (_, m) = call(a, "GET", &format!("/api/v1/matches/{}", ids[0]), None, None);
    assert_eq!(m["status"], "queued", "{m}");

    // The server tells its event stream what the other processes' workers did.
    let (mut events, _) = subscribe(a, "/api/v1/events");
    let mut w1 = start_worker(&dir, "w1");
    let mut w2 = start_worker(&dir, "w2");
    let w3 = postgres.then(|| start_worker(&dir, "w3"));
    // A second live process under a taken name is refused, and changes nothing.
    let dup = Command::new(env!("CARGO_BIN_EXE_rally"))
        .args(["worker", "--config"])
        .arg(dir.join("server.toml"))
        .args(["--name", "w1"])
        .output()
        .unwrap();
    assert!(!dup.status.success());
    assert!(
        String::from_utf8_lossy(&dup.stderr).contains("a worker named 'w1'"),
        "{}",
        String::from_utf8_lossy(&dup.stderr)
    );

    // kill -9 w1 in the middle of a match: its lease runs out and the match is played again.
    let killed = wait_holding(a, "w1");
    w1.child.kill().unwrap();
    w1.child.wait().unwrap();
    // SIGTERM w2 in the middle of a match: it finishes and stores it, then exits 0.
    let stopped = wait_holding(a, "w2");
    let status = terminate(&mut w2);
    assert!(status.success(), "exit status {status:?}");
    let (_, m) = call(a, "GET", &format!("/api/v1/matches/{stopped}"), None, None);
    assert_eq!(
        (m["status"].as_str(), m["worker"].as_str()),
        (Some("done"), Some("w2")),
        "{m}"
    );

    // The third worker plays the rest, the killed worker's match once its lease is gone.
    let _w3 = w3.unwrap_or_else(|| start_worker(&dir, "w3"));
    let mut done = Vec::new();
    for &id in &ids {
        done.push(wait_for(a, id, "done", Duration::from_secs(600)));
    }
    let (_, list) = call(a, "GET", "/api/v1/matches?limit=1000", None, None);
    assert_eq!(
        list["matches"].as_array().unwrap().len() as i64,
        matches,
        "no duplicate match"
    );
    for m in &done {
        let log = m["rally_log"].as_array().unwrap();
        let idx: Vec<i64> = log.iter().map(|r| r["idx"].as_i64().unwrap()).collect();
        assert_eq!(
            idx,
            (0..RALLIES).collect::<Vec<_>>(),
            "every rally once: {m}"
        );
    }
    let again = done.iter().find(|m| m["id"] == killed).unwrap();
    assert!(again["attempts"].as_i64().unwrap() >= 2, "{again}");
    assert_ne!(again["worker"], "w1", "{again}");

    let mut told: Vec<i64> = Vec::new();
    let t0 = Instant::now();
    while !ids.iter().all(|id| told.contains(id)) {
        assert!(
            t0.elapsed() < Duration::from_secs(30),
            "done events for {told:?} of {ids:?}"
        );
        let mut line = String::new();
        events.read_line(&mut line).unwrap();
        if let Some(data) = line.trim().strip_prefix("data:") {
            let e: Value = serde_json::from_str(data.trim()).unwrap();
            if e["kind"] == "match" && e["status"] == "done" {
                told.push(e["id"].as_i64().unwrap());
            }
        }
    }

    // Each store counted once, on the worker that made it.
    let (_, w) = call(a, "GET", "/api/v1/workers", None, None);
    let workers = w["workers"].as_array().unwrap();
    let played: i64 = workers
        .iter()
        .map(|x| x["matches_played"].as_i64().unwrap())
        .sum();
    assert_eq!(played, matches, "{w}");
    let get = |n: &str| workers.iter().find(|x| x["name"] == n).unwrap().clone();
    assert_eq!(get("w2")["status"], "stopped", "{w}");
    assert_eq!(get("w1")["alive"], false, "{w}");
    assert_eq!(get("w3")["alive"], true, "{w}");

    // The results are the ones `rally match` gives for the same agents and seed: the match played
    // twice, and the one finished under SIGTERM.
    for id in [killed, stopped] {
        let m = done.iter().find(|m| m["id"] == id).unwrap();
        let k = ids.iter().position(|&i| i == id).unwrap();
        let (x, y) = pairs[k % 2];
        let (points, lengths) = played_alone(x, y, m["seed"].as_i64().unwrap());
        assert_eq!(json!([m["points_a"], m["points_b"]]), points, "{m}");
        let stored: Vec<i64> = m["rally_log"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| r["length"].as_i64().unwrap())
            .collect();
        assert_eq!(stored, lengths, "{m}");
    }
}

/// A tournament and an SPRT, queued on `addr`; returns their ids.
fn queue_contests(addr: &str) -> (i64, i64) {
    let (code, t) = call(
        addr,
        "POST",
        "/api/v1/tournaments",
        Some(
            &json!({"kind": "round_robin", "agents": ["scripted", "scripted-drive", "scripted-soft"],
                     "rallies_per_match": 4, "rounds": 2, "seed": 70}),
        ),
        Some(TOKEN),
    );
    assert_eq!(code, 202, "{t}");
    let (code, p) = call(
        addr,
        "POST",
        "/api/v1/sprt",
        Some(
            &json!({"a": "scripted", "b": "scripted-soft", "rallies_per_match": 4,
                     "max_matches": 5, "elo1": 400, "seed": 90}),
        ),
        Some(TOKEN),
    );
    assert_eq!(code, 202, "{p}");
    (t["id"].as_i64().unwrap(), p["id"].as_i64().unwrap())
}

/// What a finished tournament and SPRT decided: the standings, every match's (seed, a, b, points),
/// and the SPRT's status, LLR, match count and matches.
fn contest_outcome(addr: &str, tid: i64, pid: i64) -> Value {
    let t = poll(
        addr,
        &format!("/api/v1/tournaments/{tid}"),
        Duration::from_secs(600),
        |v| v["progress"]["state"] == "finished",
    );
    let p = poll(
        addr,
        &format!("/api/v1/sprt/{pid}"),
        Duration::from_secs(600),
        |v| v["status"] != "running",
    );
    let games = |v: &Value| -> Vec<Value> {
        v["matches"]
            .as_array()
            .unwrap()
            .iter()
            .map(|m| {
                json!([
                    m["status"],
                    m["seed"],
                    m["agent_a"],
                    m["agent_b"],
                    m["points_a"],
                    m["points_b"]
                ])
            })
            .collect()
    };
    json!({
        "standings": t["standings"],
        "tournament": games(&t),
        "sprt": [p["status"], p["llr"], p["matches_done"]],
        "sprt_matches": games(&p),
    })
}

#[test]
fn tournaments_and_sprts_decide_the_same_with_two_worker_processes_as_with_one_worker() {
    // The reference: one server playing with its own single worker.
    let one = tempdir("contests-one");
    let srv = start_serve(&one, 1, false, "builtin_checkpoints = \"\"\n");
    let (tid, pid) = queue_contests(&srv.addr);
    let reference = contest_outcome(&srv.addr, tid, pid);
    assert_eq!(reference["tournament"].as_array().unwrap().len(), 6);
    assert!(reference["sprt"][2].as_i64().unwrap() >= 1, "{reference}");
    drop(srv);

    // The API alone and two worker processes on one store, one of them stopped half way.
    let dir = tempdir("contests-two");
    let srv = start_serve(&dir, 0, false, "builtin_checkpoints = \"\"\n");
    let a = srv.addr.as_str();
    let (tid, pid) = queue_contests(a);
    let w1 = start_worker(&dir, "w1");
    let mut w2 = start_worker(&dir, "w2");
    let _ = poll(
        a,
        &format!("/api/v1/tournaments/{tid}"),
        Duration::from_secs(600),
        |v| v["progress"]["done"].as_i64().unwrap_or(0) >= 3,
    );
    assert!(terminate(&mut w2).success());
    let outcome = contest_outcome(a, tid, pid);
    assert_eq!(outcome, reference);
    let (_, all) = call(a, "GET", "/api/v1/matches?limit=1000", None, None);
    let n = reference["tournament"].as_array().unwrap().len()
        + reference["sprt_matches"].as_array().unwrap().len();
    assert_eq!(
        all["matches"].as_array().unwrap().len(),
        n,
        "no stray match"
    );
    drop(w1);
}
