//! Tournaments, SPRTs, rate limits, multipart uploads and `rally batch` against the real server.

use super::*;

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
fn tournaments_rate_limits_multipart_and_rating_history() {
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
        kind: wire::TournamentKind::RoundRobin,
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
        kind: wire::TournamentKind::Gauntlet,
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
    // Paged: the newest points, oldest first, and how many there are.
    let last: RatingHistory = get_as(a, "/api/v1/agents/1/ratings?limit=2");
    assert_eq!(last.total, history.len() as i64);
    assert_eq!(last.history[..], history[history.len() - 2..]);
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

    // A submitter cannot cancel what it did not queue; a finished tournament cannot be cancelled.
    let (code, e) = delete(a, &format!("/api/v1/tournaments/{tid}"), Some(&other));
    assert_eq!(code, 403, "{e}");
    let (code, e) = delete(a, &format!("/api/v1/tournaments/{tid}"), Some(&token));
    assert_eq!(
        (code, e["error"]["code"].as_str()),
        (409, Some("not_cancellable")),
        "{e}"
    );
}

#[test]
fn an_sprt_plays_one_match_at_a_time_until_it_decides_and_only_its_owner_cancels_it() {
    let dir = tempdir("sprt");
    let srv = start_with(&dir, false, "builtin_checkpoints = \"\"\n");
    let a = srv.addr.as_str();
    let lab = NewToken { name: "lab".into() };
    let t: IssuedToken = post_as(a, "/api/v1/tokens", &lab, Some(TOKEN), 201);
    let token = t.token;

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
