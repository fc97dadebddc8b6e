//! The training loop: a rollout of `steps_per_env` control steps in every environment (stepped in
//! parallel with rayon, the policy run once per step on all of them), GAE, then PPO's update of
//! `epochs × minibatches` Adam steps, and the statistics of the episodes that ended.
//!
//! Determinism: the initial weights, every episode's serve and planner seeds, the action noise of an
//! iteration and its minibatch order each come from their own stream of the run's seed
//! (`stream_seed`). Every `checkpoint_every` iterations a *segment* begins with fresh episodes in
//! every environment, so the state saved there (weights, Adam, normaliser, statistics) is all a
//! resumed run needs to continue as the same run, bit for bit.

use std::collections::VecDeque;
use std::sync::Arc;
use std::time::Instant;

use candle_core::{Device, Tensor};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sim::config::ArenaConfig;
use sim::model::Model;
use sim::rng::Rng;

use super::adam::{clip_grad_norm, Adam};
use super::gae::{gae, normalise, StepEnd};
use super::loss;
use super::normalizer::RunningNormalizer;
use super::policy::ActorCritic;
use super::{stream_seed, Method, Schedule, TrainConfig, TrainEnv};
use crate::checkpoint::{Checkpoint, ObservationSpec, Training, TrainingPoint, FORMAT, VERSION};
use crate::controller::ControllerSpec;
use crate::env::{Env, EpisodeEnd, RallyEnv};
use crate::observation::ObsBlock;

/// Episodes the rolling training statistics are taken over.
pub const RECENT_EPISODES: usize = 200;

/// Stream tags: which of a run's random streams a seed belongs to.
const STREAM_WEIGHTS: u64 = 1;
const STREAM_EPISODE: u64 = 2;
const STREAM_NOISE: u64 = 3;
const STREAM_MINIBATCH: u64 = 4;
const STREAM_BANK: u64 = 5;

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
    /// The run directory this run's weights started from (a warm start), if any.
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

/// A training environment: a single serve (one robot) or a self-play rally (two).
enum TrainingEnv {
    Single(Box<Env>),
    Rally(Box<RallyEnv>),
}

/// What one robot's step gave.
struct AgentStep {
    reward: f64,
    done: bool,
    /// The episode reached its time limit (or cap) rather than a terminal state.
    time_limit: bool,
    hit: bool,
    success: bool,
    rally_length: u32,
    dual: f64,
    /// The position term, while the robot tracks a command before contact.
    tracking: Option<f64>,
    /// ‖a‖₁/n_a after the step.
    activation: f64,
}

impl TrainingEnv {
    fn reset(&mut self, seed: u64) {
        match self {
            TrainingEnv::Single(e) => {
                e.reset(seed);
            }
            TrainingEnv::Rally(e) => e.reset(seed),
        }
    }

    fn observe_into(&self, out: &mut Vec<f64>) {
        match self {
            TrainingEnv::Single(e) => out.extend_from_slice(e.observation()),
            TrainingEnv::Rally(e) => {
                out.extend_from_slice(e.observation(0));
                out.extend_from_slice(e.observation(1));
            }
        }
    }

    /// One control step with the rows of `actions` (one per robot).
    fn step(&mut self, actions: &[Vec<f64>]) -> Vec<AgentStep> {
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
                    rally_length: tr.success as u32,
                    dual: 0.0,
                    tracking,
                    activation: tr.terms.effort,
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
                    })
                    .collect()
            }
        }
    }
}

/// One robot's running episode.
#[derive(Debug, Clone, Copy, Default)]
struct Running {
    reward: f64,
    steps: u32,
    activation: f64,
    dual: f64,
}

/// An environment and its running episode.
struct Slot {
    env: TrainingEnv,
    /// Episodes begun in this segment.
    episode: u64,
    running: Vec<Running>,
}

/// What one robot's step gave the rollout.
struct StepOut {
    reward: f32,
    end: StepEnd,
    finished: Option<EpisodeStat>,
    tracking: Option<f64>,
}

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
    /// Counters, statistics, curve.
    pub progress: Progress,
    /// This process's time split.
    pub timing: Timing,
    /// The ball bank the last refresh recorded (`[bank] refresh_every`); `None`: the file's, if any.
    pub bank: Option<Arc<[sim::ball::BallState]>>,
    slots: Vec<Slot>,
    obs_dim: usize,
    act_dim: usize,
    /// Robots per environment.
    agents: usize,
    model: Arc<Model>,
    /// The arena configuration of the robot (its grip).
    pub arena: ArenaConfig,
    /// The robot's name as the command line gave it (`default`, `myochallenge`, a file).
    pub model_name: String,
}

