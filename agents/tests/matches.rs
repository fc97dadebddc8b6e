//! The match runner: deterministic to the byte, points that follow the failures, crossings and replay
//! frames recorded, and a player that produces NaN loses its rally with INVALID_ACTION.

use std::sync::Arc;

use agents::factory::PlayerSpec;
use agents::matchrun::{play_match, play_match_with, MatchEvent, MatchSpec, REPLAY_HZ};
use agents::player::{InvalidAction, Player};
use sim::ball::BallState;
use sim::robot::Robot;

fn spec(rallies: u32, seed: u64, replay: bool) -> MatchSpec {
    MatchSpec {
        model: Arc::new(sim::config::default_model()),
        config: sim::config::ArenaConfig::default(),
        preset: sim::arena::MYOCHALLENGE,
        rallies,
        seed,
        replay,
    }
}

#[test]
fn matches_repeat_to_the_byte_and_score_the_failures() {
    let (a, b) = (
        PlayerSpec::scripted("scripted").unwrap(),
        PlayerSpec::scripted("scripted-soft").unwrap(),
    );
    let (r1, p1) = play_match(&spec(6, 3, true), &a, &b, &mut |_| {}).unwrap();
    let (r2, p2) = play_match(&spec(6, 3, true), &a, &b, &mut |_| {}).unwrap();
    assert_eq!(
        serde_json::to_string(&r1).unwrap(),
        serde_json::to_string(&r2).unwrap()
    );
    assert_eq!(
        serde_json::to_string(&p1).unwrap(),
        serde_json::to_string(&p2).unwrap()
    );
    let (r3, _) = play_match(&spec(6, 4, false), &a, &b, &mut |_| {}).unwrap();
    assert_ne!(
        serde_json::to_string(&r1.rallies).unwrap(),
        serde_json::to_string(&r3.rallies).unwrap()
    );

    let mut points = [0, 0];
    for (k, r) in r1.rallies.iter().enumerate() {
        assert_eq!(r.server, if k % 2 == 0 { "a" } else { "b" });
        match r.failing_side {
            Some("a") => points[1] += 1,
            Some("b") => points[0] += 1,
            _ => {}
        }
        // Every rally has at least the serve's crossing, and exchange indices never skip.
        assert_eq!(r.crossings.first().map(|c| c.exchange), Some(0));
        // Replay at 50 Hz: about duration × 50 frames, each with both robots' joint positions.
        let frames = &p1[k];
        let expected = (r.duration * REPLAY_HZ as f64).round() as usize;
        assert!(
            frames.len() >= expected && frames.len() <= expected + 2,
            "{} frames for {} s",
            frames.len(),
            r.duration
        );
        assert_eq!(frames[0].qpos_a.len(), 25);
        assert_eq!(frames[0].qpos_b.len(), 25);
    }
    assert_eq!(points, r1.points);
    assert!(r1.drift.crossings >= 6);
}

/// A player whose policy blew up.
struct Nan;

impl Player for Nan {
    fn reset(&mut self) {}
    fn reseed(&mut self, _: u64) {}
    fn act(
        &mut self,
        _: &Robot,
        _: &BallState,
        _: f64,
        ctrl: &mut [f64],
    ) -> Result<(), InvalidAction> {
        ctrl.iter_mut().for_each(|c| *c = f64::NAN);
        Ok(())
    }
}

#[test]
fn a_live_listener_hears_every_replay_frame_as_it_is_recorded_then_the_rally() {
    // The server's live feed sends frames while a rally is played: they must be the replay's
    // frames, in order, each rally's before its end.
    let (a, b) = (
        PlayerSpec::scripted("scripted").unwrap(),
        PlayerSpec::scripted("scripted-drive").unwrap(),
    );
    let s = spec(3, 5, true);
    let build = |p: &PlayerSpec| p.build(&s.model, &s.preset, 0).unwrap();
    let mut heard: Vec<Vec<String>> = vec![Vec::new()];
    let mut ends = Vec::new();
    let (record, replay) =
        play_match_with(&s, [build(&a), build(&b)], [a.name(), b.name()], &mut |e| {
            match e {
                MatchEvent::Frame { rally, frame } => {
                    assert_eq!(
                        rally as usize,
                        heard.len() - 1,
                        "frames of the rally being played"
                    );
                    heard
                        .last_mut()
                        .unwrap()
                        .push(serde_json::to_string(frame).unwrap());
                }
                MatchEvent::Rally {
                    rally,
                    record,
                    frames,
                } => {
                    let got = heard.last().unwrap();
                    assert_eq!(
                        got.len(),
                        frames.len(),
                        "rally {rally}: every frame heard before its end"
                    );
                    ends.push((rally, record.length));
                    heard.push(Vec::new());
                }
            }
            std::ops::ControlFlow::Continue(())
        })
        .unwrap();
    heard.pop();
    let stored: Vec<Vec<String>> = replay
        .iter()
        .map(|r| {
            r.iter()
                .map(|f| serde_json::to_string(f).unwrap())
                .collect()
        })
        .collect();
    assert_eq!(heard, stored);
    assert!(stored.iter().all(|r| r.len() > 10));
    assert_eq!(
        ends,
        record
            .rallies
            .iter()
            .map(|r| (r.index, r.length))
            .collect::<Vec<_>>()
    );
}

