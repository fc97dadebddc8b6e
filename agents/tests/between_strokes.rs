//! The moment between two strokes of a rally, in single serves. Lead-ins (`lead_in` of the training
//! configuration): in that share of episodes the robot's own return flies away first, unjudged, with
//! the `ready` term paid and no stroke term, then the episode's serve comes; the draw comes after the
//! serve's, so the other episodes are served exactly as without it. Follow-ons (`follow_on`): after a
//! legal return, the return flies away unjudged and a next serve comes to the robot as its stroke left
//! it (the environment's side is tested beside it, in `env::single`). The configuration refuses a
//! share outside [0, 1] and either in the rally environment, naming the field; the checkpoint records
//! both.

use std::sync::Arc;

use agents::env::single::{Env, LeadInLength};
use agents::ppo::trainer::envs::{make_env, TrainingEnv};
use agents::ppo::trainer::Trainer;
use agents::ppo::{Method, TrainConfig, TrainEnv};
use sim::arena::{Side, MYOCHALLENGE};
use sim::config::ArenaConfig;
use sim::episode::SingleServe;
use sim::rng::Rng;
use sim::serve::ServeKind;

fn model() -> Arc<sim::model::Model> {
    Arc::new(sim::config::default_model())
}

fn env(lead_in: f64) -> Box<Env> {
    env_with(lead_in, LeadInLength::Full)
}

fn env_with(lead_in: f64, lead_in_length: LeadInLength) -> Box<Env> {
    let m = model();
    let config = TrainConfig {
        lead_in,
        lead_in_length,
        ..TrainConfig::default()
    };
    let controller = config.controller(Method::Kmac, &m);
    match make_env(&m, &ArenaConfig::default(), &controller, &config, None).unwrap() {
        (TrainingEnv::Single(env), ..) => env,
        _ => unreachable!("the default environment is the single serve"),
    }
}

/// The rally environment's configuration, without the training noise it refuses.
fn rally_config() -> TrainConfig {
    let mut c = TrainConfig {
        env: TrainEnv::Rally,
        ..TrainConfig::default()
    };
    c.controller.action_noise = 0.0;
    c.controller.activation_noise = 0.0;
    c
}

/// The checkpoint of one small training iteration under `c`.
fn one_iteration(mut c: TrainConfig) -> agents::checkpoint::Checkpoint {
    c.ppo.envs = 2;
    c.ppo.steps_per_env = 8;
    c.ppo.hidden = vec![16];
    let mut t = Trainer::new(model(), Method::Kmac, c, 3).unwrap();
    t.iterate().unwrap();
    t.checkpoint("probe", "test", "none").unwrap()
}

#[test]
fn a_lead_in_pays_the_ready_term_and_no_stroke_until_the_serve_comes() {
    let mut e = env(1.0);
    let zero = vec![0.0; e.action_dim()];
    for seed in 0..3 {
        e.reset(seed);
        assert!(e.episode.in_lead_in());
        assert!(
            e.observer.command().is_none(),
            "no command for a ball flying away"
        );
        let mut lead = 0;
        while e.episode.in_lead_in() {
            let tr = e.step(&zero);
            lead += 1;
            assert!(!tr.done && !tr.hit, "seed {seed}, step {lead}");
            assert!(
                tr.terms.ready > 0.0 && tr.terms.ready <= 1.0,
                "{:?}",
                tr.terms
            );
            assert_eq!(
                (tr.terms.hit, tr.terms.landing, tr.terms.position),
                (0.0, 0.0, 0.0),
                "seed {seed}, step {lead}"
            );
        }
        assert!(lead > 20, "seed {seed}: a lead-in of {lead} steps");
        // The serve is in play: it is planned for, and the ready term is no longer paid.
        let tr = e.step(&zero);
        assert!(e.observer.command().is_some(), "seed {seed}");
        assert_eq!(tr.terms.ready, 0.0);
        let mut done = tr.done;
        while !done {
            done = e.step(&zero).done;
        }
        assert!(e.episode.steps > lead);
    }
}

