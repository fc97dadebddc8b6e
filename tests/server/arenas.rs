//! Robots of their own: a server plays the default robot, and MyoSuite's once it is imported under
//! its data directory. Agents meet only agents of their robot; leaderboards, bodies and replays are
//! per robot. The second test needs the imported robot: `RALLY_MYOCHALLENGE` names the file
//! `rally model import myosuite` wrote (`.ci/run` sets it in its MyoChallenge step); without it, it
//! says why it did not run.

use super::*;

/// `rally batch` of the plan `text` against the server at `addr`: its exit code and standard error.
fn batch(dir: &std::path::Path, addr: &str, text: &str) -> (Option<i32>, String) {
    let plan = dir.join("plan.toml");
    std::fs::write(&plan, text).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_rally"))
        .arg("batch")
        .arg(&plan)
        .args(["--server", &format!("http://{addr}"), "--token", TOKEN])
        .env_remove("RALLY_TOKEN")
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).to_string(),
    )
}

/// The error of an answer: its code and field.
fn fault(v: &Value) -> (String, String) {
    let e: ErrorBody = serde_json::from_value(v.clone()).unwrap_or_else(|e| panic!("{e}: {v}"));
    (e.error.code, e.error.field.unwrap_or_default())
}

#[test]
fn a_server_without_myosuites_robot_plays_the_default_one_and_says_how_to_import_the_other() {
    let dir = tempdir("one-robot");
    let srv = start_with(&dir, false, "builtin_checkpoints = \"\"\n");
    let a = srv.addr.as_str();
    let health: Health = get_as(a, "/api/v1/healthz");
    assert_eq!(health.models, ["default"]);
    let agents: AgentList = get_as(a, "/api/v1/agents");
    assert!(agents.agents.iter().all(|x| x.model == "default"));
    let board: Leaderboard = get_as(a, "/api/v1/leaderboard?model=default");
    assert_eq!(board.rows.len(), agents.agents.len());

    for path in [
        "/api/v1/leaderboard?model=myochallenge",
        "/api/v1/model?model=myochallenge",
        "/api/v1/arena?model=myochallenge",
        "/api/v1/agents?model=myochallenge",
        "/api/v1/matches?model=myochallenge",
    ] {
        let (code, v) = call(a, "GET", path, None, None);
        assert_eq!(code, 400, "{path}: {v}");
        assert_eq!(fault(&v).1, "model", "{path}");
        assert!(
            v.to_string().contains("rally model import myosuite"),
            "{path}: {v}"
        );
    }

    // A plan for a robot this server does not play submits nothing.
    let (code, err) = batch(
        &dir,
        a,
        "model = \"myochallenge\"\n[[match]]\na = \"scripted\"\nb = \"scripted\"\n",
    );
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("the server plays no robot 'myochallenge'"),
        "{err}"
    );
    let none: MatchList = get_as(a, "/api/v1/matches");
    assert!(none.matches.is_empty());

    // A checkpoint of a robot this server does not play: refused before its admission, nothing
    // stored, the field named.
    let mut other = template("other");
    other["model"] = json!("myochallenge");
    let (code, v) = call(
        a,
        "POST",
        "/api/v1/agents",
        Some(&json!({"name": "elsewhere", "checkpoint": other})),
        Some(TOKEN),
    );
    assert_eq!(code, 422, "{v}");
    assert_eq!(
        fault(&v),
        ("unknown_robot".to_string(), "checkpoint.model".to_string())
    );
    let after: AgentList = get_as(a, "/api/v1/agents");
    assert_eq!(after.agents.len(), agents.agents.len());
    // Another robot's built-ins' names are kept for it, imported or not.
    let (code, v) = call(
        a,
        "POST",
        "/api/v1/agents",
        Some(&json!({"name": "MyoChallenge-kmac", "checkpoint": template("squat")})),
        Some(TOKEN),
    );
    assert_eq!(code, 400, "{v}");
    assert_eq!(fault(&v).1, "name");
    // One naming the default robot, or none (a file from before robots had names), is its agent.
    let mut named = template("named");
    named["model"] = json!("default");
    let mut unnamed = template("unnamed");
    unnamed.as_object_mut().unwrap().remove("model");
    for (name, ck) in [("named", named), ("unnamed", unnamed)] {
        let s: Submitted = post_as(
            a,
            "/api/v1/agents",
            &SubmitAgent {
                name: name.into(),
                checkpoint: ck,
            },
            Some(TOKEN),
            201,
        );
        assert_eq!(s.agent.model, "default", "{name}");
    }
}

