//! What a submitter token may spend: rallies per hour (an SPRT counting every match it may play),
//! replay storage (past it a match keeps no frames and still replays, re-simulated).

use super::*;

fn token(a: &str, name: &str) -> String {
    let t: IssuedToken = post_as(
        a,
        "/api/v1/tokens",
        &NewToken { name: name.into() },
        Some(TOKEN),
        201,
    );
    t.token
}

#[test]
fn a_token_asks_for_rallies_within_its_hourly_budget_an_sprt_counting_all_it_may_play() {
    let dir = tempdir("rally_budget");
    // No workers: what is queued stays queued; the budget is spent when asked for.
    let srv = start_serve(&dir, 0, false, "max_rallies_per_hour = 100\n");
    let a = srv.addr.as_str();
    let mine = token(a, "lab");
    let queue = |rallies: u32, who: &str| {
        let q = QueueMatch {
            a: "scripted".into(),
            b: "scripted".into(),
            rallies,
            seed: Some(1),
        };
        call(
            a,
            "POST",
            "/api/v1/matches",
            Some(&serde_json::to_value(q).unwrap()),
            Some(who),
        )
    };
    assert_eq!(queue(60, &mine).0, 202);
    // An SPRT of up to 10 matches of 10 rallies may play 100 more: over the 100 an hour.
    let sprt = NewSprt {
        rallies_per_match: 10,
        max_matches: 10,
        ..NewSprt::new("scripted".into(), "scripted-soft".into())
    };
    let sprt = serde_json::to_value(sprt).unwrap();
    let (code, v) = call(a, "POST", "/api/v1/sprt", Some(&sprt), Some(&mine));
    assert_eq!(
        (code, v["error"]["code"].as_str()),
        (429, Some("rate_limited")),
        "{v}"
    );
    let message = v["error"]["message"].as_str().unwrap();
    assert!(
        message.contains("asked for 60 rallies in the last hour (limit 100)"),
        "{message}"
    );
    // Refused whole: the SPRT queued nothing, its first match included.
    let list: MatchList = get_as(a, "/api/v1/matches");
    assert_eq!(list.matches.len(), 1, "{list:?}");
    // What is left can be spent, and no more; a tournament counts all its matches' rallies.
    assert_eq!(queue(40, &mine).0, 202);
    assert_eq!(queue(1, &mine).0, 429);
    let tour = NewTournament {
        kind: server::wire::TournamentKind::RoundRobin,
        agents: vec!["scripted".into(), "scripted-soft".into()],
        rallies_per_match: 1,
        rounds: 1,
        seed: Some(1),
    };
    let (code, _) = call(
        a,
        "POST",
        "/api/v1/tournaments",
        Some(&serde_json::to_value(tour).unwrap()),
        Some(&mine),
    );
    assert_eq!(code, 429);
    // Another token has its own budget; the admin has none.
    assert_eq!(queue(100, &token(a, "other")).0, 202);
    let (code, v) = call(a, "POST", "/api/v1/sprt", Some(&sprt), Some(TOKEN));
    assert_eq!(code, 202, "{v}");
}

#[test]
fn past_its_replay_quota_a_tokens_match_keeps_no_frames_and_replays_the_same() {
    let dir = tempdir("replay_quota");
    // A quota of 1 KiB: less than any rally's frames.
    let srv = start_serve(&dir, 1, false, "replay_quota_mb = 0.001\n");
    let a = srv.addr.as_str();
    let mine = token(a, "lab");
    let q = serde_json::to_value(QueueMatch {
        a: "scripted".into(),
        b: "scripted-soft".into(),
        rallies: 1,
        seed: Some(7),
    })
    .unwrap();
    let mut played = Vec::new();
    for who in [mine.as_str(), TOKEN] {
        let (code, m) = call(a, "POST", "/api/v1/matches", Some(&q), Some(who));
        assert_eq!(code, 202, "{m}");
        let id = m["id"].as_i64().unwrap();
        let done: MatchDetail =
            serde_json::from_value(wait_for(a, id, "done", Duration::from_secs(120))).unwrap();
        let (code, replay) = call(
            a,
            "GET",
            &format!("/api/v1/matches/{id}/replay?rally=0"),
            None,
            None,
        );
        assert_eq!(code, 200, "{replay}");
        played.push((done, replay));
    }
    let [(over, resimulated), (kept, stored)] = <[_; 2]>::try_from(played).unwrap();
    // The token's match kept nothing and counts nothing; the admin's (no quota) kept its frames.
    assert_eq!(
        (over.row.keep_replay, over.row.replay_bytes),
        (false, 0),
        "{over:?}"
    );
    assert!(
        kept.row.keep_replay && kept.row.replay_bytes > 1024,
        "{kept:?}"
    );
    // Both replay, the same frames: the one re-simulated, the other as stored.
    assert_eq!(resimulated["resimulated"], true);
    assert_eq!(stored["resimulated"], false);
    assert_eq!(resimulated["frames"], stored["frames"]);
}
