//! The server under load stays responsive: long matches finishing (their replays compressed and
//! stored), a flood of public reads of a big agent. Each measures `/healthz` against the same
//! server idle.

use super::*;

#[test]
fn long_matches_finishing_leave_the_server_responsive() {
    let dir = tempdir("long_matches");
    let srv = start_serve(&dir, 2, false, "");
    let a = srv.addr.as_str();
    let idle = healthz_idle(a);
    let q = serde_json::to_value(QueueMatch {
        a: "kmac-rally".into(),
        b: "kmac-rally".into(),
        rallies: 60,
        seed: Some(11),
    })
    .unwrap();
    let started = Instant::now();
    let (done, worst) = while_probing(a, || {
        let ids: Vec<i64> = (0..2)
            .map(|_| {
                let (code, m) = call(a, "POST", "/api/v1/matches", Some(&q), Some(TOKEN));
                assert_eq!(code, 202, "{m}");
                m["id"].as_i64().unwrap()
            })
            .collect();
        ids.iter()
            .map(|&id| wait_for(a, id, "done", Duration::from_secs(600)))
            .collect::<Vec<_>>()
    });
    let bytes: Vec<i64> = done
        .iter()
        .map(|m| m["replay_bytes"].as_i64().unwrap())
        .collect();
    eprintln!(
        "two 60-rally matches in {:?}, replays {bytes:?} bytes; /healthz idle {idle:?}, at worst {worst:?} meanwhile",
        started.elapsed()
    );
    assert!(bytes.iter().all(|&b| b > 0), "the frames were stored");
    assert!(worst < responsive_bound(idle), "/healthz took {worst:?}");
}

#[test]
fn a_flood_of_public_reads_of_a_big_agent_leaves_the_server_responsive_and_small() {
    let dir = tempdir("read_flood");
    let srv = start_serve(
        &dir,
        1,
        false,
        "builtin_checkpoints = \"\"\nmax_body_bytes = 8388608\n",
    );
    let a = srv.addr.as_str();
    // A checkpoint of 1.2 M weights (~5 MB) with the trained Diff-Muscle's provenance and the
    // longest learning curve a checkpoint may carry.
    let out = Command::new(env!("CARGO_BIN_EXE_rally"))
        .args([
            "checkpoint",
            "template",
            "--hidden",
            "1000,1000",
            "--name",
            "curvy",
        ])
        .output()
        .unwrap();
    let mut ck: Value = serde_json::from_slice(&out.stdout).unwrap();
    let kmac: Value =
        serde_json::from_str(agents::builtins::checkpoint("kmac").expect("built in")).unwrap();
    ck["training"] = kmac["training"].clone();
    let curve = ck["training"]["curve"].as_array().unwrap().clone();
    let points = agents::checkpoint::MAX_CURVE_POINTS;
    ck["training"]["curve"] = Value::Array(curve.iter().cycle().take(points).cloned().collect());
    let body = json!({"name": "curvy", "checkpoint": ck});
    let (code, v) = call(a, "POST", "/api/v1/agents", Some(&body), Some(TOKEN));
    assert_eq!(code, 201, "{v}");
    let path = format!("/api/v1/agents/{}", v["agent"]["id"]);
    let idle = healthz_idle(a);
    let rss_before = rss_kib(&srv);
    // Sixteen clients without a token read its page as fast as they can for 3 s.
    let (reads, worst) = while_probing(a, || {
        let until = Instant::now() + Duration::from_secs(3);
        let readers: Vec<_> = (0..16)
            .map(|_| {
                let (a, path) = (a.to_string(), path.clone());
                std::thread::spawn(move || {
                    let mut n = 0;
                    while Instant::now() < until {
                        let (code, body) = raw(&a, "GET", &path, &[], b"");
                        assert_eq!(code, 200);
                        let v: Value = serde_json::from_slice(&body).unwrap();
                        assert_eq!(v["training"]["curve"].as_array().unwrap().len(), points);
                        n += 1;
                    }
                    n
                })
            })
            .collect();
        readers
            .into_iter()
            .map(|r| r.join().unwrap())
            .sum::<usize>()
    });
    let grew_mib = rss_kib(&srv).saturating_sub(rss_before) / 1024;
    eprintln!(
        "{reads} reads in 3 s; /healthz idle {idle:?}, at worst {worst:?} meanwhile; the server grew by {grew_mib} MiB"
    );
    assert!(reads > 16, "{reads}");
    assert!(worst < responsive_bound(idle), "/healthz took {worst:?}");
    assert!(grew_mib < 128, "the server grew by {grew_mib} MiB");
}