/// MyoSuite's robot as `rally model import myosuite` wrote it, if the tests were given it.
fn imported() -> Option<std::path::PathBuf> {
    let Some(path) = std::env::var_os("RALLY_MYOCHALLENGE") else {
        eprintln!(
            "not run: set RALLY_MYOCHALLENGE to the file `rally model import myosuite` wrote"
        );
        return None;
    };
    Some(path.into())
}

#[test]
fn myosuites_robot_has_its_own_agents_matches_leaderboard_and_body() {
    let Some(xml) = imported() else { return };
    let dir = tempdir("two-robots");
    std::fs::create_dir_all(dir.join("models")).unwrap();
    std::fs::copy(&xml, dir.join("models/myochallenge.xml")).unwrap();
    // The embedded built-ins: each robot's scripted agents and trained checkpoints.
    let srv = start_with(&dir, false, "max_body_bytes = 8388608\n");
    let a = srv.addr.as_str();
    let health: Health = get_as(a, "/api/v1/healthz");
    assert_eq!(health.models, ["default", "myochallenge"]);

    let all: AgentList = get_as(a, "/api/v1/agents");
    let mine: AgentList = get_as(a, "/api/v1/agents?model=myochallenge");
    let names: Vec<&str> = mine.agents.iter().map(|x| x.name.as_str()).collect();
    assert!(names.contains(&"myochallenge-scripted"), "{names:?}");
    assert!(names.contains(&"myochallenge-kmac"), "{names:?}");
    assert!(mine.agents.iter().all(|x| x.model == "myochallenge"));
    let defaults = all.agents.iter().filter(|x| x.model == "default").count();
    assert_eq!(defaults + mine.agents.len(), all.agents.len());
    assert!(defaults > 0);

    // Agents of two robots never meet: a match, an SPRT, a tournament that mixes them is refused
    // naming the field, and nothing is queued.
    let mixed = [
        (
            "/api/v1/matches",
            json!({"a": "scripted", "b": "myochallenge-scripted", "rallies": 1}),
            "b",
        ),
        (
            "/api/v1/sprt",
            json!({"a": "myochallenge-kmac", "b": "kmac"}),
            "b",
        ),
        (
            "/api/v1/tournaments",
            json!({"kind": "round_robin", "agents": ["myochallenge-scripted", "myochallenge-kmac", "scripted"], "rallies_per_match": 1}),
            "agents",
        ),
    ];
    for (path, body, field) in mixed {
        let (code, v) = call(a, "POST", path, Some(&body), Some(TOKEN));
        assert_eq!(code, 422, "{path}: {v}");
        assert_eq!(
            fault(&v),
            ("robot_mismatch".to_string(), field.to_string()),
            "{path}"
        );
    }
    // A plan naming another robot's agent submits nothing and says which robot that agent plays.
    let (code, err) = batch(
        &dir,
        a,
        "model = \"myochallenge\"\n[[match]]\na = \"myochallenge-scripted\"\nb = \"kmac\"\n",
    );
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("('kmac') plays the default robot, not this plan's myochallenge"),
        "{err}"
    );
    let none: MatchList = get_as(a, "/api/v1/matches");
    assert!(none.matches.is_empty());

    // A match of MyoSuite's robot plays on it; its replay draws its bodies.
    let m: server::wire::Match = post_as(
        a,
        "/api/v1/matches",
        &QueueMatch {
            a: "myochallenge-kmac".into(),
            b: "myochallenge-scripted".into(),
            rallies: 1,
            seed: Some(7),
        },
        Some(TOKEN),
        202,
    );
    assert_eq!(m.model, "myochallenge");
    let done = wait_for(a, m.id, "done", Duration::from_secs(600));
    assert_eq!(done["model"], "myochallenge");
    let body: Value = get_as(a, "/api/v1/model?model=myochallenge");
    assert_eq!(body["robot"], "myochallenge");
    assert_eq!(body["muscles"].as_array().unwrap().len(), 273);
    let arena: Value = get_as(a, "/api/v1/arena?model=myochallenge");
    assert_eq!(arena["model"], "myochallenge");
    let replay: Value = get_as(a, &format!("/api/v1/matches/{}/replay", m.id));
    assert_eq!(replay["model"], "myochallenge");
    let bodies = body["bodies"].as_array().unwrap().len();
    let frame = &replay["frames"][0];
    let poses = frame["bodies_a"].as_array().map_or(0, Vec::len);
    assert_eq!(
        poses, bodies,
        "a pose for each of MyoSuite's bodies: {frame}"
    );

    // Each robot's leaderboard has its own agents and matches.
    let theirs: Leaderboard = get_as(a, "/api/v1/leaderboard?model=myochallenge");
    let ours: Leaderboard = get_as(a, "/api/v1/leaderboard");
    assert_eq!(theirs.matches, 1);
    assert_eq!(
        theirs.anchor.as_ref().map(|x| x.agent.as_str()),
        Some("myochallenge-scripted"),
        "its scale is anchored on its own scripted agent"
    );
    assert_eq!(ours.matches, 0);
    let ids = |b: &Leaderboard| b.rows.iter().map(|r| r.agent_id).collect::<Vec<_>>();
    assert!(ids(&theirs)
        .iter()
        .all(|id| mine.agents.iter().any(|x| x.id == *id)));
    assert!(ids(&ours)
        .iter()
        .all(|id| !mine.agents.iter().any(|x| x.id == *id)));
    let listed: MatchList = get_as(a, "/api/v1/matches?model=default");
    assert!(listed.matches.is_empty());

    // A submission names its robot: MyoSuite's trained K-MAC under another name is its agent.
    let kmac: Value = serde_json::from_str(
        agents::builtins::checkpoint_of("myochallenge", "kmac").expect("built in"),
    )
    .unwrap();
    let s: Submitted = post_as(
        a,
        "/api/v1/agents",
        &SubmitAgent {
            name: "my-kmac".into(),
            checkpoint: kmac,
        },
        Some(TOKEN),
        201,
    );
    assert_eq!(s.agent.model, "myochallenge");

    // The robot's file gone from under the server: the admission cannot load it, which is the
    // server's failure (500), not the checkpoint's, and nothing is stored.
    std::fs::remove_file(dir.join("models/myochallenge.xml")).unwrap();
    let kmac: Value = serde_json::from_str(
        agents::builtins::checkpoint_of("myochallenge", "kmac").expect("built in"),
    )
    .unwrap();
    let (code, v) = call(
        a,
        "POST",
        "/api/v1/agents",
        Some(&json!({"name": "orphan", "checkpoint": kmac})),
        Some(TOKEN),
    );
    assert_eq!(code, 500, "{v}");
    let after: AgentList = get_as(a, "/api/v1/agents");
    assert!(after.agents.iter().all(|x| x.name != "orphan"));
}