/// The ball bank `[bank] file` names, read once for every environment; `None` without a file.
fn read_bank(config: &TrainConfig) -> Result<Option<crate::env::BallBank>, String> {
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
fn make_env(
    model: &Arc<Model>,
    arena: &ArenaConfig,
    controller: &ControllerSpec,
    config: &TrainConfig,
    bank: Option<&crate::env::BallBank>,
) -> Result<(TrainingEnv, usize, usize), String> {
    // Both environments: MyoChallenge contact laws, every observation block.
    let (preset, blocks) = (sim::arena::MYOCHALLENGE, ObsBlock::ALL.to_vec());
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
                config.reward,
                kind,
            )?;
            env.end = EpisodeEnd::Training;
            env.grip_floor = grip_floor;
            env.bank = bank.cloned();
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
                config.reward,
            )?;
            env.grip_floor = grip_floor;
            let (o, a) = (env.obs_dim(), env.action_dim());
            (TrainingEnv::Rally(Box::new(env)), o, a)
        }
    })
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
        let (_, obs_dim, act_dim) = make_env(&model, &arena, &controller, &config, bank.as_ref())?;
        let agents = config.env.agents();
        let p = &config.ppo;
        let net = ActorCritic::new(
            obs_dim,
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
            agents,
            config,
            model,
            arena,
            model_name: model_name.to_string(),
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

    /// One iteration: rollout, update, statistics. Returns the iteration's curve row.
    pub fn iterate(&mut self) -> Result<CurveRow, String> {
        let started = Instant::now();
        let p = self.config.ppo.clone();
        if self
            .progress
            .iteration
            .is_multiple_of(p.checkpoint_every as u64)
        {
            self.begin_segment();
        }
        // Rows: every robot of every environment (one per environment in the single serve).
        let (n_env, d, a_dim, t_len) = (
            p.envs * self.agents,
            self.obs_dim,
            self.act_dim,
            p.steps_per_env,
        );
        let agents = self.agents;
        let n = n_env * t_len;
        let mut obs_buf: Vec<f32> = Vec::with_capacity(n * d);
        let mut act_buf: Vec<f32> = Vec::with_capacity(n * a_dim);
        let mut mu_buf: Vec<f32> = Vec::with_capacity(n * a_dim);
        let mut logp_buf: Vec<f32> = Vec::with_capacity(n);
        let mut val_buf: Vec<f32> = Vec::with_capacity(n);
        let mut rew_buf: Vec<f32> = Vec::with_capacity(n);
        let mut end_buf: Vec<StepEnd> = Vec::with_capacity(n);
        let mut noise = Rng::seeded(stream_seed(
            self.seed,
            STREAM_NOISE,
            self.progress.iteration,
            0,
        ));
        let std: Vec<f32> = self.net.std().map_err(e)?;
        let log_std = self.net.log_std.as_tensor().detach();
        let mut tracking = Vec::new();
        let segment_start =
            self.progress.iteration - self.progress.iteration % p.checkpoint_every as u64;
        let (seed, scale) = (self.seed, p.reward_scale as f32);
        for _ in 0..t_len {
            let t0 = Instant::now();
            let raw = self.observations();
            self.normalizer.update(&raw);
            let obs = self.normalised(&raw);
            let x = Self::tensor(obs.clone(), n_env, d)?;
            let mean = self.net.mean(&x).map_err(e)?.detach();
            let value = self.net.value(&x).map_err(e)?.to_vec1::<f32>().map_err(e)?;
            let mean_v: Vec<f32> = mean.flatten_all().map_err(e)?.to_vec1().map_err(e)?;
            let actions: Vec<f32> = mean_v
                .iter()
                .enumerate()
                .map(|(i, &m)| m + std[i % a_dim] * noise.normal() as f32)
                .collect();
            let at = Self::tensor(actions.clone(), n_env, a_dim)?;
            let logp = loss::log_prob(&at, &mean, &log_std)
                .and_then(|l| l.to_vec1::<f32>())
                .map_err(e)?;
            self.timing.policy += t0.elapsed().as_secs_f64();
            let t1 = Instant::now();
            let outs: Vec<StepOut> = self
                .slots
                .par_iter_mut()
                .zip(actions.par_chunks(a_dim * agents))
                .enumerate()
                .flat_map_iter(|(k, (slot, a))| {
                    let rows: Vec<Vec<f64>> = a
                        .chunks(a_dim)
                        .map(|r| r.iter().map(|&x| (x as f64).clamp(-1.0, 1.0)).collect())
                        .collect();
                    let steps = slot.env.step(&rows);
                    let done = steps.iter().any(|s| s.done);
                    let outs: Vec<StepOut> = steps
                        .iter()
                        .zip(slot.running.iter_mut())
                        .map(|(st, run)| {
                            run.activation += st.activation;
                            run.reward += st.reward;
                            run.dual += st.dual;
                            run.steps += 1;
                            let end = if !done {
                                StepEnd::Running
                            } else if st.time_limit {
                                StepEnd::TimeLimit
                            } else {
                                StepEnd::Terminal
                            };
                            StepOut {
                                reward: st.reward as f32 * scale,
                                end,
                                finished: done.then(|| EpisodeStat {
                                    reward: run.reward,
                                    steps: run.steps,
                                    hit: st.hit,
                                    success: st.success,
                                    mean_activation: run.activation / run.steps.max(1) as f64,
                                    rally_length: st.rally_length,
                                    dual: run.dual,
                                }),
                                tracking: st.tracking,
                            }
                        })
                        .collect();
                    if done {
                        slot.episode += 1;
                        slot.env.reset(stream_seed(
                            seed,
                            STREAM_EPISODE,
                            segment_start,
                            ((k as u64) << 32) | slot.episode,
                        ));
                        slot.running.fill(Running::default());
                    }
                    outs
                })
                .collect();
            self.timing.simulation += t1.elapsed().as_secs_f64();
            obs_buf.extend(obs);
            act_buf.extend(actions);
            mu_buf.extend(mean_v);
            logp_buf.extend(logp);
            val_buf.extend(value);
            for o in outs {
                rew_buf.push(o.reward);
                end_buf.push(o.end);
                tracking.extend(o.tracking);
                if let Some(stat) = o.finished {
                    self.progress.episodes += 1;
                    self.progress.recent.push_back(stat);
                    if self.progress.recent.len() > RECENT_EPISODES {
                        self.progress.recent.pop_front();
                    }
                }
            }
        }
        let t2 = Instant::now();
        let last_obs = self.normalised(&self.observations());
        let last_values = self
            .net
            .value(&Self::tensor(last_obs, n_env, d)?)
            .and_then(|v| v.to_vec1::<f32>())
            .map_err(e)?;
        let adv = gae(
            &rew_buf,
            &val_buf,
            &end_buf,
            &last_values,
            p.gamma as f32,
            p.lambda as f32,
        );
        let losses = self.update(
            &obs_buf,
            &act_buf,
            &mu_buf,
            &logp_buf,
            &val_buf,
            &adv.advantages,
            &adv.returns,
            &log_std,
        )?;
        self.timing.update += t2.elapsed().as_secs_f64();
        self.timing.env_steps += n as u64;
        self.progress.iteration += 1;
        self.progress.env_steps += n as u64;
        self.progress.wall_s += started.elapsed().as_secs_f64();
        let recent = &self.progress.recent;
        let std_now = self.net.std().map_err(e)?;
        let row = CurveRow {
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
        };
        self.progress.curve.push(row);
        Ok(row)
    }

    #[allow(clippy::too_many_arguments)]
    fn update(
        &mut self,
        obs: &[f32],
        actions: &[f32],
        old_mu: &[f32],
        old_logp: &[f32],
        old_values: &[f32],
        advantages: &[f32],
        returns: &[f32],
        old_log_std: &Tensor,
    ) -> Result<Losses, String> {
        let p = self.config.ppo.clone();
        let (d, a_dim) = (self.obs_dim, self.act_dim);
        let n = old_logp.len();
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
                let idx = &order[k * mb..(k + 1) * mb];
                let gather = |src: &[f32], w: usize| -> Vec<f32> {
                    idx.iter()
                        .flat_map(|&i| src[i * w..(i + 1) * w].iter().copied())
                        .collect()
                };
                let obs_b = Self::tensor(gather(obs, d), mb, d)?;
                let act_b = Self::tensor(gather(actions, a_dim), mb, a_dim)?;
                let mu_old = Self::tensor(gather(old_mu, a_dim), mb, a_dim)?;
                let logp_old =
                    Tensor::from_vec(gather(old_logp, 1), mb, &Device::Cpu).map_err(e)?;
                let v_old = Tensor::from_vec(gather(old_values, 1), mb, &Device::Cpu).map_err(e)?;
                let ret = Tensor::from_vec(gather(returns, 1), mb, &Device::Cpu).map_err(e)?;
                let mut adv_b = gather(advantages, 1);
                normalise(&mut adv_b);
                let adv_t = Tensor::from_vec(adv_b, mb, &Device::Cpu).map_err(e)?;
                let mu = self.net.mean(&obs_b).map_err(e)?;
                let log_std = self.net.log_std.as_tensor();
                let kl = loss::gaussian_kl(&mu_old, old_log_std, &mu.detach(), &log_std.detach())
                    .and_then(|k| k.to_scalar::<f32>())
                    .map_err(e)? as f64;
                if p.schedule == Schedule::Adaptive {
                    if kl > 2.0 * p.desired_kl {
                        self.adam.lr = (self.adam.lr / 1.5).max(1e-5);
                    } else if kl < p.desired_kl / 2.0 && kl > 0.0 {
                        self.adam.lr = (self.adam.lr * 1.5).min(1e-2);
                    }
                }
                let logp = loss::log_prob(&act_b, &mu, log_std).map_err(e)?;
                let values = self.net.value(&obs_b).map_err(e)?;
                let surrogate =
                    loss::surrogate_loss(&logp, &logp_old, &adv_t, p.clip).map_err(e)?;
                let value = loss::value_loss(&values, &v_old, &ret, p.clip).map_err(e)?;
                let entropy = loss::entropy(log_std).map_err(e)?;
                let mut total = (&surrogate + (&value * p.value_coef).map_err(e)?)
                    .and_then(|t| t - (&entropy * p.entropy_coef)?)
                    .map_err(e)?;
                if p.bound_coef > 0.0 {
                    let bound = loss::bound_loss(&mu, p.bound).map_err(e)?;
                    total = (total + (bound * p.bound_coef).map_err(e)?).map_err(e)?;
                }
                let mut grads = total.backward().map_err(e)?;
                clip_grad_norm(&mut grads, &vars, p.max_grad_norm).map_err(e)?;
                self.adam.step(&grads).map_err(e)?;
                if let Some(cap) = p.std_cap(self.progress.env_steps) {
                    let ls = &self.net.log_std;
                    let capped = ls.as_tensor().clamp(f32::MIN, cap.ln() as f32).map_err(e)?;
                    ls.set(&capped).map_err(e)?;
                }
                let f = |t: &Tensor| t.to_scalar::<f32>().map(|x| x as f64).map_err(e);
                sums.kl += kl;
                sums.surrogate += f(&surrogate)?;
                sums.value += f(&value)?;
                sums.entropy += f(&entropy)?;
                count += 1.0;
            }
        }
        Ok(Losses {
            kl: sums.kl / count,
            surrogate: sums.surrogate / count,
            value: sums.value / count,
            entropy: sums.entropy / count,
        })
    }

    /// Plays the policy as a checkpoint would play it (its trained Gaussian, seeded per episode) on
    /// the validation's held-out episodes: self-play rallies in the rally environment (score: mean
    /// rally length), single serves of the training distribution otherwise (score: success rate).
    /// Reads the weights and the observation statistics, changes nothing.
    pub fn validate(&self) -> Result<ValidationPoint, String> {
        let v = &self.config.validation;
        let player = crate::factory::PlayerSpec::Checkpoint(Arc::new(self.validation_checkpoint(
            "validation",
            "",
            "",
        )?));
        let (config, preset) = (self.arena.clone(), sim::arena::MYOCHALLENGE);
        let (score, longest) = match self.config.validation_env() {
            TrainEnv::Rally => {
                let spec = self.match_spec(v.episodes as u32, v.seed);
                let lengths: Vec<u32> = crate::matchrun::play_rallies(&spec, &player, &player)?
                    .iter()
                    .map(|r| r.length)
                    .collect();
                (
                    mean_of(lengths.iter().map(|&l| l as f64)),
                    lengths.iter().copied().max().unwrap_or(0),
                )
            }
            TrainEnv::Single => {
                let e = crate::eval::Evaluation {
                    model: self.model.clone(),
                    config,
                    preset,
                    kind: self.config.serve.kind(),
                    episodes: v.episodes,
                    seed: v.seed,
                };
                let r = crate::eval::evaluate(&e, &player, &|| {})?;
                (r.success_rate.value, 0)
            }
        };
        Ok(ValidationPoint {
            iteration: self.progress.iteration,
            env_steps: self.progress.env_steps,
            score,
            episodes: v.episodes,
            longest,
        })
    }

    /// The checkpoint as validation plays it: [`Trainer::checkpoint`] with its noise scaled by
    /// `[validation] noise_scale` (what `best.json` holds).
    pub fn validation_checkpoint(
        &self,
        name: &str,
        command: &str,
        commit: &str,
    ) -> Result<Checkpoint, String> {
        let mut ck = self.checkpoint(name, command, commit)?;
        let scale = self.config.validation.noise_scale;
        if scale != 1.0 {
            ck.scale_noise(scale).map_err(|e| e.to_string())?;
        }
        Ok(ck)
    }

    /// A match of `rallies` rallies on `seed` in the run's arena (MyoChallenge contact laws),
    /// without replay: what validation and the bank's refresh play.
    fn match_spec(&self, rallies: u32, seed: u64) -> crate::matchrun::MatchSpec {
        crate::matchrun::MatchSpec {
            model: self.model.clone(),
            config: self.arena.clone(),
            preset: sim::arena::MYOCHALLENGE,
            rallies,
            seed,
            replay: false,
        }
    }

    /// Replaces the single-serve environments' ball bank with `balls` (served in `[bank] fraction`
    /// of the episodes from the next segment on).
    pub fn set_bank(&mut self, balls: Arc<[sim::ball::BallState]>) {
        let fraction = self.config.bank.fraction;
        for s in &mut self.slots {
            if let TrainingEnv::Single(env) = &mut s.env {
                env.bank = Some(crate::env::BallBank {
                    balls: balls.clone(),
                    fraction,
                });
            }
        }
        self.bank = Some(balls);
    }

    /// Records the policy's own legal returns in `[bank] refresh_rallies` self-play rallies (their
    /// seed from the run's seed and the iteration) and makes them the bank; returns how many. A
    /// policy that returned nothing keeps the old bank.
    pub fn refresh_bank(&mut self) -> Result<usize, String> {
        let player =
            crate::factory::PlayerSpec::Checkpoint(Arc::new(self.checkpoint("bank", "", "")?));
        let spec = self.match_spec(
            self.config.bank.refresh_rallies as u32,
            stream_seed(self.seed, STREAM_BANK, self.progress.iteration, 0),
        );
        let balls = crate::matchrun::record_returns(&spec, &player, &player)?;
        if !balls.is_empty() {
            self.set_bank(balls.clone().into());
        }
        Ok(balls.len())
    }

    /// The policy as a checkpoint in the agents' format, named `name`, with its provenance.
    pub fn checkpoint(
        &self,
        name: &str,
        command: &str,
        git_commit: &str,
    ) -> Result<Checkpoint, String> {
        let last = self.progress.curve.last().copied().unwrap_or_default();
        // At most ~200 points of the curve travel with the checkpoint.
        let stride = self.progress.curve.len().div_ceil(200).max(1);
        let curve = self
            .progress
            .curve
            .iter()
            .enumerate()
            .filter(|(i, r)| {
                r.episodes > 0 && ((i + 1) % stride == 0 || i + 1 == self.progress.curve.len())
            })
            .map(|(_, r)| TrainingPoint {
                env_steps: r.env_steps,
                reward: r.reward,
                hit_rate: r.hit_rate,
                success_rate: r.success_rate,
            })
            .collect();
        Ok(Checkpoint {
            format: FORMAT.into(),
            version: VERSION,
            name: name.into(),
            controller: self.controller.clone(),
            observation: ObservationSpec {
                blocks: ObsBlock::ALL.to_vec(),
                mean: self.normalizer.mean.clone(),
                std: self.normalizer.scale(),
            },
            policy: Some(self.net.actor_mlp().map_err(e)?),
            onnx: None,
            policy_std: Some(
                self.net
                    .std()
                    .map_err(e)?
                    .iter()
                    .map(|&s| s as f64)
                    .collect(),
            ),
            grip_floor: (self.config.controller.grip_floor > 0.0)
                .then_some(self.config.controller.grip_floor),
            training: Some(Training {
                method: self.method.name().into(),
                command: command.into(),
                seed: self.seed,
                git_commit: git_commit.into(),
                env_steps: self.progress.env_steps,
                iterations: self.progress.iteration,
                wall_seconds: self.progress.wall_s,
                hit_rate: last.hit_rate,
                success_rate: last.success_rate,
                episodes: self.progress.recent.len() as u64,
                curve,
                env: self.config.env.name().into(),
                warm_start: self.progress.warm_start.clone(),
                rally_length: (self.config.env == TrainEnv::Rally).then_some(last.rally_length),
                note: None,
                noise_scale: None,
            }),
        })
    }
}

/// Means over an update's minibatches.
#[derive(Debug, Clone, Copy, Default)]
struct Losses {
    kl: f64,
    surrogate: f64,
    value: f64,
    entropy: f64,
}
