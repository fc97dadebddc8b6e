//! Follow-on serves (`follow_on` of the training configuration): after a legal return, the robot's
//! own return flies away unjudged and a next serve comes to the robot as its stroke left it, so
//! that single-serve training sees the moment between two strokes of a rally; the configuration refuses
//! a share outside [0, 1] and follow-ons in the rally environment, naming the field; the checkpoint
//! records it. (The environment's side is tested beside it, in `env::single`.)

use std::sync::Arc;

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
fn the_configuration_checks_the_share_and_the_checkpoint_records_it() {
    for bad in [-0.1, 1.5, f64::NAN] {
        let c = TrainConfig {
            follow_on: bad,
            ..TrainConfig::default()
        };
        assert!(c.validate().unwrap_err().contains("follow_on"), "{bad}");
    }
    let mut rally = TrainConfig {
        follow_on: 0.5,
        env: TrainEnv::Rally,
        ..TrainConfig::default()
    };
    rally.controller.action_noise = 0.0;
    rally.controller.activation_noise = 0.0;
    assert!(rally.validate().unwrap_err().starts_with("follow_on"));
    let text = toml::to_string(&TrainConfig::default()).unwrap();
    assert!(!text.contains("follow_on"), "{text}");
    let parsed: TrainConfig = toml::from_str("follow_on = 0.25").unwrap();
    assert_eq!(parsed.follow_on, 0.25);
    for follow_on in [0.0, 0.5] {
        let mut c = TrainConfig {
            follow_on,
            ..TrainConfig::default()
        };
        c.ppo.envs = 2;
        c.ppo.steps_per_env = 8;
        c.ppo.hidden = vec![16];
        let mut t = Trainer::new(model(), Method::Kmac, c, 3).unwrap();
        t.iterate().unwrap();
        let ck = t.checkpoint("probe", "test", "none").unwrap();
        let training = ck.training.as_ref().unwrap();
        assert_eq!(training.follow_on, (follow_on > 0.0).then_some(follow_on));
        let json = serde_json::to_string(&ck).unwrap();
        assert_eq!(json.contains("follow_on"), follow_on > 0.0);
    }
}
