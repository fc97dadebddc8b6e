//! The environments a training run steps: single serves or self-play rallies.

use std::sync::Arc;

use sim::config::ArenaConfig;
use sim::model::Model;

use crate::controller::ControllerSpec;
use crate::env::{Env, EpisodeEnd, RallyEnv};
use crate::ppo::{TrainConfig, TrainEnv};

/// A training environment: a single serve (one robot) or a self-play rally (two).
pub enum TrainingEnv {
    /// One robot returns one serve.
    Single(Box<Env>),
    /// Two robots rally, the policy playing both.
    Rally(Box<RallyEnv>),
}

/// What one robot's step gave.
pub struct AgentStep {
    /// The weighted reward (before the run's `reward_scale`).
    pub reward: f64,
    /// The episode is over.
    pub done: bool,
    /// The episode reached its time limit (or cap) rather than a terminal state.
    pub time_limit: bool,
    /// The robot has touched the ball (so far).
    pub hit: bool,
    /// A legal return (so far; in a rally: by this robot in this step).
    pub success: bool,
    /// Returns in the rally so far (single serve: the episode's legal returns, more than 1 only
    /// with follow-ons).
    pub rally_length: u32,
    /// The rally's dual term of this step.
    pub dual: f64,
    /// The position term, while the robot tracks a command before contact.
    pub tracking: Option<f64>,
    /// ‖a‖₁/n_a after the step.
    pub activation: f64,
    /// What each reward term added to `reward` ([`crate::env::RewardTerms::NAMES`]'s order).
    pub terms: [f64; 13],
}

impl TrainingEnv {
    /// A new episode from `seed`.
    pub fn reset(&mut self, seed: u64) {
        match self {
            TrainingEnv::Single(e) => {
                e.reset(seed);
            }
            TrainingEnv::Rally(e) => e.reset(seed),
        }
    }

    /// Appends every robot's observation to `out`, robot by robot.
    pub fn observe_into(&self, out: &mut Vec<f64>) {
        match self {
            TrainingEnv::Single(e) => out.extend_from_slice(e.observation()),
            TrainingEnv::Rally(e) => {
                out.extend_from_slice(e.observation(0));
                out.extend_from_slice(e.observation(1));
            }
        }
    }

    /// Entries of [`TrainingEnv::privileged_into`] per robot (0 in a rally, which has none).
    pub fn privileged_dim(&self) -> usize {
        match self {
            TrainingEnv::Single(e) => e.privileged_dim(),
            TrainingEnv::Rally(_) => 0,
        }
    }

    /// Appends what only a privileged critic sees (single serves; see [`Env::privileged_into`]).
    pub fn privileged_into(&self, out: &mut Vec<f64>) {
        if let TrainingEnv::Single(e) = self {
            e.privileged_into(out);
        }
    }

    /// One control step with the rows of `actions` (one per robot).
    pub fn step(&mut self, actions: &[Vec<f64>]) -> Vec<AgentStep> {
        match self {
            TrainingEnv::Single(env) => {
                let tr = env.step(&actions[0]);
                let tracking =
                    (!tr.hit && env.observer.command().is_some()).then_some(tr.terms.position);
                let time_limit = tr.done
                    && env.episode.referee.end().is_none()
                    && !tr.success
                    && env.episode.steps >= env.episode.max_steps;
                vec![AgentStep {
                    reward: tr.reward,
                    done: tr.done,
                    time_limit,
                    hit: tr.hit,
                    success: tr.success,
                    rally_length: env.returns(),
                    dual: 0.0,
                    tracking,
                    activation: tr.terms.effort,
                    terms: tr.terms.weighted(&env.weights),
                }]
            }
            TrainingEnv::Rally(env) => {
                let trs = env.step([&actions[0], &actions[1]]);
                let length = trs.iter().map(|t| t.returns).sum();
                let capped = env.capped();
                trs.iter()
                    .map(|t| AgentStep {
                        reward: t.step.reward,
                        done: t.step.done,
                        time_limit: t.step.done && capped,
                        hit: t.step.hit,
                        success: t.step.success,
                        rally_length: length,
                        dual: t.step.terms.dual,
                        tracking: t.tracking,
                        activation: t.step.terms.effort,
                        terms: t.step.terms.weighted(&env.weights),
                    })
                    .collect()
            }
        }
    }
}

/// The ball bank `[bank] file` names, read once for every environment; `None` without a file.
pub fn read_bank(config: &TrainConfig) -> Result<Option<crate::env::BallBank>, String> {
    let Some(file) = &config.bank.file else {
        return Ok(None);
    };
    let text = std::fs::read_to_string(file).map_err(|e| format!("bank.file {file}: {e}"))?;
    let balls = crate::env::BallBank::parse(&text).map_err(|e| format!("bank.file {file}: {e}"))?;
    Ok(Some(crate::env::BallBank {
        balls: balls.into(),
        fraction: config.bank.fraction,
    }))
}

/// The training environment a method runs in; its observation and action sizes.
pub fn make_env(
    model: &Arc<Model>,
    arena: &ArenaConfig,
    controller: &ControllerSpec,
    config: &TrainConfig,
    bank: Option<&crate::env::BallBank>,
) -> Result<(TrainingEnv, usize, usize), String> {
    // Both environments: MyoChallenge contact laws; every observation block but what the
    // ablation removes of the command.
    let (preset, blocks) = (sim::arena::MYOCHALLENGE, config.obs_blocks());
    let grip_floor = config.controller.grip_floor;
    Ok(match config.env {
        TrainEnv::Single => {
            let kind = config.serve.kind();
            let mut env = Env::new(
                model.clone(),
                arena,
                preset,
                controller,
                blocks,
                config.reward_weights(),
                kind,
            )?;
            env.end = EpisodeEnd::Training;
            env.grip_floor = grip_floor;
            env.task_rules = config.task_rules;
            env.position_target = config.position_target;
            env.observer.set_replan(config.replan);
            env.noise = crate::env::TrainingNoise {
                action: config.controller.action_noise,
                activation: config.controller.activation_noise,
            };
            env.bank = bank.cloned();
            env.lead_in = config.lead_in;
            env.lead_in_length = config.lead_in_length;
            env.follow_on = config.follow_on;
            let (o, a) = (env.obs_dim(), env.action_dim());
            (TrainingEnv::Single(Box::new(env)), o, a)
        }
        TrainEnv::Rally => {
            let mut env = RallyEnv::new(
                model.clone(),
                arena,
                preset,
                controller,
                blocks,
                config.reward_weights(),
            )?;
            env.grip_floor = grip_floor;
            env.task_rules = config.task_rules;
            env.position_target = config.position_target;
            env.set_replan(config.replan);
            let (o, a) = (env.obs_dim(), env.action_dim());
            (TrainingEnv::Rally(Box::new(env)), o, a)
        }
    })
}
