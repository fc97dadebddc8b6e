//! Regression test for a bug found reading the code (issue 9, item 7): `evaluate` built a new player
//! (for ONNX: a new network) for every episode, not one per worker. Alone in its test binary, since
//! it counts builds with a process-wide counter.

use std::sync::Arc;

use agents::eval::{evaluate, play_episode, Evaluation};
use agents::factory::{players_built, PlayerSpec};
use sim::serve::ServeKind;

fn model() -> Arc<sim::model::Model> {
    Arc::new(sim::config::default_model())
}

#[test]
fn evaluation_builds_one_player_per_worker_and_gives_the_per_episode_numbers() {
    let m = model();
    let spec = PlayerSpec::scripted("scripted").unwrap();
    let episodes = 24;
    let e = Evaluation {
        lead_in: false,
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
        let (serve_seed, agent_seed) = agents::seeds::episode_seeds(e.seed, i);
        let mut p = spec.build(&m, &e.preset, agent_seed).unwrap();
        p.reseed(agent_seed);
        let r = play_episode(&mut env, p.as_mut(), e.kind, serve_seed);
        hits += r.hit as usize;
        wins += r.success as usize;
    }
    assert_eq!(report.hit_rate, agents::eval::wilson(hits, episodes));
    assert_eq!(report.success_rate, agents::eval::wilson(wins, episodes));
}
