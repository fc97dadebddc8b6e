//! The training loop: a rollout of `steps_per_env` control steps in every environment (stepped in
//! parallel with rayon, the policy run once per step on all of them), GAE, then PPO's update of
//! `epochs × minibatches` Adam steps, and the statistics of the episodes that ended.
//!
//! Determinism: the initial weights, every episode's serve and planner seeds, the action noise of an
//! iteration and its minibatch order each come from their own stream of the run's seed
//! (`stream_seed`). Every `checkpoint_every` iterations a *segment* begins with fresh episodes in
//! every environment, so the state saved there (weights, Adam, normaliser, statistics) is all a
//! resumed run needs to continue as the same run, bit for bit.
//!
//! By part: this file (the trainer, advantages and update), `rollout` (the rollout and the
//! environments' running episodes), [`progress`] (statistics, curve, validations), `envs` (the
//! environments a run steps), `outputs` (validation, checkpoints, the bank).

pub mod envs;
mod outputs;
pub mod progress;
mod rollout;
mod warm;

use envs::*;
pub use progress::*;
use rollout::{Rollout, Running, Slot};

use std::collections::VecDeque;
use std::sync::Arc;
use std::time::Instant;

use candle_core::{Device, Tensor, Var};
use rayon::prelude::*;
use sim::config::ArenaConfig;
use sim::model::Model;
use sim::rng::Rng;

use super::adam::{clip_grad_norm, Adam};
use super::gae::{gae, normalise, Advantages};
use super::loss;
use super::normalizer::RunningNormalizer;
use super::policy::ActorCritic;
use super::{stream_seed, CriticInput, Method, PpoConfig, Schedule, TrainConfig};
use crate::controller::ControllerSpec;

/// Episodes the rolling training statistics are taken over.
pub const RECENT_EPISODES: usize = 200;

/// Stream tags: which of a run's random streams a seed belongs to.
const STREAM_WEIGHTS: u64 = 1;
const STREAM_EPISODE: u64 = 2;
const STREAM_NOISE: u64 = 3;
const STREAM_MINIBATCH: u64 = 4;
const STREAM_BANK: u64 = 5;

/// A PPO run in progress.
pub struct Trainer {
    /// The method trained.
    pub method: Method,
    /// Its configuration.
    pub config: TrainConfig,
    /// The run's seed.
    pub seed: u64,
    /// The controller the checkpoints carry.
    pub controller: ControllerSpec,
    /// Actor and critic.
    pub net: ActorCritic,
    /// The optimiser.
    pub adam: Adam,
    /// Observation statistics.
    pub normalizer: RunningNormalizer,
    /// Statistics of what only the critic sees (`ppo.critic = "privileged"`; else `None`).
    pub critic_normalizer: Option<RunningNormalizer>,
    /// Counters, statistics, curve.
    pub progress: Progress,
    /// This process's time split.
    pub timing: Timing,
    /// The ball bank the last refresh recorded (`[bank] refresh_every`); `None`: the file's, if any.
    pub bank: Option<Arc<[sim::ball::BallState]>>,
    slots: Vec<Slot>,
    obs_dim: usize,
    act_dim: usize,
    /// Entries only the critic sees, after the observation (0: it sees the actor's).
    extra_dim: usize,
    /// Robots per environment.
    agents: usize,
    model: Arc<Model>,
    /// The arena configuration of the robot (its grip).
    pub arena: ArenaConfig,
    /// The robot's name as the command line gave it (`default`, `myochallenge`, a file).
    pub model_name: String,
    /// The env steps the run is to reach (`rally train --steps`): where the `linear_decay`
    /// schedule reaches zero (0: unknown, the schedule keeps `learning_rate`).
    pub steps_target: u64,
}

fn e(err: candle_core::Error) -> String {
    format!("tensor error: {err}")
}

fn mean_of(xs: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = xs.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    if n == 0 {
        0.0
    } else {
        s / n as f64
    }
}

impl Trainer {
    /// A fresh run of `method` on `model` (the built-in body's arena, see [`Trainer::on`]).
    pub fn new(
        model: Arc<Model>,
        method: Method,
        config: TrainConfig,
        seed: u64,
    ) -> Result<Trainer, String> {
        Trainer::on(
            model,
            ArenaConfig::default(),
            "default",
            method,
            config,
            seed,
        )
    }