/// Control steps of the lead-in of the episode `e` was just reset to.
fn lead_in_steps(e: &mut Env) -> usize {
    let zero = vec![0.0; e.action_dim()];
    let mut n = 0;
    while e.episode.in_lead_in() {
        e.step(&zero);
        n += 1;
    }
    n
}

#[test]
fn spread_lead_ins_are_cut_anywhere_in_the_flight_of_the_same_balls() {
    let (mut full, mut spread) = (env(1.0), env_with(1.0, LeadInLength::Spread));
    let mut shares = Vec::new();
    for seed in 0..30 {
        full.reset(seed);
        spread.reset(seed);
        let (f, s) = (lead_in_steps(&mut full), lead_in_steps(&mut spread));
        assert!((1..=f).contains(&s), "seed {seed}: {s} of {f} steps");
        shares.push(s as f64 / f as f64);
    }
    let below = shares.iter().filter(|&&x| x < 0.5).count();
    assert!(
        (8..=22).contains(&below),
        "{below} of 30 below half: {shares:?}"
    );
}

#[test]
fn episodes_without_a_lead_in_are_served_as_without_the_setting() {
    let (mut plain, mut half) = (env(0.0), env(0.5));
    let mut with = 0;
    for seed in 0..40 {
        let a = plain.reset(seed);
        let b = half.reset(seed);
        assert_eq!(plain.episode.serve, half.episode.serve, "seed {seed}");
        if half.episode.in_lead_in() {
            with += 1;
            assert_ne!(a, b, "seed {seed}: the lead-in's ball is observed");
        } else {
            assert_eq!(a, b, "seed {seed}");
        }
        assert!(!plain.episode.in_lead_in());
    }
    assert!(
        (10..=30).contains(&with),
        "{with} of 40 episodes with a lead-in"
    );
}

#[test]
fn the_configuration_checks_the_lead_in_share_and_the_checkpoint_records_it() {
    for bad in [-0.1, 1.5, f64::NAN] {
        let c = TrainConfig {
            lead_in: bad,
            ..TrainConfig::default()
        };
        assert!(c.validate().unwrap_err().contains("lead_in"), "{bad}");
    }
    let rally = TrainConfig {
        lead_in: 0.5,
        ..rally_config()
    };
    assert!(rally.validate().unwrap_err().starts_with("lead_in"));
    let idle = TrainConfig {
        lead_in_length: LeadInLength::Spread,
        ..TrainConfig::default()
    };
    assert!(idle.validate().unwrap_err().starts_with("lead_in_length"));
    // Written only when set, so configurations and checkpoints without it read and write as before.
    let text = toml::to_string(&TrainConfig::default()).unwrap();
    assert!(!text.contains("lead_in"), "{text}");
    for (lead_in, length) in [
        (0.0, LeadInLength::Full),
        (0.5, LeadInLength::Full),
        (0.5, LeadInLength::Spread),
    ] {
        let c = TrainConfig {
            lead_in,
            lead_in_length: length,
            ..TrainConfig::default()
        };
        let ck = one_iteration(c);
        let training = ck.training.as_ref().unwrap();
        assert_eq!(training.lead_in, (lead_in > 0.0).then_some(lead_in));
        let spread = length == LeadInLength::Spread;
        assert_eq!(training.lead_in_length, spread.then_some(length));
        let json = serde_json::to_string(&ck).unwrap();
        assert_eq!(json.contains("lead_in"), lead_in > 0.0);
    }
}

