//! A match's life on the real server: submitted, qualified, queued, played (watched live, told on
//! the event stream), stored and replayed; continuous mode; kill -9 and SIGTERM in the middle.

use super::*;

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

#[test]
fn sigterm_past_its_deadline_queues_a_long_match_again() {
    let dir = tempdir("sigterm_deadline");
    let mut srv = start_serve(&dir, 1, false, "shutdown_deadline_s = 1.0\n");
    let q = QueueMatch {
        a: "kmac-rally".into(),
        b: "kmac-rally".into(),
        rallies: 1000,
        seed: Some(5),
    };
    let m: db::Match = post_as(&srv.addr, "/api/v1/matches", &q, Some(TOKEN), 202);
    wait_for(&srv.addr, m.id, "running", Duration::from_secs(30));
    let asked = Instant::now();
    let status = terminate(&mut srv);
    let took = asked.elapsed();
    eprintln!("exited {took:?} after SIGTERM");
    assert!(status.success(), "exit status {status:?}");
    // The deadline (1 s) and the rally being played, not the minutes the match would take.
    assert!(took < Duration::from_secs(15), "{took:?}");
    drop(srv);
    // Queued again, nothing of it stored; played from its start by the next worker.
    let srv = start_serve(&dir, 0, false, "");
    let again: MatchDetail = get_as(&srv.addr, &format!("/api/v1/matches/{}", m.id));
    assert_eq!(again.row.status, MatchStatus::Queued, "{again:?}");
    assert!(again.rally_log.is_empty(), "{again:?}");
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
