//! The player factory: `PlayerSpec`, a recipe for a player that can be sent to worker threads — a
//! scripted variant by name, a built-in checkpoint by name ([`crate::builtins`]) or a checkpoint
//! file — and the count of players built.

use sim::arena::Preset;
use sim::model::Model;
use sim::predict::BounceModel;

use crate::player::Player;
use crate::scripted::{Scripted, ScriptedParams};

static PLAYERS_BUILT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// Players built by [`PlayerSpec::build`] in this process so far (evaluations and matches build one
/// per worker or side, never one per episode: a test holds them to it).
pub fn players_built() -> usize {
    PLAYERS_BUILT.load(std::sync::atomic::Ordering::Relaxed)
}

/// How to build a player: a recipe that can be sent to worker threads.
#[derive(Debug, Clone, PartialEq)]
pub enum PlayerSpec {
    /// A scripted agent with a name and its parameters.
    Scripted {
        /// e.g. "scripted", "scripted-drive".
        name: String,
        /// How it plays.
        params: ScriptedParams,
    },
    /// A validated policy checkpoint.
    Checkpoint(std::sync::Arc<crate::checkpoint::Checkpoint>),
}

impl PlayerSpec {
    /// The same player without the Gaussian noise a trained checkpoint was trained with
    /// (`policy_std`, `action_noise`): it plays its network's mean action (named "… (mean
    /// action)"), and K-MAC the expectation of its training noise on the activations, so that
    /// nothing is drawn. A scripted player is unchanged.
    pub fn mean_action(self) -> PlayerSpec {
        match self {
            PlayerSpec::Checkpoint(c) => {
                let mut c = (*c).clone();
                c.policy_std = None;
                c.action_noise = None;
                c.expected_activation_noise = true;
                c.name = format!("{} (mean action)", c.name);
                PlayerSpec::Checkpoint(std::sync::Arc::new(c))
            }
            other => other,
        }
    }

    /// A scripted variant's name, a built-in checkpoint's name of `model`'s robot (`kmac`,
    /// `kmac-rally`, …: compiled into the binary, found from any directory), or else a checkpoint file to read (through
    /// `read`) and validate.
    pub fn resolve(
        name: &str,
        model: &Model,
        read: &dyn Fn(&str) -> std::io::Result<String>,
    ) -> Result<PlayerSpec, String> {
        if let Some(s) = PlayerSpec::scripted(name) {
            return Ok(s);
        }
        let robot = sim::config::robot_name(model);
        let text = match crate::builtins::checkpoint_of(robot, name) {
            Some(text) => text.to_string(),
            None => read(name).map_err(|e| {
                let scripted: Vec<&str> = crate::scripted::variants()
                    .iter()
                    .map(|(n, _)| *n)
                    .collect();
                format!(
                    "'{name}' is neither a scripted agent ({}), a built-in checkpoint ({}) nor a readable checkpoint file: {e}",
                    scripted.join(", "),
                    crate::builtins::names_of(robot).join(", ")
                )
            })?,
        };
        let c = crate::checkpoint::Checkpoint::from_json(&text, model)
            .map_err(|e| format!("checkpoint {name}: {e}"))?;
        Ok(PlayerSpec::Checkpoint(std::sync::Arc::new(c)))
    }

    /// The scripted variant called `name`, if there is one (see [`crate::scripted::variants`]).
    pub fn scripted(name: &str) -> Option<PlayerSpec> {
        crate::scripted::variants()
            .into_iter()
            .find(|(n, _)| *n == name)
            .map(|(n, params)| PlayerSpec::Scripted {
                name: n.to_string(),
                params,
            })
    }

    /// Display name.
    pub fn name(&self) -> String {
        match self {
            PlayerSpec::Scripted { name, .. } => name.clone(),
            PlayerSpec::Checkpoint(c) => c.name.clone(),
        }
    }

    /// A player for `model` in an arena of `preset` (its planner predicts with that preset's table
    /// bounce).
    pub fn build(
        &self,
        model: &Model,
        preset: &Preset,
        seed: u64,
    ) -> Result<Box<dyn Player>, String> {
        PLAYERS_BUILT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let bounce = BounceModel::for_table(&preset.table);
        match self {
            PlayerSpec::Scripted { params, .. } => {
                let paddle = model
                    .body("paddle")
                    .ok_or("the model has no body named 'paddle'")?;
                Ok(Box::new(Scripted::new(
                    model,
                    paddle,
                    params.clone(),
                    bounce,
                    seed,
                )?))
            }
            PlayerSpec::Checkpoint(c) => {
                c.validate(model).map_err(|e| e.to_string())?;
                let p = crate::checkpoint::CheckpointPlayer::new(c.clone(), model, bounce, seed)
                    .map_err(|e| e.to_string())?;
                Ok(Box::new(p))
            }
        }
    }
}