#[test]
fn an_evaluation_with_a_lead_in_plays_the_same_serves_after_the_robots_own_return() {
    let evaluation = |lead_in, episodes| agents::eval::Evaluation {
        model: model(),
        config: ArenaConfig::default(),
        preset: sim::arena::MYOCHALLENGE,
        kind: sim::serve::ServeKind::Stroke {
            server: sim::arena::Side::B,
        },
        episodes,
        seed: 5,
        lead_in,
    };
    let spec = agents::factory::PlayerSpec::scripted("scripted").unwrap();
    let run = |lead_in, episodes| {
        agents::eval::evaluate_traced(&evaluation(lead_in, episodes), &spec, &|| {}, true).unwrap()
    };
    let ((plain, plain_trace), (led, led_trace)) = (run(false, 3), run(true, 3));
    assert!(led.lead_in && !plain.lead_in);
    let json = serde_json::to_value(&plain).unwrap();
    assert!(json.get("lead_in").is_none(), "left out when off: {json}");
    assert_eq!(serde_json::to_value(&led).unwrap()["lead_in"], true);
    assert!(plain_trace.iter().all(|s| !s.lead_in));
    for episode in 0..3 {
        let of = |t: &[agents::eval::TraceStep]| -> Vec<agents::eval::TraceStep> {
            t.iter().filter(|s| s.episode == episode).cloned().collect()
        };
        let (a, b) = (of(&plain_trace), of(&led_trace));
        // Every step is traced, the lead-in's marked and numbered on with the rest.
        assert!(b.iter().enumerate().all(|(i, s)| s.step == i));
        let lead = b.iter().take_while(|s| s.lead_in).count();
        assert!(lead > 20 && b[lead..].iter().all(|s| !s.lead_in), "{lead}");
        assert!(!a.is_empty() && b.len() > lead);
        // The serve starts where the lead-in's ball left off, the same serve as without.
        let serve_time = b[lead].time;
        assert!((serve_time - lead as f64 * sim::arena::CONTROL_DT).abs() < 1e-9);
    }
    // The figures count from the serve on: an episode's steps are the trace's after its lead-in.
    let kind = sim::serve::ServeKind::Stroke {
        server: sim::arena::Side::B,
    };
    let bounce = sim::predict::BounceModel::for_table(&sim::arena::MYOCHALLENGE.table);
    let mut env =
        sim::episode::SingleServe::new(model(), &ArenaConfig::default(), sim::arena::MYOCHALLENGE)
            .unwrap();
    let mut player = spec.build(&model(), &sim::arena::MYOCHALLENGE, 0).unwrap();
    for seed in 0..3 {
        let mut rng = sim::rng::Rng::seeded(seed);
        env.reset(kind, &mut rng, None);
        let away = sim::serve::generate(
            sim::serve::ServeKind::Stroke {
                server: sim::arena::Side::A,
            },
            &mut rng,
            &bounce,
        );
        env.start_lead_in(away.ball, sim::episode::LEAD_IN_STEPS);
        let mut trace = Vec::new();
        let r = agents::eval::play_traced(&mut env, player.as_mut(), Some(&mut trace));
        let lead = trace.iter().filter(|s| s.lead_in).count();
        assert!(lead > 20, "seed {seed}: {lead}");
        assert_eq!(r.steps, trace.len() - lead, "seed {seed}");
        assert!(r.steps <= sim::arena::EPISODE_STEPS);
    }
}

/// One control step of `player` on `env`; whether the paddle touched the ball in it.
fn step(env: &mut SingleServe, player: &mut dyn agents::player::Player, ctrl: &mut [f64]) -> bool {
    ctrl.copy_from_slice(&env.robot.state.ctrl);
    player
        .act(&env.robot, &env.world.ball, env.world.time, ctrl)
        .unwrap();
    env.robot.state.ctrl.copy_from_slice(ctrl);
    let report = env.step();
    report
        .events
        .iter()
        .any(|e| e.kind == sim::ContactKind::Paddle { owner: Side::A })
}

