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
//! By part: this file (the trainer, its rollout and update), [`progress`] (statistics, curve,
//! validations), `envs` (the environments a run steps), `outputs` (validation, checkpoints, the bank).

mod envs;
mod outputs;
pub mod progress;

use envs::*;
pub use progress::*;

use std::collections::VecDeque;
use std::sync::Arc;
use std::time::Instant;

use candle_core::{Device, Tensor};
use rayon::prelude::*;
use sim::config::ArenaConfig;
use sim::model::Model;
use sim::rng::Rng;

use super::adam::{clip_grad_norm, Adam};
use super::gae::{gae, normalise, StepEnd};
use super::loss;
use super::normalizer::RunningNormalizer;
use super::policy::ActorCritic;
use super::{stream_seed, Method, Schedule, TrainConfig};
use crate::controller::ControllerSpec;

/// Episodes the rolling training statistics are taken over.
pub const RECENT_EPISODES: usize = 200;

/// Stream tags: which of a run's random streams a seed belongs to.
const STREAM_WEIGHTS: u64 = 1;
const STREAM_EPISODE: u64 = 2;
const STREAM_NOISE: u64 = 3;
const STREAM_MINIBATCH: u64 = 4;
const STREAM_BANK: u64 = 5;

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
}

/// Means over an update's minibatches.
#[derive(Debug, Clone, Copy, Default)]
struct Losses {
    kl: f64,
    surrogate: f64,
    value: f64,
    entropy: f64,
}
