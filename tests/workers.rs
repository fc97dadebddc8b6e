//! Scale-out: `rally serve --workers 0` (the API alone) and `rally worker` processes on one store.
//! Workers are killed with -9 and stopped with SIGTERM in the middle of matches: every match is
//! played and stored exactly once, with the result `rally match` gives for the same seed.
//!
//! On SQLite (one file): 12 matches, two workers at a time (a third replaces the two). On
//! PostgreSQL (`RALLY_TEST_POSTGRES`, CI's second pass): 30 matches, three workers from the start.

use std::io::BufRead;
use std::process::Command;
use std::time::{Duration, Instant};

use serde_json::json;
use server::db::{MatchStatus, SprtStatus, WorkerStatus};
use server::tournament::ProgressState;
use server::wire::{
    MatchDetail, MatchList, NewSprt, NewTournament, QueueMatch, SprtView, TournamentView,
    WorkerList,
};

mod common;
use common::*;

const RALLIES: i64 = 6;

/// The matches `name` holds the lease of, per `GET /workers`.
fn holding(addr: &str, name: &str) -> Vec<i64> {
    let w: WorkerList = get_as(addr, "/api/v1/workers");
    w.workers
        .into_iter()
        .find(|x| x.row.name == name)
        .map(|x| x.matches_running)
        .unwrap_or_default()
}

/// A match as the API shows it.
fn detail(addr: &str, id: i64) -> MatchDetail {
    get_as(addr, &format!("/api/v1/matches/{id}"))
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
fn played_alone(a: &str, b: &str, seed: i64) -> ([i64; 2], Vec<i64>) {
    let out = Command::new(env!("CARGO_BIN_EXE_rally"))
        .args(["match", a, b, "--json", "--rallies", &RALLIES.to_string()])
        .args(["--seed", &seed.to_string()])
        .output()
        .unwrap();
    assert!(out.status.success());
    #[derive(serde::Deserialize)]
    struct Rally {
        length: i64,
    }
    #[derive(serde::Deserialize)]
    struct Played {
        points: [i64; 2],
        rallies: Vec<Rally>,
    }
    let r: Played = serde_json::from_slice(&out.stdout).unwrap();
    (r.points, r.rallies.iter().map(|x| x.length).collect())
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
        let q = QueueMatch {
            a: x.into(),
            b: y.into(),
            rallies: RALLIES as u32,
            seed: Some(100 + k as u64),
        };
        let m: server::db::Match = post_as(a, "/api/v1/matches", &q, Some(TOKEN), 202);
        ids.push(m.id);
    }
    // The API alone plays nothing.
    std::thread::sleep(Duration::from_millis(1500));
    assert_eq!(detail(a, ids[0]).row.status, MatchStatus::Queued);

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
    let m = detail(a, stopped).row;
    assert_eq!(
        (m.status, m.worker.as_deref()),
        (MatchStatus::Done, Some("w2")),
        "{m:?}"
    );

    // The third worker plays the rest, the killed worker's match once its lease is gone.
    let _w3 = w3.unwrap_or_else(|| start_worker(&dir, "w3"));
    let mut done: Vec<MatchDetail> = Vec::new();
    for &id in &ids {
        wait_for(a, id, "done", Duration::from_secs(600));
        done.push(detail(a, id));
    }
    let list: MatchList = get_as(a, "/api/v1/matches?limit=1000");
    assert_eq!(list.matches.len() as i64, matches, "no duplicate match");
    for m in &done {
        let idx: Vec<i64> = m.rally_log.iter().map(|r| r.idx).collect();
        assert_eq!(
            idx,
            (0..RALLIES).collect::<Vec<_>>(),
            "every rally once: {m:?}"
        );
    }
    let again = &done.iter().find(|m| m.row.id == killed).unwrap().row;
    assert!(again.attempts >= 2, "{again:?}");
    assert_ne!(again.worker.as_deref(), Some("w1"), "{again:?}");

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
            let e: server::ServerEvent = serde_json::from_str(data.trim()).unwrap();
            if e.kind == server::EventKind::Match && e.status == Some(MatchStatus::Done) {
                told.push(e.id);
            }
        }
    }

    // Each store counted once, on the worker that made it.
    let w: WorkerList = get_as(a, "/api/v1/workers");
    let played: i64 = w.workers.iter().map(|x| x.row.matches_played).sum();
    assert_eq!(played, matches, "{w:?}");
    let get = |n: &str| w.workers.iter().find(|x| x.row.name == n).unwrap();
    assert_eq!(get("w2").row.status, WorkerStatus::Stopped, "{w:?}");
    assert!(!get("w1").alive, "{w:?}");
    assert!(get("w3").alive, "{w:?}");

    // The results are the ones `rally match` gives for the same agents and seed: the match played
    // twice, and the one finished under SIGTERM.
    for id in [killed, stopped] {
        let m = done.iter().find(|m| m.row.id == id).unwrap();
        let k = ids.iter().position(|&i| i == id).unwrap();
        let (x, y) = pairs[k % 2];
        let (points, lengths) = played_alone(x, y, m.row.seed);
        assert_eq!([m.row.points_a.unwrap(), m.row.points_b.unwrap()], points);
        let stored: Vec<i64> = m.rally_log.iter().map(|r| r.length).collect();
        assert_eq!(stored, lengths, "{m:?}");
    }
}

/// A tournament and an SPRT, queued on `addr`; returns their ids.
fn queue_contests(addr: &str) -> (i64, i64) {
    let t = NewTournament {
        kind: server::wire::TournamentKind::RoundRobin,
        agents: vec![
            "scripted".into(),
            "scripted-drive".into(),
            "scripted-soft".into(),
        ],
        rallies_per_match: 4,
        rounds: 2,
        seed: Some(70),
    };
    let t: TournamentView = post_as(addr, "/api/v1/tournaments", &t, Some(TOKEN), 202);
    let p = NewSprt {
        rallies_per_match: 4,
        max_matches: 5,
        elo1: 400.0,
        seed: Some(90),
        ..NewSprt::new("scripted".into(), "scripted-soft".into())
    };
    let p: SprtView = post_as(addr, "/api/v1/sprt", &p, Some(TOKEN), 202);
    (t.summary.id, p.row.id)
}

/// What a finished tournament and SPRT decided: the standings, every match's (status, seed, sides,
/// points), and the SPRT's status, LLR, match count and matches.
fn contest_outcome(addr: &str, tid: i64, pid: i64) -> serde_json::Value {
    let t: TournamentView = poll_as(
        addr,
        &format!("/api/v1/tournaments/{tid}"),
        Duration::from_secs(600),
        |v: &TournamentView| v.summary.progress.state == ProgressState::Finished,
    );
    let p: SprtView = poll_as(
        addr,
        &format!("/api/v1/sprt/{pid}"),
        Duration::from_secs(600),
        |v: &SprtView| v.row.status != SprtStatus::Running,
    );
    let sprt_matches: Vec<_> = p.matches.iter().map(|m| &m.m).collect();
    json!({
        "standings": t.standings,
        "tournament": t.matches,
        "sprt": [p.row.status, p.row.llr, p.row.matches_done],
        "sprt_matches": sprt_matches,
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
