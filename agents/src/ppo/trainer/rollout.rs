//! An iteration's rollout: `steps_per_env` control steps of every robot of every environment, the
//! policy run once per step on all of them and the environments stepped in parallel with rayon.

use std::time::Instant;

use candle_core::Tensor;
use rayon::prelude::*;
use sim::rng::Rng;

use super::envs::{AgentStep, TrainingEnv};
use super::{e, EpisodeStat, Trainer, RECENT_EPISODES, STREAM_EPISODE, STREAM_NOISE};
use crate::ppo::gae::StepEnd;
use crate::ppo::{loss, stream_seed};

/// One robot's running episode.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Running {
    reward: f64,
    steps: u32,
    activation: f64,
    dual: f64,
}

/// An environment and its running episode.
pub(super) struct Slot {
    pub(super) env: TrainingEnv,
    /// Episodes begun in this segment.
    pub(super) episode: u64,
    pub(super) running: Vec<Running>,
}

/// What one robot's step gave the rollout.
struct StepOut {
    reward: f32,
    end: StepEnd,
    finished: Option<EpisodeStat>,
    tracking: Option<f64>,
}

/// What the policy did at one control step, one row per robot.
struct Acted {
    /// Normalised observations, `[rows, obs]`.
    obs: Vec<f32>,
    /// The actions sampled (before clamping), `[rows, act]`.
    actions: Vec<f32>,
    /// The policy's means, `[rows, act]`.
    means: Vec<f32>,
    /// Log-probabilities of the actions.
    logp: Vec<f32>,
    /// The critic's values.
    values: Vec<f32>,
    /// What only the critic saw, normalised, `[rows, extra]` (empty: it sees the observation).
    extra: Vec<f32>,
}

/// The rollout of an iteration: one row per robot and control step, step-major (every robot of
/// step 0, then of step 1, ...), as GAE and the update read it.
pub(super) struct Rollout {
    /// Normalised observations, `[rows, obs]`.
    pub(super) obs: Vec<f32>,
    /// The actions sampled (before clamping), `[rows, act]`.
    pub(super) actions: Vec<f32>,
    /// The policy's means, `[rows, act]`.
    pub(super) means: Vec<f32>,
    /// Log-probabilities of the actions.
    pub(super) logp: Vec<f32>,
    /// The critic's values.
    pub(super) values: Vec<f32>,
    /// What only the critic saw, normalised, `[rows, extra]` (empty: it sees the observation).
    pub(super) extra: Vec<f32>,
    /// Rewards, scaled by `reward_scale`.
    pub(super) rewards: Vec<f32>,
    /// How each step ended.
    pub(super) ends: Vec<StepEnd>,
    /// The tracking terms of the steps that had one (a statistic, not trained on).
    pub(super) tracking: Vec<f64>,
}

impl Rollout {
    /// An empty rollout with room for `rows` rows.
    fn with_capacity(rows: usize, obs_dim: usize, act_dim: usize) -> Rollout {
        Rollout {
            obs: Vec::with_capacity(rows * obs_dim),
            actions: Vec::with_capacity(rows * act_dim),
            means: Vec::with_capacity(rows * act_dim),
            logp: Vec::with_capacity(rows),
            values: Vec::with_capacity(rows),
            extra: Vec::new(),
            rewards: Vec::with_capacity(rows),
            ends: Vec::with_capacity(rows),
            tracking: Vec::new(),
        }
    }

    /// Appends a control step: what the policy did and what each robot's step gave. Returns the
    /// episodes that ended, in row order.
    fn push(&mut self, acted: Acted, outs: Vec<StepOut>) -> Vec<EpisodeStat> {
        self.obs.extend(acted.obs);
        self.actions.extend(acted.actions);
        self.means.extend(acted.means);
        self.logp.extend(acted.logp);
        self.values.extend(acted.values);
        self.extra.extend(acted.extra);
        let mut finished = Vec::new();
        for o in outs {
            self.rewards.push(o.reward);
            self.ends.push(o.end);
            self.tracking.extend(o.tracking);
            finished.extend(o.finished);
        }
        finished
    }

    /// Rows: control steps of all robots.
    pub(super) fn len(&self) -> usize {
        self.logp.len()
    }
}

impl Running {
    /// Adds one step of a robot to its episode; `done`: the environment's episode ended with it.
    fn add(&mut self, st: &AgentStep, done: bool, reward_scale: f32) -> StepOut {
        self.activation += st.activation;
        self.reward += st.reward;
        self.dual += st.dual;
        self.steps += 1;
        let end = if !done {
            StepEnd::Running
        } else if st.time_limit {
            StepEnd::TimeLimit
        } else {
            StepEnd::Terminal
        };
        StepOut {
            reward: st.reward as f32 * reward_scale,
            end,
            finished: done.then(|| EpisodeStat {
                reward: self.reward,
                steps: self.steps,
                hit: st.hit,
                success: st.success,
                mean_activation: self.activation / self.steps.max(1) as f64,
                rally_length: st.rally_length,
                dual: self.dual,
            }),
            tracking: st.tracking,
        }
    }
}