    /// A fresh run of `method` on `model` in the arena `arena` configures (its grip); `model_name`
    /// is what the run records, so that `--resume` refuses another robot.
    pub fn on(
        model: Arc<Model>,
        arena: ArenaConfig,
        model_name: &str,
        method: Method,
        config: TrainConfig,
        seed: u64,
    ) -> Result<Trainer, String> {
        config.validate()?;
        let controller = config.controller(method, &model);
        let bank = read_bank(&config)?;
        let (env, obs_dim, act_dim) =
            make_env(&model, &arena, &controller, &config, bank.as_ref())?;
        let extra_dim = match config.ppo.critic {
            CriticInput::Actor => 0,
            CriticInput::Privileged => env.privileged_dim(),
        };
        let agents = config.env.agents();
        let p = &config.ppo;
        let net = ActorCritic::new(
            obs_dim,
            obs_dim + extra_dim,
            act_dim,
            &p.hidden,
            p.init_std,
            stream_seed(seed, STREAM_WEIGHTS, 0, 0),
        )
        .map_err(e)?;
        let adam = Adam::new(net.vars(), p.learning_rate).map_err(e)?;
        let slots = (0..p.envs)
            .map(|_| {
                Ok(Slot {
                    env: make_env(&model, &arena, &controller, &config, bank.as_ref())?.0,
                    episode: 0,
                    running: vec![Running::default(); agents],
                })
            })
            .collect::<Result<Vec<_>, String>>()?;
        Ok(Trainer {
            method,
            seed,
            controller,
            net,
            adam,
            normalizer: RunningNormalizer::new(obs_dim),
            critic_normalizer: (extra_dim > 0).then(|| RunningNormalizer::new(extra_dim)),
            progress: Progress {
                iteration: 0,
                env_steps: 0,
                wall_s: 0.0,
                episodes: 0,
                recent: VecDeque::new(),
                curve: Vec::new(),
                warm_start: None,
                validations: Vec::new(),
            },
            timing: Timing::default(),
            bank: None,
            slots,
            obs_dim,
            act_dim,
            extra_dim,
            agents,
            config,
            model,
            arena,
            model_name: model_name.to_string(),
            steps_target: 0,
        })
    }

    /// Observation entries.
    pub fn obs_dim(&self) -> usize {
        self.obs_dim
    }

    /// Action entries.
    pub fn act_dim(&self) -> usize {
        self.act_dim
    }

    /// Starts a segment: every environment begins a fresh episode.
    fn begin_segment(&mut self) {
        let (seed, it) = (self.seed, self.progress.iteration);
        self.slots.par_iter_mut().enumerate().for_each(|(k, s)| {
            s.episode = 0;
            s.env
                .reset(stream_seed(seed, STREAM_EPISODE, it, (k as u64) << 32));
            s.running.fill(Running::default());
        });
    }

    /// Raw observations of every robot of every environment, `[envs·agents, obs]` row-major.
    fn observations(&self) -> Vec<f64> {
        let mut out = Vec::with_capacity(self.slots.len() * self.agents * self.obs_dim);
        for s in &self.slots {
            s.env.observe_into(&mut out);
        }
        out
    }

    /// What only the critic sees, raw, `[envs·agents, extra]` row-major (empty when it sees the
    /// actor's observation).
    fn privileged(&self) -> Vec<f64> {
        let mut out = Vec::with_capacity(self.slots.len() * self.agents * self.extra_dim);
        if self.extra_dim > 0 {
            for s in &self.slots {
                s.env.privileged_into(&mut out);
            }
        }
        out
    }

    /// `raw` privileged rows normalised by the critic's statistics.
    fn normalised_extra(&self, raw: &[f64]) -> Vec<f32> {
        let Some(norm) = &self.critic_normalizer else {
            return Vec::new();
        };
        let mut out = Vec::with_capacity(raw.len());
        for row in raw.chunks(self.extra_dim) {
            let mut r = row.to_vec();
            norm.apply(&mut r);
            out.extend(r.iter().map(|&x| x as f32));
        }
        out
    }