#[test]
fn after_a_real_stroke_the_return_flies_away_unjudged_and_the_next_serve_finds_the_robot_as_it_is()
{
    let m = model();
    let kind = ServeKind::Stroke { server: Side::B };
    let bounce = sim::predict::BounceModel::for_table(&MYOCHALLENGE.table);
    let mut env = SingleServe::new(m.clone(), &ArenaConfig::default(), MYOCHALLENGE).unwrap();
    let spec = agents::factory::PlayerSpec::scripted("scripted").unwrap();
    let mut player = spec.build(&m, &MYOCHALLENGE, 0).unwrap();
    let mut ctrl = vec![0.0; m.actuators.len()];
    let mut rng = Rng::seeded(21);
    let (mut followed, mut second_hits) = (0, 0);
    for _ in 0..10 {
        env.reset(kind, &mut rng, None);
        player.reset();
        // Play the serve until the ball left the paddle three control steps ago (the training
        // episode's judgement).
        let mut since: Option<usize> = None;
        while !env.done && since != Some(3) {
            if step(&mut env, player.as_mut(), &mut ctrl) {
                since = Some(0);
            } else if let Some(k) = since.as_mut() {
                *k += 1;
            }
        }
        if env.done || Side::A.sign() * env.world.ball.vel.x >= 0.0 {
            continue;
        }
        let next = sim::serve::generate(kind, &mut rng, &bounce);
        let (qpos, t0, step0) = (env.robot.state.clone(), env.world.time, env.steps);
        env.follow_on(next);
        followed += 1;
        assert!(env.in_lead_in() && !env.hit && !env.success && env.referee.end().is_none());
        assert_eq!(env.robot.state, qpos, "the robot is left as it is");
        while env.in_lead_in() {
            let x = env.world.ball.pos.x;
            step(&mut env, player.as_mut(), &mut ctrl);
            assert!(!env.done && !env.hit);
            if env.in_lead_in() {
                assert!(env.world.ball.pos.x < x, "the return flies away");
            }
        }
        let away = env.steps - step0;
        assert!((1..=sim::episode::LEAD_IN_STEPS).contains(&away), "{away}");
        // The next serve from its start, at the episode's time, with a full episode ahead.
        assert_eq!(env.world.ball.pos, next.ball.pos);
        assert_eq!(env.world.ball.vel, next.ball.vel);
        let dt = away as f64 * sim::arena::CONTROL_DT;
        assert!((env.world.time - t0 - dt).abs() < 1e-9);
        assert_eq!(env.max_steps, env.steps + sim::arena::EPISODE_STEPS);
        while !env.done {
            step(&mut env, player.as_mut(), &mut ctrl);
        }
        second_hits += env.hit as usize;
    }
    // The scripted agent closes its loop on the plan, so it strikes again from where its stroke
    // left it.
    assert!(followed >= 4, "{followed} of 10 strokes followed on");
    assert!(
        second_hits >= 2,
        "{second_hits} of {followed} next balls hit"
    );
}

#[test]
fn the_configuration_checks_the_follow_on_share_and_the_checkpoint_records_it() {
    for bad in [-0.1, 1.5, f64::NAN] {
        let c = TrainConfig {
            follow_on: bad,
            ..TrainConfig::default()
        };
        assert!(c.validate().unwrap_err().contains("follow_on"), "{bad}");
    }
    let rally = TrainConfig {
        follow_on: 0.5,
        ..rally_config()
    };
    assert!(rally.validate().unwrap_err().starts_with("follow_on"));
    let text = toml::to_string(&TrainConfig::default()).unwrap();
    assert!(!text.contains("follow_on"), "{text}");
    let parsed: TrainConfig = toml::from_str("follow_on = 0.25").unwrap();
    assert_eq!(parsed.follow_on, 0.25);
    for follow_on in [0.0, 0.5] {
        let ck = one_iteration(TrainConfig {
            follow_on,
            ..TrainConfig::default()
        });
        let training = ck.training.as_ref().unwrap();
        assert_eq!(training.follow_on, (follow_on > 0.0).then_some(follow_on));
        // Its returns per episode are kept, as a rally run's rally length is.
        assert_eq!(training.rally_length.is_some(), follow_on > 0.0);
        let json = serde_json::to_string(&ck).unwrap();
        assert_eq!(json.contains("follow_on"), follow_on > 0.0);
    }
}