#[test]
fn a_player_producing_nan_loses_with_invalid_action_and_nothing_crashes() {
    let s = spec(2, 1, false);
    let good = PlayerSpec::scripted("scripted")
        .unwrap()
        .build(&s.model, &s.preset, 0)
        .unwrap();
    let (r, _) = play_match_with(
        &s,
        [good, Box::new(Nan)],
        ["scripted".into(), "nan".into()],
        &mut |_| std::ops::ControlFlow::Continue(()),
    )
    .unwrap();
    for rally in &r.rallies {
        assert_eq!(
            (rally.end, rally.failing_side),
            ("INVALID_ACTION", Some("b"))
        );
    }
    assert_eq!(r.points, [2, 0]);
}

#[test]
fn any_rally_replays_alone_bit_for_bit() {
    // Rallies are independent (each from the ready pose, with its own seeds), so the server can
    // re-simulate one rally of a match that kept no replay frames.
    let (a, b) = (
        PlayerSpec::scripted("scripted-drive").unwrap(),
        PlayerSpec::scripted("scripted").unwrap(),
    );
    let s = spec(5, 11, true);
    let (record, replay) = play_match(&s, &a, &b, &mut |_| {}).unwrap();
    // Without frames in the match itself, too: the re-simulation turns them on.
    let quiet = spec(5, 11, false);
    for k in [4u32, 1, 3] {
        let (r, frames) = agents::matchrun::replay_rally(&quiet, &a, &b, k).unwrap();
        assert_eq!(r, record.rallies[k as usize], "rally {k}'s record");
        assert_eq!(frames, replay[k as usize], "rally {k}'s frames");
        assert!(!frames.is_empty());
    }
    assert!(agents::matchrun::replay_rally(&quiet, &a, &b, 5).is_err());
}

#[test]
fn rallies_played_in_parallel_are_the_match_rallies() {
    // Training's validation plays a match's rallies on every core; each must be that match's rally.
    let (a, b) = (
        PlayerSpec::scripted("scripted").unwrap(),
        PlayerSpec::scripted("scripted-drive").unwrap(),
    );
    let s = spec(5, 11, false);
    let (whole, _) = play_match(&s, &a, &b, &mut |_| {}).unwrap();
    for threads in [1, 3] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let parallel = pool
            .install(|| agents::matchrun::play_rallies(&s, &a, &b))
            .unwrap();
        assert_eq!(
            serde_json::to_string(&parallel).unwrap(),
            serde_json::to_string(&whole.rallies).unwrap(),
            "{threads} threads"
        );
    }
}

#[test]
fn recorded_returns_are_the_legal_returns_struck_towards_a() {
    let s = spec(24, 11, false);
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../config/checkpoints/kmac-rally.json"
    ))
    .unwrap();
    let ck = agents::checkpoint::Checkpoint::from_json(&text, &s.model).unwrap();
    let p = PlayerSpec::Checkpoint(Arc::new(ck));
    let lengths: u32 = agents::matchrun::play_rallies(&s, &p, &p)
        .unwrap()
        .iter()
        .map(|r| r.length)
        .sum();
    let balls = agents::matchrun::record_returns(&s, &p, &p).unwrap();
    assert!(lengths >= 10, "too few returns to test: {lengths}");
    assert_eq!(balls.len() as u32, lengths, "one ball per legal return");
    for b in &balls {
        // Struck by B: on B's half or just over the net, flying towards A, above the table.
        assert!(b.pos.x < 0.5 && b.vel.x > 0.0 && b.pos.z > 0.76, "{b:?}");
    }
    let again = agents::matchrun::record_returns(&s, &p, &p).unwrap();
    assert_eq!(balls, again, "the same match records the same balls");
    let bank = agents::env::BallBank::parse(
        &agents::env::BallBank::to_json(&balls, serde_json::Value::Null).to_string(),
    )
    .unwrap();
    assert_eq!(bank, balls, "the bank file keeps every bit");
}

#[test]
fn a_break_stops_the_match_at_the_end_of_the_rally() {
    let a = PlayerSpec::scripted("scripted").unwrap();
    let s = spec(5, 7, false);
    let build = |p: &PlayerSpec| p.build(&s.model, &s.preset, 0).unwrap();
    let mut ended = Vec::new();
    let stopped = play_match_with(
        &s,
        [build(&a), build(&a)],
        [a.name(), a.name()],
        &mut |e| match e {
            MatchEvent::Rally { rally, .. } => {
                ended.push(rally);
                if rally == 1 {
                    std::ops::ControlFlow::Break(())
                } else {
                    std::ops::ControlFlow::Continue(())
                }
            }
            MatchEvent::Frame { .. } => std::ops::ControlFlow::Continue(()),
        },
    )
    .unwrap_err();
    assert_eq!(ended, [0, 1]);
    assert_eq!(stopped, "stopped after 2 of 5 rallies");
}
