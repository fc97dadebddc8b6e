//! Cancelling what runs: a running match stops at the end of its rally and frees its worker.

use super::*;

#[test]
fn cancelling_a_running_match_frees_its_worker_at_the_next_rally() {
    let dir = tempdir("cancel_running");
    let srv = start(&dir, false);
    let a = &srv.addr;
    // One worker: a 1000-rally match (minutes of play) holds it, a short one waits behind it.
    let long = QueueMatch {
        a: 1.into(),
        b: 2.into(),
        rallies: 1000,
        seed: Some(3),
    };
    let m: db::Match = post_as(a, "/api/v1/matches", &long, Some(TOKEN), 202);
    wait_for(a, m.id, "running", Duration::from_secs(60));
    let short = QueueMatch {
        rallies: 2,
        ..long.clone()
    };
    let next: db::Match = post_as(a, "/api/v1/matches", &short, Some(TOKEN), 202);
    let cancelled = Instant::now();
    let path = format!("/api/v1/matches/{}", m.id);
    let (code, _) = call(a, "DELETE", &path, None, Some(TOKEN));
    assert_eq!(code, 200);
    wait_for(a, next.id, "done", Duration::from_secs(120));
    let took = cancelled.elapsed();
    assert!(
        took < Duration::from_secs(30),
        "the worker came free after {took:?}"
    );
    let gone: MatchDetail = get_as(a, &path);
    assert_eq!(gone.row.status, MatchStatus::Cancelled);
    assert!(
        gone.rally_log.is_empty(),
        "a cancelled match stores no rally"
    );
}
