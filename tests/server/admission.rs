//! What becomes an agent and what the leaderboard shows: qualification thresholds, the admission
//! budgets, retirement, built-ins that do not load, and every leaderboard row against its agent page.

use super::*;

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

/// A checkpoint of the template's shape whose network is `onnx`.
fn onnx_checkpoint(name: &str, onnx: &[u8]) -> Value {
    use base64::Engine;
    let mut ck = template(name);
    ck.as_object_mut().unwrap().remove("policy");
    ck["onnx"] = json!({"model_base64": base64::engine::general_purpose::STANDARD.encode(onnx)});
    ck
}

#[test]
fn uploads_past_the_admission_budgets_are_refused_and_the_server_keeps_answering() {
    let dir = tempdir("budget");
    let srv = start_with(
        &dir,
        false,
        "builtin_checkpoints = \"\"\nadmission_cpu_s = 2.0\nadmission_memory_mb = 512\nqualification_min_hit_rate = 0.3\n\
         admission_queue = 1\n\
         max_body_bytes = 8388608\n",
    );
    let a = srv.addr.as_str();
    let idle = healthz_idle(a);
    let rss_before = rss_kib(&srv);
    let fixtures: [(&str, &[u8], &str, &str); 3] = [
        // 2 000 chained matrix products a call: past its CPU time.
        (
            "slow",
            include_bytes!("../../agents/tests/fixtures/policy_slow.onnx"),
            "over_budget",
            "admission_cpu_s",
        ),
        // A 4 GB tensor from a computed shape: past its memory.
        (
            "computed-big",
            include_bytes!("../../agents/tests/fixtures/policy_computed_big.onnx"),
            "over_budget",
            "admission_memory_mb",
        ),
        // 13 actions for the zero observation, more for others: refused when read (its shapes
        // depend on its input).
        (
            "variable-width",
            include_bytes!("../../agents/tests/fixtures/policy_variable_width.onnx"),
            "invalid_checkpoint",
            "known only from the input's values",
        ),
    ];
    for (name, onnx, code_word, says) in fixtures {
        let body = json!({"name": name, "checkpoint": onnx_checkpoint(name, onnx)});
        let started = Instant::now();
        let ((code, v), worst) = while_probing(a, || {
            call(a, "POST", "/api/v1/agents", Some(&body), Some(TOKEN))
        });
        eprintln!(
            "{name}: {code} in {:?}; /healthz idle {idle:?}, at worst {worst:?} meanwhile",
            started.elapsed()
        );
        assert_eq!(
            (code, v["error"]["code"].as_str()),
            (422, Some(code_word)),
            "{v}"
        );
        let message = v["error"]["message"].as_str().unwrap();
        assert!(message.contains(says), "{name}: {message}");
        assert!(
            worst < responsive_bound(idle),
            "{name}: /healthz took {worst:?}"
        );
    }
    // One admission waits at most (admission_queue = 1): a second upload meanwhile is told to come
    // back later, and charged nothing.
    let slow = json!({"name": "slow2", "checkpoint": onnx_checkpoint("slow2", fixtures[0].1)});
    let first = {
        let (a, slow) = (a.to_string(), slow.clone());
        std::thread::spawn(move || call(&a, "POST", "/api/v1/agents", Some(&slow), Some(TOKEN)))
    };
    std::thread::sleep(Duration::from_millis(300));
    let (code, v) = call(a, "POST", "/api/v1/agents", Some(&slow), Some(TOKEN));
    assert_eq!(
        (code, v["error"]["code"].as_str()),
        (503, Some("busy")),
        "{v}"
    );
    assert_eq!(first.join().unwrap().0, 422);
    // The memory went to the admission's process, not the server's.
    let grew_mib = rss_kib(&srv).saturating_sub(rss_before) / 1024;
    assert!(grew_mib < 256, "the server grew by {grew_mib} MiB");
    let list: AgentList = get_as(a, "/api/v1/agents?all=1");
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
fn from_any_directory_the_store_is_the_data_directorys_and_the_builtins_play() {
    let dir = tempdir("data_dir");
    let (data, elsewhere) = (dir.join("data"), dir.join("elsewhere"));
    std::fs::create_dir_all(&elsewhere).unwrap();
    // The test configuration without its `db` line: the store goes where it goes by default.
    let config = write_config(&dir, 1, false, "");
    let text: String = std::fs::read_to_string(&config)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with("db ="))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(&config, text).unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_rally"))
        .current_dir(&elsewhere)
        .args(["serve", "--config"])
        .arg(&config)
        .env("RALLY_DATA_DIR", &data)
        .env("RUST_LOG", "warn")
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    std::io::BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let addr = line
        .trim()
        .trim_start_matches("listening on http://")
        .to_string();
    let srv = Server { child, addr };
    assert!(data.join("rally.db").exists(), "the store is DATA/rally.db");
    let left: Vec<_> = std::fs::read_dir(&elsewhere).unwrap().collect();
    assert!(
        left.is_empty(),
        "nothing written where it started: {left:?}"
    );
    let list: AgentList = get_as(&srv.addr, "/api/v1/agents");
    let names: Vec<&str> = list.agents.iter().map(|a| a.name.as_str()).collect();
    for builtin in [
        "scripted",
        "kmac",
        "kmac-rally",
        "muscle-ppo",
        "muscle-pd",
        "dynsyn",
    ] {
        assert!(names.contains(&builtin), "{builtin} missing from {names:?}");
    }
}