    /// The critic's input for `rows` rows: each normalised observation row of `obs`, followed by
    /// its row of `extra` when the critic is privileged.
    fn critic_input(&self, obs: Vec<f32>, extra: &[f32], rows: usize) -> Result<Tensor, String> {
        let (d, x) = (self.obs_dim, self.extra_dim);
        if x == 0 {
            return Self::tensor(obs, rows, d);
        }
        let mut joined = Vec::with_capacity(rows * (d + x));
        for (o, p) in obs.chunks(d).zip(extra.chunks(x)) {
            joined.extend_from_slice(o);
            joined.extend_from_slice(p);
        }
        Self::tensor(joined, rows, d + x)
    }

    fn tensor(data: Vec<f32>, rows: usize, cols: usize) -> Result<Tensor, String> {
        Tensor::from_vec(data, (rows, cols), &Device::Cpu).map_err(e)
    }

    fn normalised(&self, raw: &[f64]) -> Vec<f32> {
        let d = self.obs_dim;
        let mut out = Vec::with_capacity(raw.len());
        for row in raw.chunks(d) {
            let mut r = row.to_vec();
            self.normalizer.apply(&mut r);
            out.extend(r.iter().map(|&x| x as f32));
        }
        out
    }

    /// One iteration: rollout, advantages, update, statistics. Returns the iteration's curve row.
    pub fn iterate(&mut self) -> Result<CurveRow, String> {
        let started = Instant::now();
        if self
            .progress
            .iteration
            .is_multiple_of(self.config.ppo.checkpoint_every as u64)
        {
            self.begin_segment();
        }
        if self.config.ppo.schedule == Schedule::LinearDecay {
            self.adam.lr = self.linear_decay_lr();
        }
        let log_std = self.net.log_std.as_tensor().detach();
        let rollout = self.collect(&log_std)?;
        let t2 = Instant::now();
        let adv = self.advantages(&rollout)?;
        let losses = self.update(&rollout, &adv, &log_std)?;
        if !self.parameters_finite()? {
            return Err(format!(
                "iteration {}: the network's parameters are no longer finite (nothing of this \
                 iteration is saved; --resume continues from the last saved state)",
                self.progress.iteration + 1
            ));
        }
        self.timing.update += t2.elapsed().as_secs_f64();
        let n = rollout.len() as u64;
        self.timing.env_steps += n;
        self.progress.iteration += 1;
        self.progress.env_steps += n;
        self.progress.wall_s += started.elapsed().as_secs_f64();
        let row = self.curve_row(&losses, rollout.tracking)?;
        self.progress.curve.push(row);
        Ok(row)
    }

    /// Whether every parameter of the policy and critic is finite.
    fn parameters_finite(&self) -> Result<bool, String> {
        for v in self.net.vars() {
            let sum = v.as_tensor().abs().and_then(|t| t.sum_all());
            if !sum
                .and_then(|t| t.to_scalar::<f32>())
                .map_err(e)?
                .is_finite()
            {
                return Ok(false);
            }
        }
        Ok(true)
    }

    /// The `linear_decay` schedule's rate at the steps done: `learning_rate` scaled by the share
    /// of `steps_target` still to go.
    pub fn linear_decay_lr(&self) -> f64 {
        let lr = self.config.ppo.learning_rate;
        if self.steps_target == 0 {
            return lr;
        }
        let left = 1.0 - self.progress.env_steps as f64 / self.steps_target as f64;
        lr * left.max(0.0)
    }

    /// GAE over the rollout, bootstrapped from the critic's values of the observations after it.
    fn advantages(&self, rollout: &Rollout) -> Result<Advantages, String> {
        let p = &self.config.ppo;
        let last_obs = self.normalised(&self.observations());
        let last_extra = self.normalised_extra(&self.privileged());
        let last_values = self
            .net
            .value(&self.critic_input(last_obs, &last_extra, p.envs * self.agents)?)
            .and_then(|v| v.to_vec1::<f32>())
            .map_err(e)?;
        Ok(gae(
            &rollout.rewards,
            &rollout.values,
            &rollout.ends,
            &last_values,
            p.gamma as f32,
            p.lambda as f32,
        ))
    }

