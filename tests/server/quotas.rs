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
    let srv = start_serve(
        &dir,
        0,
        false,
        "max_rallies_per_hour = 100\nmax_matches_per_minute = 4\n",
    );
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
    // Refused whole: the SPRT queued nothing, its first match included, and booked none of the
    // token's 4 matches a minute (else the last request below would be over on matches, not on
    // rallies).
    let list: MatchList = get_as(a, "/api/v1/matches");
    assert_eq!(list.matches.len(), 1, "{list:?}");
    // What is left can be spent, and no more; a tournament counts all its matches' rallies.
    assert_eq!(queue(39, &mine).0, 202);
    assert_eq!(queue(1, &mine).0, 202);
    let (code, v) = queue(1, &mine);
    assert_eq!(code, 429, "{v}");
    assert!(
        v["error"]["message"].as_str().unwrap().contains("rallies"),
        "{v}"
    );
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
    // A request that no wait would let through is not a 429: an SPRT that may play 10 000 rallies.
    let huge = serde_json::to_value(NewSprt {
        rallies_per_match: 10,
        max_matches: 1000,
        ..NewSprt::new("scripted".into(), "scripted-soft".into())
    })
    .unwrap();
    let (code, v) = call(
        a,
        "POST",
        "/api/v1/sprt",
        Some(&huge),
        Some(&token(a, "big")),
    );
    assert_eq!(
        (code, v["error"]["code"].as_str()),
        (422, Some("over_limit")),
        "{v}"
    );
    assert!(
        v["error"]["message"]
            .as_str()
            .unwrap()
            .contains("max_rallies_per_hour"),
        "{v}"
    );
    // Another token has its own budget; the admin has none.
    assert_eq!(queue(100, &token(a, "other")).0, 202);
    let (code, v) = call(a, "POST", "/api/v1/sprt", Some(&sprt), Some(TOKEN));
    assert_eq!(code, 202, "{v}");
}

#[test]
fn a_tokens_matches_keep_their_frames_within_its_replay_quota_and_none_past_it() {
    let q = serde_json::to_value(QueueMatch {
        a: "scripted".into(),
        b: "scripted-soft".into(),
        rallies: 1,
        seed: Some(7),
    })
    .unwrap();
    // Plays the match for `who` on `a`; its row and its rally's replay.
    let play = |a: &str, who: &str| {
        let (code, m) = call(a, "POST", "/api/v1/matches", Some(&q), Some(who));
        assert_eq!(code, 202, "{m}");
        let id = m["id"].as_i64().unwrap();
        let done: MatchDetail =
            serde_json::from_value(wait_for(a, id, "done", Duration::from_secs(120))).unwrap();
        let path = format!("/api/v1/matches/{id}/replay?rally=0");
        let (code, replay) = call(a, "GET", &path, None, None);
        assert_eq!(code, 200, "{replay}");
        (done, replay)
    };
    // Within the default quota (1 GiB) a token's matches keep their frames, and count them.
    let dir = tempdir("replay_quota_within");
    let srv = start_serve(&dir, 1, false, "");
    let mine = token(&srv.addr, "lab");
    let (first, _) = play(&srv.addr, &mine);
    let (second, stored) = play(&srv.addr, &mine);
    for m in [&first, &second] {
        assert!(m.row.keep_replay && m.row.replay_bytes > 1024, "{m:?}");
    }
    assert_eq!(stored["resimulated"], false);
    drop(srv);
    // A quota of 1 KiB, less than any rally's frames: the token's match keeps none and counts
    // none; the admin's (no quota) keeps its frames. Both replay the same frames, the first
    // re-simulated.
    let dir = tempdir("replay_quota_past");
    let srv = start_serve(&dir, 1, false, "replay_quota_mb = 0.001\n");
    let mine = token(&srv.addr, "lab");
    let (over, resimulated) = play(&srv.addr, &mine);
    let (kept, stored) = play(&srv.addr, TOKEN);
    assert_eq!(
        (over.row.keep_replay, over.row.replay_bytes),
        (false, 0),
        "{over:?}"
    );
    assert!(
        kept.row.keep_replay && kept.row.replay_bytes > 1024,
        "{kept:?}"
    );
    assert_eq!(
        kept.row.replay_bytes, second.row.replay_bytes,
        "the same match, the same frames"
    );
    assert_eq!(resimulated["resimulated"], true);
    assert_eq!(stored["resimulated"], false);
    assert_eq!(resimulated["frames"], stored["frames"]);
}
