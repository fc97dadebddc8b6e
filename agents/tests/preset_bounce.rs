//! Regression test for a bug found reading the code (issue 9, item 7): `PlayerSpec::build` ignored
//! the arena preset and always planned with MyoChallenge's table bounce.

use std::sync::Arc;

use agents::checkpoint::{Activation, Checkpoint};
use agents::controller::{ControllerSpec, PdGains};
use agents::factory::PlayerSpec;
use sim::serve::ServeKind;

fn model() -> Arc<sim::model::Model> {
    Arc::new(sim::config::default_model())
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
            activation_clamp: None,
            activation_noise: None,
            clamp_coupled: false,
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
        let mut episode = sim::episode::SingleServe::new(
            m.clone(),
            &sim::config::ArenaConfig::default(),
            *preset,
        )
        .unwrap();
        episode.reset(ServeKind::P2, &mut sim::rng::Rng::seeded(4), None);
        let mut ctrl = episode.robot.state.ctrl.clone();
        p.act(&episode.robot, &episode.world.ball, 0.0, &mut ctrl)
            .unwrap();
        ctrl
    };
    let myo = controls(&sim::arena::MYOCHALLENGE);
    let realistic = sim::Preset::by_name("realistic").unwrap();
    assert_eq!(myo, controls(&sim::arena::MYOCHALLENGE), "deterministic");
    assert_ne!(
        myo,
        controls(&realistic),
        "the realistic table bounces differently"
    );
}
