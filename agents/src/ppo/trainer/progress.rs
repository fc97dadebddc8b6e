//! A run's progress: its episodes, learning curve, timing and validations.

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

/// One finished training episode.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct EpisodeStat {
    /// Sum of the (unscaled) rewards.
    pub reward: f64,
    /// Control steps.
    pub steps: u32,
    /// The paddle touched the ball.
    pub hit: bool,
    /// The return was legal (or predicted legal, when the training episode ended before it landed).
    pub success: bool,
    /// Mean ‖a‖₁/n_a over its steps.
    pub mean_activation: f64,
    /// Legal returns in the episode (a rally's, by both sides; a single serve's: 0 or 1).
    #[serde(default)]
    pub rally_length: u32,
    /// Times the `dual` term was paid to this robot (its return crossed the other plane in the box).
    #[serde(default)]
    pub dual: f64,
}

/// One row of the learning curve: an iteration's losses and the rolling episode statistics after it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, Default)]
pub struct CurveRow {
    /// Iterations done.
    pub iteration: u64,
    /// Control steps simulated so far (all environments).
    pub env_steps: u64,
    /// Training wall time so far, s.
    pub wall_s: f64,
    /// Episodes finished so far.
    pub episodes: u64,
    /// Mean episode reward (unscaled) over the last `RECENT_EPISODES`.
    pub reward: f64,
    /// Mean episode length, control steps.
    pub length: f64,
    /// Hit rate over the last episodes.
    pub hit_rate: f64,
    /// Success rate over the last episodes.
    pub success_rate: f64,
    /// Mean activation over the last episodes.
    pub mean_activation: f64,
    /// Mean of the position term `exp(−8·d)` over this rollout's steps before contact (the command
    /// tracking: 1 when the blade sits at the planned strike point).
    pub tracking: f64,
    /// Learning rate after the update.
    pub learning_rate: f64,
    /// Mean KL(old ‖ new) over the update's minibatches.
    pub kl: f64,
    /// Mean clipped value loss.
    pub value_loss: f64,
    /// Mean clipped surrogate loss.
    pub surrogate_loss: f64,
    /// Policy entropy.
    pub entropy: f64,
    /// Mean policy σ.
    pub std: f64,
    /// Mean legal returns per episode over the last episodes (a rally's length).
    #[serde(default)]
    pub rally_length: f64,
    /// Mean times per episode the `dual` term was paid, over the last episodes.
    #[serde(default)]
    pub dual: f64,
    /// Minibatch steps of the update skipped because their gradient was not finite.
    #[serde(default)]
    pub skipped_steps: u64,
}

/// Where the time of the run went, s (this process only).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Timing {
    /// Stepping and resetting the environments (parallel).
    pub simulation: f64,
    /// The policy's batched forward passes and sampling during rollouts.
    pub policy: f64,
    /// GAE and PPO's update.
    pub update: f64,
    /// Control steps simulated.
    pub env_steps: u64,
}

/// What a run has done so far, besides its tensors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Progress {
    /// Iterations done.
    pub iteration: u64,
    /// Control steps simulated.
    pub env_steps: u64,
    /// Training wall time, s, over every process of the run.
    pub wall_s: f64,
    /// Episodes finished.
    pub episodes: u64,
    /// The last episodes.
    pub recent: VecDeque<EpisodeStat>,
    /// One row per iteration.
    pub curve: Vec<CurveRow>,
    /// What this run's weights started from (a warm start: a run directory or a checkpoint file),
    /// if anything.
    #[serde(default)]
    pub warm_start: Option<String>,
    /// Every validation so far (see [`super::ValidationConfig`]).
    #[serde(default)]
    pub validations: Vec<ValidationPoint>,
}

impl Progress {
    /// The best validation so far (the earliest of equals).
    pub fn best_validation(&self) -> Option<&ValidationPoint> {
        self.validations
            .iter()
            .fold(None, |best: Option<&ValidationPoint>, v| match best {
                Some(b) if b.score >= v.score => Some(b),
                _ => Some(v),
            })
    }
}

/// One validation of the policy on held-out episodes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ValidationPoint {
    /// Iterations done when it was taken.
    pub iteration: u64,
    /// Env steps done then.
    pub env_steps: u64,
    /// Mean rally length (rally environment) or success rate (single serves).
    pub score: f64,
    /// Rallies or episodes played.
    pub episodes: usize,
    /// Longest rally (rally environment; 0 for single serves).
    #[serde(default)]
    pub longest: u32,
}
