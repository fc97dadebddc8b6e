//! What the checkpoint diagnosis examples share: the robot model (the default body, or the MJCF file
//! named by `RALLY_MODEL`, e.g. the imported MyoSuite robot, with its arena configuration), a
//! checkpoint read from the command line, the MyoChallenge arena and its bounce model.
#![allow(dead_code)]

use agents::checkpoint::{Checkpoint, CheckpointPlayer};
use sim::model::Model;
use std::sync::Arc;

/// The arena an example plays in, with the checkpoint it diagnoses.
pub struct Bench {
    /// The robot model: the default body, or `RALLY_MODEL`'s file.
    pub model: Arc<Model>,
    /// The checkpoint, validated against `model`.
    pub checkpoint: Arc<Checkpoint>,
    /// The MyoChallenge contact laws.
    pub preset: sim::arena::Preset,
    /// Their bounce model, for the planner.
    pub bounce: sim::predict::BounceModel,
    /// Arena constants: the default body's, or MyoSuite's robot's with `RALLY_MODEL`.
    pub config: sim::config::ArenaConfig,
}

impl Bench {
    /// Reads the checkpoint at `path`; panics with the reason if it does not load. With
    /// `RALLY_MODEL=FILE` set, the robot is that MJCF file (MyoSuite's robot: `rally model import
    /// myosuite` writes it) and the arena configuration MyoSuite's robot's.
    pub fn load(path: &str) -> Bench {
        let (model, config) = match std::env::var("RALLY_MODEL") {
            Ok(file) => (
                sim::mjcf::load(std::path::Path::new(&file), &|p| std::fs::read_to_string(p))
                    .unwrap_or_else(|e| panic!("RALLY_MODEL={file}: {e}")),
                sim::config::ArenaConfig::myochallenge(),
            ),
            Err(_) => (
                sim::config::default_model(),
                sim::config::ArenaConfig::default(),
            ),
        };
        let model = Arc::new(model);
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
            config,
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
            .expect("the arena configuration fits the model")
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
