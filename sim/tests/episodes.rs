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

#[test]
fn p2_of_an_arena_with_p2_draws_draws_the_paddle_mass_and_ball_friction_after_the_ball() {
    let plain = ArenaConfig::default();
    assert_eq!(plain.p2, None, "the default robot's P2 draws the ball only");
    let drawn = ArenaConfig {
        p2: Some(sim::config::P2Draws {
            paddle_mass: [0.10, 0.15],
            ball_friction: [0.9, 1.1],
        }),
        ..plain.clone()
    };
    let mut a = SingleServe::new(model(), &plain, MYOCHALLENGE).unwrap();
    let mut b = SingleServe::new(model(), &drawn, MYOCHALLENGE).unwrap();
    let nominal = a.robot.paddle_mass();
    let mut masses = Vec::new();
    for seed in 0..20 {
        a.reset(ServeKind::P2, &mut Rng::seeded(seed), None);
        b.reset(ServeKind::P2, &mut Rng::seeded(seed), None);
        // The same ball (drawn first), then the draws.
        assert_eq!(a.serve.ball.pos, b.serve.ball.pos);
        assert_eq!((a.robot.paddle_mass(), a.ball_friction), (nominal, 1.0));
        let (m, f) = (b.robot.paddle_mass(), b.ball_friction);
        assert!(
            (0.10..=0.15).contains(&m) && (0.9..=1.1).contains(&f),
            "{m} {f}"
        );
        assert_eq!(
            b.robot
                .held_model()
                .bodies
                .iter()
                .filter(|x| x.mass == m)
                .count(),
            1
        );
        assert_eq!(b.world.preset, MYOCHALLENGE);
        masses.push(m);
        // The same seed, the same draws.
        let mut again = SingleServe::new(model(), &drawn, MYOCHALLENGE).unwrap();
        again.reset(ServeKind::P2, &mut Rng::seeded(seed), None);
        assert_eq!((again.robot.paddle_mass(), again.ball_friction), (m, f));
    }
    assert!(masses.iter().any(|&m| m < 0.125) && masses.iter().any(|&m| m > 0.125));
    // Other serves play the model's own paddle in the scene's friction.
    b.reset(ServeKind::P1, &mut Rng::seeded(3), None);
    assert_eq!((b.robot.paddle_mass(), b.ball_friction), (nominal, 1.0));
    // A heavier paddle weighs on the arm: the same relaxed episode moves it otherwise.
    let fall = |mass_seed: u64| {
        let mut e = SingleServe::new(model(), &drawn, MYOCHALLENGE).unwrap();
        e.reset(ServeKind::P2, &mut Rng::seeded(mass_seed), None);
        for _ in 0..20 {
            e.step();
        }
        (e.robot.paddle_mass(), e.robot.state.qpos.clone())
    };
    let (m1, q1) = fall(0);
    let (m2, q2) = fall(1);
    assert_ne!(m1, m2);
    assert_ne!(q1, q2);
}

