//! What the checkpoint diagnosis examples share: the default model, a checkpoint read from the
//! command line, the MyoChallenge arena and its bounce model.
#![allow(dead_code)]

use agents::checkpoint::{Checkpoint, CheckpointPlayer};
use sim::model::Model;
use std::sync::Arc;

/// The arena an example plays in, with the checkpoint it diagnoses.
pub struct Bench {
    /// The default robot model.
    pub model: Arc<Model>,
    /// The checkpoint, validated against `model`.
    pub checkpoint: Arc<Checkpoint>,
    /// The MyoChallenge contact laws.
    pub preset: sim::arena::Preset,
    /// Their bounce model, for the planner.
    pub bounce: sim::predict::BounceModel,
    /// Default arena constants.
    pub config: sim::config::ArenaConfig,
}

impl Bench {
    /// Reads the checkpoint at `path`; panics with the reason if it does not load.
    pub fn load(path: &str) -> Bench {
        let model = Arc::new(sim::config::default_model());
        let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{path}: {e}"));
        let checkpoint = Arc::new(
            Checkpoint::from_json(&text, &model).unwrap_or_else(|e| panic!("{path}: {e}")),
        );
        let preset = sim::arena::MYOCHALLENGE;
        Bench {
            bounce: sim::predict::BounceModel::for_table(&preset.table),
            model,
            checkpoint,
            preset,
            config: sim::config::ArenaConfig::default(),
        }
    }

    /// A player of the checkpoint (agent seed 0; reseed it per episode).
    pub fn player(&self) -> CheckpointPlayer {
        CheckpointPlayer::new(self.checkpoint.clone(), &self.model, self.bounce, 0)
            .expect("validated checkpoint")
    }

    /// A single-serve environment.
    pub fn single(&self) -> sim::episode::SingleServe {
        sim::episode::SingleServe::new(self.model.clone(), &self.config, self.preset)
            .expect("default arena")
    }
}

/// The `i`-th command-line argument parsed, or `default` when absent.
pub fn arg<T: std::str::FromStr>(args: &[String], i: usize, default: T) -> T {
    args.get(i)
        .map(|s| {
            s.parse()
                .unwrap_or_else(|_| panic!("argument {}: cannot read '{s}'", i + 1))
        })
        .unwrap_or(default)
}

/// Lets `player` choose the controls of `env`'s robot for the next step, written into `ctrl` and
/// the robot; false (the episode ended as an invalid action) when it cannot.
pub fn act(
    player: &mut dyn agents::player::Player,
    env: &mut sim::episode::SingleServe,
    ctrl: &mut Vec<f64>,
) -> bool {
    ctrl.clone_from(&env.robot.state.ctrl);
    let ok = player
        .act(&env.robot, &env.world.ball, env.world.time, ctrl)
        .is_ok();
    if ok {
        env.robot.state.ctrl.copy_from_slice(ctrl);
    } else {
        env.invalid_action();
    }
    ok
}