    /// The curve row of the iteration just done: the rolling episode statistics, the mean of the
    /// rollout's `tracking` terms, the update's `losses` and the policy's noise now.
    fn curve_row(&self, losses: &Losses, tracking: Vec<f64>) -> Result<CurveRow, String> {
        let recent = &self.progress.recent;
        let std_now = self.net.std().map_err(e)?;
        Ok(CurveRow {
            iteration: self.progress.iteration,
            env_steps: self.progress.env_steps,
            wall_s: self.progress.wall_s,
            episodes: self.progress.episodes,
            reward: mean_of(recent.iter().map(|s| s.reward)),
            length: mean_of(recent.iter().map(|s| s.steps as f64)),
            hit_rate: mean_of(recent.iter().map(|s| s.hit as u8 as f64)),
            success_rate: mean_of(recent.iter().map(|s| s.success as u8 as f64)),
            mean_activation: mean_of(recent.iter().map(|s| s.mean_activation)),
            tracking: mean_of(tracking.into_iter()),
            learning_rate: self.adam.lr,
            kl: losses.kl,
            value_loss: losses.value,
            surrogate_loss: losses.surrogate,
            entropy: losses.entropy,
            std: mean_of(std_now.iter().map(|&s| s as f64)),
            rally_length: mean_of(recent.iter().map(|s| s.rally_length as f64)),
            dual: mean_of(recent.iter().map(|s| s.dual)),
            skipped_steps: losses.skipped,
        })
    }

    /// PPO's update: `epochs` passes over the rollout in shuffled minibatches (the minibatch
    /// stream of the iteration), one Adam step each. Returns the means of the losses.
    fn update(
        &mut self,
        rollout: &Rollout,
        adv: &Advantages,
        old_log_std: &Tensor,
    ) -> Result<Losses, String> {
        let p = self.config.ppo.clone();
        let n = rollout.len();
        let mb = n / p.minibatches;
        let mut rng = Rng::seeded(stream_seed(
            self.seed,
            STREAM_MINIBATCH,
            self.progress.iteration,
            0,
        ));
        let vars = self.net.vars();
        let mut sums = Losses::default();
        let mut count = 0.0;
        for _ in 0..p.epochs {
            // Fisher–Yates on the portable stream.
            let mut order: Vec<usize> = (0..n).collect();
            for i in (1..n).rev() {
                let j = (rng.unit() * (i + 1) as f64) as usize;
                order.swap(i, j.min(i));
            }
            for k in 0..p.minibatches {
                let batch = self.minibatch(rollout, adv, &order[k * mb..(k + 1) * mb])?;
                let losses = self.step_on(&batch, old_log_std, &vars, &p)?;
                if losses.skipped > 0 {
                    sums.skipped += losses.skipped;
                    continue;
                }
                sums.kl += losses.kl;
                sums.surrogate += losses.surrogate;
                sums.value += losses.value;
                sums.entropy += losses.entropy;
                count += 1.0;
            }
        }
        Ok(Losses {
            kl: sums.kl / count,
            surrogate: sums.surrogate / count,
            value: sums.value / count,
            entropy: sums.entropy / count,
            skipped: sums.skipped,
        })
    }

    /// The rows `idx` of the rollout as tensors, their advantages normalised.
    fn minibatch(
        &self,
        rollout: &Rollout,
        adv: &Advantages,
        idx: &[usize],
    ) -> Result<Minibatch, String> {
        let (d, a_dim, mb) = (self.obs_dim, self.act_dim, idx.len());
        let gather = |src: &[f32], w: usize| -> Vec<f32> {
            idx.iter()
                .flat_map(|&i| src[i * w..(i + 1) * w].iter().copied())
                .collect()
        };
        let column = |v: Vec<f32>| Tensor::from_vec(v, mb, &Device::Cpu).map_err(e);
        let obs_rows = gather(&rollout.obs, d);
        let critic_obs = if self.extra_dim > 0 {
            let extra = gather(&rollout.extra, self.extra_dim);
            Some(self.critic_input(obs_rows.clone(), &extra, mb)?)
        } else {
            None
        };
        let obs = Self::tensor(obs_rows, mb, d)?;
        let critic_obs = critic_obs.unwrap_or_else(|| obs.clone());
        let actions = Self::tensor(gather(&rollout.actions, a_dim), mb, a_dim)?;
        let old_means = Self::tensor(gather(&rollout.means, a_dim), mb, a_dim)?;
        let old_logp = column(gather(&rollout.logp, 1))?;
        let old_values = column(gather(&rollout.values, 1))?;
        let returns = column(gather(&adv.returns, 1))?;
        let mut advantages = gather(&adv.advantages, 1);
        normalise(&mut advantages);
        Ok(Minibatch {
            obs,
            critic_obs,
            actions,
            old_means,
            old_logp,
            old_values,
            returns,
            advantages: column(advantages)?,
        })
    }

