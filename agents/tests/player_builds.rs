//! Regression tests for two bugs found reading the code (issue 9, item 7):
//! - `evaluate` built a new player (for ONNX: a new network) for every episode, not one per worker;
//! - `PlayerSpec::build` ignored the arena preset and always planned with MyoChallenge's bounce.
//!
//! Each test is alone in this file's binary where it counts builds (the counter is process-wide).

use std::sync::Arc;

use agents::checkpoint::{Activation, Checkpoint};
use agents::controller::{ControllerSpec, PdGains};
use agents::eval::{evaluate, play_episode, Evaluation};
use agents::player::{players_built, PlayerSpec};
use sim::serve::ServeKind;

fn model() -> Arc<sim::model::Model> {
    Arc::new(
        sim::mjcf::parse_str(sim::config::DEFAULT_MODEL_XML, "upper_body.xml").expect("model"),
    )
}

#[test]
fn evaluation_builds_one_player_per_worker_and_gives_the_per_episode_numbers() {
    let m = model();
    let spec = PlayerSpec::scripted("scripted").unwrap();
    let episodes = 24;
    let e = Evaluation {
        model: m.clone(),
        config: sim::config::ArenaConfig::default(),
        preset: sim::arena::MYOCHALLENGE,
        kind: ServeKind::P2,
        episodes,
        seed: 9,
    };
    let before = players_built();
    let report = evaluate(&e, &spec, &|| {}).unwrap();
    let built = players_built() - before;
    // One check up front and at most one per rayon worker — never one per episode.
    assert!(
        built <= 1 + rayon::current_num_threads(),
        "{built} players built for {episodes} episodes"
    );
    // The numbers are those of a fresh player for every episode.
    let mut env = sim::episode::SingleServe::new(m.clone(), &e.config, e.preset).unwrap();
    let (mut hits, mut wins) = (0, 0);
    for i in 0..episodes {
        let (serve_seed, agent_seed) = agents::eval::episode_seeds(e.seed, i);
        let mut p = spec.build(&m, &e.preset, agent_seed).unwrap();
        p.reseed(agent_seed);
        let r = play_episode(&mut env, p.as_mut(), e.kind, serve_seed);
        hits += r.hit as usize;
        wins += r.success as usize;
    }
    assert_eq!(report.hit_rate, agents::eval::wilson(hits, episodes));
    assert_eq!(report.success_rate, agents::eval::wilson(wins, episodes));
}

#[test]
fn players_plan_with_the_bounce_of_the_arena_preset() {
    // A checkpoint whose actions are its planner's command (strike point, racket velocity): built
    // for two presets with different table bounces, it must plan differently for the same ball.
    let m = model();
    let mut ck = Checkpoint::template(
        &m,
        "command-echo",
        ControllerSpec::Kmac {
            gains: PdGains { kp: 10.0, kd: 1.0 },
        },
        &[],
        Activation::Linear,
    );
    let space = agents::controller::ActionSpace::new(&m);
    let obs: usize = ck.observation.blocks.iter().map(|b| b.size(&space)).sum();
    let command = obs - 11;
    let layer = &mut ck.policy.as_mut().unwrap().layers[0];
    for (k, row) in layer.weights.iter_mut().enumerate() {
        row[command + k % 6] = 0.1;
    }
    let spec = PlayerSpec::Checkpoint(Arc::new(ck));
    let controls = |preset: &sim::Preset| -> Vec<f64> {
        let mut p = spec.build(&m, preset, 1).unwrap();
        let mut episode =
            sim::episode::SingleServe::new(m.clone(), &sim::config::ArenaConfig::default(), *preset)
                .unwrap();
        episode.reset(ServeKind::P2, &mut sim::rng::Rng::seeded(4), None);
        let mut ctrl = episode.robot.state.ctrl.clone();
        p.act(&episode.robot, &episode.world.ball, 0.0, &mut ctrl).unwrap();
        ctrl
    };
    let myo = controls(&sim::arena::MYOCHALLENGE);
    let realistic = sim::Preset::by_name("realistic").unwrap();
    assert_eq!(myo, controls(&sim::arena::MYOCHALLENGE), "deterministic");
    assert_ne!(myo, controls(&realistic), "the realistic table bounces differently");
}