impl Slot {
    /// Steps the environment with one row of `act_dim` actions per robot (clamped to [-1, 1]);
    /// when its episode ends the next one begins, with the seed `episode_seed` gives its number.
    fn step(
        &mut self,
        actions: &[f32],
        act_dim: usize,
        reward_scale: f32,
        episode_seed: impl Fn(u64) -> u64,
    ) -> Vec<StepOut> {
        let rows: Vec<Vec<f64>> = actions
            .chunks(act_dim)
            .map(|r| r.iter().map(|&x| (x as f64).clamp(-1.0, 1.0)).collect())
            .collect();
        let steps = self.env.step(&rows);
        let done = steps.iter().any(|s| s.done);
        let outs: Vec<StepOut> = steps
            .iter()
            .zip(self.running.iter_mut())
            .map(|(st, run)| run.add(st, done, reward_scale))
            .collect();
        if done {
            self.episode += 1;
            self.env.reset(episode_seed(self.episode));
            self.running.fill(Running::default());
        }
        outs
    }
}

impl Trainer {
    /// The iteration's rollout; `log_std` is the policy's noise, fixed for the iteration. Adds the
    /// episodes that ended to the statistics and the time spent to `timing`.
    pub(super) fn collect(&mut self, log_std: &Tensor) -> Result<Rollout, String> {
        let p = &self.config.ppo;
        let (rows, steps) = (p.envs * self.agents, p.steps_per_env);
        let mut rollout = Rollout::with_capacity(rows * steps, self.obs_dim, self.act_dim);
        let mut noise = Rng::seeded(stream_seed(
            self.seed,
            STREAM_NOISE,
            self.progress.iteration,
            0,
        ));
        let std: Vec<f32> = self.net.std().map_err(e)?;
        for _ in 0..steps {
            let t0 = Instant::now();
            let acted = self.act(&std, log_std, &mut noise)?;
            self.timing.policy += t0.elapsed().as_secs_f64();
            let t1 = Instant::now();
            let outs = self.step_envs(&acted.actions);
            self.timing.simulation += t1.elapsed().as_secs_f64();
            for stat in rollout.push(acted, outs) {
                self.progress.episodes += 1;
                self.progress.recent.push_back(stat);
                if self.progress.recent.len() > RECENT_EPISODES {
                    self.progress.recent.pop_front();
                }
            }
        }
        Ok(rollout)
    }

    /// The policy on every robot's observation: updates the normaliser with the raw observations,
    /// then samples the actions (noise `std`, drawn from `noise` in row order).
    fn act(&mut self, std: &[f32], log_std: &Tensor, noise: &mut Rng) -> Result<Acted, String> {
        let (rows, d, a_dim) = (
            self.config.ppo.envs * self.agents,
            self.obs_dim,
            self.act_dim,
        );
        let raw = self.observations();
        self.normalizer.update(&raw);
        let obs = self.normalised(&raw);
        let raw_extra = self.privileged();
        if let Some(norm) = self.critic_normalizer.as_mut() {
            norm.update(&raw_extra);
        }
        let extra = self.normalised_extra(&raw_extra);
        let x = Self::tensor(obs.clone(), rows, d)?;
        let mean = self.net.mean(&x).map_err(e)?.detach();
        let values = if self.extra_dim > 0 {
            self.net
                .value(&self.critic_input(obs.clone(), &extra, rows)?)
        } else {
            self.net.value(&x)
        };
        let values = values.map_err(e)?.to_vec1::<f32>().map_err(e)?;
        let means: Vec<f32> = mean.flatten_all().map_err(e)?.to_vec1().map_err(e)?;
        let actions: Vec<f32> = means
            .iter()
            .enumerate()
            .map(|(i, &m)| m + std[i % a_dim] * noise.normal() as f32)
            .collect();
        let at = Self::tensor(actions.clone(), rows, a_dim)?;
        let logp = loss::log_prob(&at, &mean, log_std)
            .and_then(|l| l.to_vec1::<f32>())
            .map_err(e)?;
        Ok(Acted {
            obs,
            actions,
            means,
            logp,
            values,
            extra,
        })
    }

    /// Steps every environment (in parallel) with its robots' rows of `actions`; an episode that
    /// ends is followed by the next, seeded from the segment and its number.
    fn step_envs(&mut self, actions: &[f32]) -> Vec<StepOut> {
        let p = &self.config.ppo;
        let segment_start =
            self.progress.iteration - self.progress.iteration % p.checkpoint_every as u64;
        let (seed, scale) = (self.seed, p.reward_scale as f32);
        let (a_dim, agents) = (self.act_dim, self.agents);
        self.slots
            .par_iter_mut()
            .zip(actions.par_chunks(a_dim * agents))
            .enumerate()
            .flat_map_iter(|(k, (slot, a))| {
                slot.step(a, a_dim, scale, |episode| {
                    stream_seed(
                        seed,
                        STREAM_EPISODE,
                        segment_start,
                        ((k as u64) << 32) | episode,
                    )
                })
            })
            .collect()
    }
}