    /// One Adam step on a minibatch (after the adaptive schedule has looked at its KL), then the
    /// cap on the policy's noise. Returns the minibatch's losses.
    fn step_on(
        &mut self,
        b: &Minibatch,
        old_log_std: &Tensor,
        vars: &[Var],
        p: &PpoConfig,
    ) -> Result<Losses, String> {
        let mu = self.net.mean(&b.obs).map_err(e)?;
        let log_std = self.net.log_std.as_tensor();
        let kl = loss::gaussian_kl(&b.old_means, old_log_std, &mu.detach(), &log_std.detach())
            .and_then(|k| k.to_scalar::<f32>())
            .map_err(e)? as f64;
        // While only the critic learns the policy keeps still: its KL says nothing to the schedule.
        let critic_only = self.progress.iteration < p.critic_warmup;
        if p.schedule == Schedule::Adaptive && !critic_only {
            if kl > 2.0 * p.desired_kl {
                self.adam.lr = (self.adam.lr / 1.5).max(1e-5);
            } else if kl < p.desired_kl / 2.0 && kl > 0.0 {
                self.adam.lr = (self.adam.lr * 1.5).min(1e-2);
            }
        }
        let logp = loss::log_prob(&b.actions, &mu, log_std).map_err(e)?;
        let values = self.net.value(&b.critic_obs).map_err(e)?;
        let surrogate =
            loss::surrogate_loss(&logp, &b.old_logp, &b.advantages, p.clip).map_err(e)?;
        let value = loss::value_loss(&values, &b.old_values, &b.returns, p.clip).map_err(e)?;
        let entropy = loss::entropy(log_std).map_err(e)?;
        let mut total = if critic_only {
            // The policy's terms are left out of the graph: its variables get no gradient, and
            // Adam leaves a variable without one as it is (its first step after the warm-up is a
            // fresh Adam's: the bias correction counts each variable's own steps).
            (&value * p.value_coef).map_err(e)?
        } else {
            (&surrogate + (&value * p.value_coef).map_err(e)?)
                .and_then(|t| t - (&entropy * p.entropy_coef)?)
                .map_err(e)?
        };
        if p.bound_coef > 0.0 && !critic_only {
            let bound = loss::bound_loss(&mu, p.bound).map_err(e)?;
            total = (total + (bound * p.bound_coef).map_err(e)?).map_err(e)?;
        }
        let mut grads = total.backward().map_err(e)?;
        let norm = clip_grad_norm(&mut grads, vars, p.max_grad_norm).map_err(e)?;
        if !norm.is_finite() {
            // Adam would carry the inf or NaN into every parameter it touches, for good: the
            // step is skipped (the curve's `skipped` counts it), as mixed-precision scalers do.
            return Ok(Losses {
                skipped: 1,
                ..Losses::default()
            });
        }
        self.adam.step(&grads).map_err(e)?;
        if let Some(cap) = p.std_cap(self.progress.env_steps).filter(|_| !critic_only) {
            let ls = &self.net.log_std;
            let capped = ls.as_tensor().clamp(f32::MIN, cap.ln() as f32).map_err(e)?;
            ls.set(&capped).map_err(e)?;
        }
        let f = |t: &Tensor| t.to_scalar::<f32>().map(|x| x as f64).map_err(e);
        Ok(Losses {
            kl,
            surrogate: f(&surrogate)?,
            value: f(&value)?,
            entropy: f(&entropy)?,
            skipped: 0,
        })
    }
}

/// A minibatch of the rollout: its rows, what the policy and critic gave them, their targets.
struct Minibatch {
    obs: Tensor,
    /// What the critic reads: `obs`, or `obs` and the privileged rows.
    critic_obs: Tensor,
    actions: Tensor,
    old_means: Tensor,
    old_logp: Tensor,
    old_values: Tensor,
    returns: Tensor,
    /// Normalised over the minibatch.
    advantages: Tensor,
}

/// Means over an update's minibatches.
#[derive(Debug, Clone, Copy, Default)]
struct Losses {
    kl: f64,
    surrogate: f64,
    value: f64,
    entropy: f64,
    /// Minibatch steps skipped: their gradient was not finite (the means leave them out).
    skipped: u64,
}