#[test]
fn a_worker_plays_only_the_robots_it_has_imported() {
    let Some(xml) = imported() else { return };
    let dir = tempdir("robot-workers");
    std::fs::create_dir_all(dir.join("models")).unwrap();
    std::fs::copy(&xml, dir.join("models/myochallenge.xml")).unwrap();
    // The API alone (it has both robots), the scripted built-ins only.
    let srv = start_serve(&dir, 0, false, "builtin_checkpoints = \"\"\n");
    let a = srv.addr.as_str();
    let queue = |x: &str, y: &str| -> server::wire::Match {
        post_as(
            a,
            "/api/v1/matches",
            &QueueMatch {
                a: x.into(),
                b: y.into(),
                rallies: 1,
                seed: Some(3),
            },
            Some(TOKEN),
            202,
        )
    };
    // Theirs first: the oldest queued match, which a worker without the import must pass over.
    let theirs = queue("myochallenge-scripted", "myochallenge-scripted");
    let ours = queue("scripted", "scripted");
    let bare = dir.join("bare");
    std::fs::create_dir_all(&bare).unwrap();
    let _plain = start_worker_with_data(&dir, "plain", &bare);
    wait_for(a, ours.id, "done", Duration::from_secs(120));
    std::thread::sleep(Duration::from_secs(2));
    let still: Value = get_as(a, &format!("/api/v1/matches/{}", theirs.id));
    assert_eq!(still["status"], "queued", "{still}");
    let _full = start_worker(&dir, "full");
    let done = wait_for(a, theirs.id, "done", Duration::from_secs(300));
    assert_eq!(done["worker"], "full", "{done}");
}
