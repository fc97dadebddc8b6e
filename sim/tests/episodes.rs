//! The single-serve episode and the rally as state machines: with nobody swinging, every serve is a
//! MISS for the receiver; rally serves cross the receiver's plane in the serve box; the cap ends a
//! rally with no loser; a dropped paddle and an invalid action end it with the right failure.

use std::sync::Arc;

use sim::arena::{Side, MYOCHALLENGE};
use sim::config::ArenaConfig;
use sim::episode::{Rally, SingleServe};
use sim::rng::Rng;
use sim::rules::{EndReason, Failure};
use sim::serve::ServeKind;

fn model() -> Arc<sim::model::Model> {
    Arc::new(sim::config::default_model())
}

#[test]
fn an_unreturned_serve_is_a_miss_and_ends_the_episode_early() {
    let mut env = SingleServe::new(model(), &ArenaConfig::default(), MYOCHALLENGE).unwrap();
    let mut rng = Rng::seeded(4);
    for kind in [ServeKind::P1, ServeKind::P2] {
        env.reset(kind, &mut rng, None);
        let mut steps = 0;
        while !env.step().done {
            steps += 1;
        }
        let end = env.referee.end().expect("judged");
        // The robot may still graze the ball (its arm hangs into the path sometimes); it never returns it.
        assert!(!env.success);
        assert_eq!(end.failing_side, Some(Side::A), "{end:?}");
        assert!(
            steps < 300,
            "ends when the ball falls, not at the time limit"
        );
    }
}

#[test]
fn rally_serves_cross_in_the_box_and_unreturned_serves_end_the_rally() {
    let mut rally = Rally::new(model(), &ArenaConfig::default(), MYOCHALLENGE).unwrap();
    let mut rng = Rng::seeded(8);
    let mut in_box = 0;
    for i in 0..10 {
        let server = if i % 2 == 0 { Side::A } else { Side::B };
        rally.reset(server, &mut rng, None);
        while !rally.step().done {}
        let end = rally.referee.end().unwrap();
        assert_eq!(end.failing_side, Some(server.other()), "{end:?}");
        assert_eq!(rally.referee.rally_length(), 0);
        let c = rally
            .crossings
            .first()
            .expect("the serve crossed the receiver's plane");
        assert_eq!(
            (c.receiver, c.exchange, c.extrapolated),
            (server.other(), 0, false)
        );
        in_box += c.in_box as u32;
    }
    assert!(
        in_box >= 9,
        "only {in_box} of 10 rally serves crossed in the box"
    );
}

#[test]
fn caps_drops_and_invalid_actions() {
    let cfg = ArenaConfig::default();
    let mut rally = Rally::new(model(), &cfg, MYOCHALLENGE).unwrap();
    let mut rng = Rng::seeded(1);
    rally.reset(Side::A, &mut rng, None);
    rally.params.max_seconds = 0.05;
    while !rally.step().done {}
    assert_eq!(rally.referee.end().unwrap().reason, EndReason::Capped);
    assert_eq!(rally.referee.end().unwrap().failing_side, None);

    // B lets go of its paddle: it slips out and drops.
    rally.params = cfg.rally.clone();
    rally.reset(Side::A, &mut rng, None);
    let grip: Vec<usize> = rally.arena.robots[1].grip_muscles().to_vec();
    for a in grip {
        rally.arena.robots[1].state.ctrl[a] = 0.0;
        rally.arena.robots[1].state.act[a] = 0.0;
    }
    while !rally.step().done {}
    let end = rally.referee.end().unwrap();
    assert_eq!(
        (end.reason, end.failing_side),
        (EndReason::Failure(Failure::DroppedPaddle), Some(Side::B))
    );

    rally.reset(Side::B, &mut rng, None);
    rally.invalid_action(Side::A);
    let end = rally.referee.end().unwrap();
    assert_eq!(
        (end.reason, end.failing_side),
        (EndReason::Failure(Failure::InvalidAction), Some(Side::A))
    );
}