#[test]
fn a_lead_in_flies_the_robots_own_return_away_then_brings_the_serve_from_its_start() {
    let cfg = ArenaConfig::default();
    let bounce = sim::predict::BounceModel::for_table(&MYOCHALLENGE.table);
    let mut env = SingleServe::new(model(), &cfg, MYOCHALLENGE).unwrap();
    let mut rng = Rng::seeded(12);
    for _ in 0..5 {
        env.reset(ServeKind::Stroke { server: Side::B }, &mut rng, None);
        let serve = env.serve;
        let away = sim::serve::generate(ServeKind::Stroke { server: Side::A }, &mut rng, &bounce);
        env.start_lead_in(away.ball, sim::episode::LEAD_IN_STEPS);
        assert!(env.in_lead_in());
        assert_eq!(env.world.ball.pos, away.ball.pos);
        // The lead-in: the ball flies towards B, nothing is judged, the robot goes on moving.
        let mut last_x = env.world.ball.pos.x;
        while env.in_lead_in() {
            let report = env.step();
            assert!(!report.done && report.calls.is_empty(), "{report:?}");
            assert!(env.steps <= sim::episode::LEAD_IN_STEPS);
            if env.in_lead_in() {
                assert!(
                    env.world.ball.pos.x < last_x,
                    "the lead-in's ball flies away"
                );
                last_x = env.world.ball.pos.x;
            }
        }
        let lead = env.steps;
        // It ended when the ball reached B's hitting plane, not at the limit.
        assert!(last_x <= Side::B.strike_plane_x() + 0.2, "x {last_x}");
        assert!(
            (30..sim::episode::LEAD_IN_STEPS).contains(&lead),
            "{lead} steps"
        );
        // The serve is in play from its start, at the lead-in's time, with a full episode ahead.
        assert_eq!(env.world.ball.pos, serve.ball.pos);
        assert_eq!(env.world.ball.vel, serve.ball.vel);
        assert!((env.world.time - lead as f64 * sim::arena::CONTROL_DT).abs() < 1e-9);
        assert_eq!(env.max_steps, lead + sim::arena::EPISODE_STEPS);
        assert!(!env.hit && !env.success);
        // Then as any episode: unreturned, the serve is A's miss.
        while !env.step().done {}
        assert_eq!(env.referee.end().unwrap().failing_side, Some(Side::A));
        assert!(env.steps < lead + sim::arena::EPISODE_STEPS);
        // A reset clears the lead-in.
        env.reset(ServeKind::P2, &mut rng, None);
        assert!(!env.in_lead_in() && env.max_steps == sim::arena::EPISODE_STEPS);
    }
    // A lead-in cut short: the serve comes after that many steps; none at all for 0.
    env.reset(ServeKind::P2, &mut rng, None);
    let serve = env.serve;
    let away = sim::serve::generate(ServeKind::Stroke { server: Side::A }, &mut rng, &bounce);
    env.start_lead_in(away.ball, 0);
    assert!(!env.in_lead_in());
    assert_eq!(env.world.ball.pos, serve.ball.pos);
    env.start_lead_in(away.ball, 7);
    let mut lead = 0;
    while env.in_lead_in() {
        env.step();
        lead += 1;
    }
    assert_eq!(lead, 7);
    assert_eq!(env.world.ball.pos, serve.ball.pos);
    assert_eq!(env.max_steps, 7 + sim::arena::EPISODE_STEPS);
}

#[test]
fn a_lead_in_ends_when_its_ball_turns_back_and_a_dropped_paddle_in_it_loses_the_episode() {
    let cfg = ArenaConfig::default();
    let bounce = sim::predict::BounceModel::for_table(&MYOCHALLENGE.table);
    let mut env = SingleServe::new(model(), &cfg, MYOCHALLENGE).unwrap();
    let mut rng = Rng::seeded(3);
    env.reset(ServeKind::P2, &mut rng, None);
    let serve = env.serve;
    // A ball that does not fly away (here: towards the robot) is no lead-in's: the serve comes at
    // once, before any player could plan for the wrong ball.
    let mut back =
        sim::serve::generate(ServeKind::Stroke { server: Side::A }, &mut rng, &bounce).ball;
    back.vel.x = -back.vel.x;
    env.start_lead_in(back, sim::episode::LEAD_IN_STEPS);
    env.step();
    assert!(!env.in_lead_in() && env.steps == 1);
    assert_eq!(env.world.ball.pos, serve.ball.pos);

    // The robot lets go of its paddle during the lead-in: it drops, and the episode is A's loss.
    env.reset(ServeKind::P2, &mut rng, None);
    let away = sim::serve::generate(ServeKind::Stroke { server: Side::A }, &mut rng, &bounce);
    env.start_lead_in(away.ball, sim::episode::LEAD_IN_STEPS);
    let grip: Vec<usize> = env.robot.grip_muscles().to_vec();
    let mut dropped = false;
    for _ in 0..sim::episode::LEAD_IN_STEPS {
        for &a in &grip {
            env.robot.state.ctrl[a] = 0.0;
            env.robot.state.act[a] = 0.0;
        }
        let report = env.step();
        if report.done {
            dropped = true;
            break;
        }
    }
    let end = env.referee.end().expect("judged");
    assert!(dropped, "{end:?}");
    assert_eq!(
        (end.reason, end.failing_side),
        (EndReason::Failure(Failure::DroppedPaddle), Some(Side::A))
    );
    assert!(!env.hit && !env.success);
}
