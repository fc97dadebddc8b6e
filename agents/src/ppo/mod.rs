//! PPO (Schulman et al. 2017) with rsl_rl's semantics (docs/design.md §11), on candle: GAE, the clipped
//! surrogate and value losses, an entropy bonus, Adam with gradient-norm clipping, per-minibatch
//! advantage normalisation, empirical observation normalisation, a Gaussian policy with a learned
//! σ and the adaptive-KL learning rate. Environments step in parallel (rayon) and the policy runs
//! once per step on all of them.
//!
//! - `gae`, `loss`, `normalizer`, `adam`: the algorithm's pieces, each tested against closed forms.
//! - `policy`: the actor-critic network.
//! - `trainer`: the training loop (rollout, update, statistics), deterministic in its seed.
//! - `store`: a run's directory — resumable state, the checkpoint, the learning curve.

pub mod adam;
pub mod gae;
pub mod loss;
pub mod normalizer;
pub mod policy;
pub mod store;
pub mod trainer;

use serde::{Deserialize, Serialize};

/// candle's own knob for its element-wise worker threads: how long each spins for more work before it
/// sleeps.
const SPIN_LIMIT: &str = "CANDLE_BARRIER_POOL_SPIN_LIMIT";

/// Settles, once, how candle uses the machine's threads while training.
///
/// - Matrix products: unless `RAYON_NUM_THREADS` is set, candle works their thread count out again
///   before every product, on Linux by reading `/proc/cpuinfo` (`num_cpus::get_physical`): 2 200
///   reads in a 6 s `rally bench train` here, a few per policy forward. This builds rayon's global
///   pool first (its size unchanged: `RAYON_NUM_THREADS` if the user set it, else every logical CPU)
///   and then sets `RAYON_NUM_THREADS` to the count candle would have chosen, so products run on the
///   same threads as before, without the reads.
/// - Element-wise operations on large tensors (the update's hidden layers: 512 × 128 values) run on a
///   pool of candle's own whose threads, after each operation, spin 25 000 times before they sleep:
///   during an update they spin most of the time (8% of a training run's samples on 2 cores). Unless
///   the user set `CANDLE_BARRIER_POOL_SPIN_LIMIT`, they spin 200 times. A run trains the same
///   weights either way (each element is computed alone). On an idle 2-core machine it made no
///   measurable difference; on one that also ran another training, the spinning took cores the
///   other work needed, and an iteration of MyoSuite's robot took 10–15% less time without it.
///
/// Changes the process's environment: call it at the start of a command, before other threads are
/// started (the `rally train` and `rally bench train` commands do; library code and tests do not).
pub fn tune_candle_threads() {
    if std::env::var_os(SPIN_LIMIT).is_none() {
        std::env::set_var(SPIN_LIMIT, "200");
    }
    if std::env::var_os("RAYON_NUM_THREADS").is_some() {
        return;
    }
    let candle = candle_core::utils::get_num_threads();
    // Err only when the global pool already exists, whose size then stands as it is.
    let _ = rayon::ThreadPoolBuilder::new().build_global();
    std::env::set_var("RAYON_NUM_THREADS", candle.to_string());
}

use crate::controller::{ControllerSpec, PdGains, Synergies};
use crate::env::RewardWeights;

/// Which of the paper's methods a run trains: the same PPO, reward and network, another action
/// space (docs/design.md §6).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Diff-Muscle: joint targets through K-MAC.
    Kmac,
    /// Muscle-PPO: every muscle's control.
    Muscle,
    /// Muscle-PD (MuscleVAE-style): target muscle lengths.
    MusclePd,
    /// DynSyn: synergy groups and per-muscle weights.
    Dynsyn,
}

impl Method {
    /// The name of its committed checkpoint (`config/checkpoints/NAME.json`).
    pub fn checkpoint_name(self) -> &'static str {
        match self {
            Method::Kmac => "kmac",
            Method::Muscle => "muscle-ppo",
            Method::MusclePd => "muscle-pd",
            Method::Dynsyn => "dynsyn",
        }
    }

    /// The paper's name for it.
    pub fn paper_name(self) -> &'static str {
        match self {
            Method::Kmac => "Diff-Muscle",
            Method::Muscle => "Muscle-PPO",
            Method::MusclePd => "Muscle-PD",
            Method::Dynsyn => "DynSyn",
        }
    }

    /// Its name on the command line and in files.
    pub fn name(self) -> &'static str {
        match self {
            Method::Kmac => "kmac",
            Method::Muscle => "muscle",
            Method::MusclePd => "muscle-pd",
            Method::Dynsyn => "dynsyn",
        }
    }

    /// All four, in the paper's table order.
    pub const ALL: [Method; 4] = [
        Method::Muscle,
        Method::Dynsyn,
        Method::MusclePd,
        Method::Kmac,
    ];
}

impl std::str::FromStr for Method {
    type Err = String;

    fn from_str(s: &str) -> Result<Method, String> {
        Method::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| format!("'{s}': the methods are kmac, muscle, muscle-pd and dynsyn"))
    }
}

/// The learning-rate schedule.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Schedule {
    /// Fixed.
    Fixed,
    /// rsl_rl's adaptive KL rule: per minibatch ÷1.5 when KL > 2·target, ×1.5 when KL < target/2,
    /// within [1e-5, 1e-2].
    Adaptive,
    /// Linear decay from `learning_rate` at the first step to zero at the run's step target
    /// (`rally train --steps`), set at the start of each iteration from the steps done; a run
    /// extended past its first target decays from where it is to the new one.
    LinearDecay,
}

/// What the critic sees.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CriticInput {
    /// The actor's observation (every shipped configuration).
    #[default]
    Actor,
    /// The actor's observation and what the robot does not observe, as the official code's critic
    /// (single serves only): the episode's elapsed share of its time limit, every muscle's velocity
    /// over its length range, the paddle's mass and the ball's friction (P2's draws), normalised by
    /// running statistics of their own. The checkpoint's policy is unchanged: only training sees it.
    Privileged,
}

/// PPO's hyperparameters. The official code's values (docs/design.md §11) are in the comments where ours
/// differ; `config/train.toml` carries the same with both.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PpoConfig {
    /// Parallel environments (official 1024).
    pub envs: usize,
    /// Control steps per environment per iteration (official 20).
    pub steps_per_env: usize,
    /// Passes over each rollout (official 5).
    pub epochs: usize,
    /// Minibatches per pass (official 4).
    pub minibatches: usize,
    /// Initial learning rate (official 5e-4).
    pub learning_rate: f64,
    /// Learning-rate schedule (the official config names `linear_decay`; docs/design.md §11).
    pub schedule: Schedule,
    /// KL target of the adaptive schedule (official 0.01).
    pub desired_kl: f64,
    /// Clip of the ratio and the value (official 0.2).
    pub clip: f64,
    /// Value-loss coefficient (official 1.0).
    pub value_coef: f64,
    /// Entropy coefficient (official 0.01).
    pub entropy_coef: f64,
    /// Discount (official 0.99).
    pub gamma: f64,
    /// GAE λ (official 0.95).
    pub lambda: f64,
    /// Gradient-norm clip (official 1.0).
    pub max_grad_norm: f64,
    /// Initial policy σ (official 1.0).
    pub init_std: f64,
    /// Hidden layers of actor and critic, ELU (official 1024, 1024, 512, 512, 256, 256).
    pub hidden: Vec<usize>,
    /// Save the checkpoint and the resumable state every this many iterations (ours; also where a
    /// segment of fresh episodes begins, so that a resumed run is the same run).
    pub checkpoint_every: usize,
    /// Multiplies every reward before PPO sees it (ours: the official rewards are O(100), which
    /// makes the value loss dwarf the policy's gradient under one joint norm clip).
    pub reward_scale: f64,
    /// Upper bound on the policy's σ (ours; rsl_rl has none): `[from, to]`, lowered linearly from
    /// `from` to `to` over the run's first `max_std_steps` env steps and held at `to` after; applied
    /// after every optimiser step. `None` (the default and every shipped configuration): unbounded.
    /// Tried on the rally fine-tuning and not kept: a trained `kmac-rally` played at 0.75 of its σ
    /// returned 60.5% of rally serves against 52% at its σ (200 episodes, seed 9191), but training
    /// under a cap falling 0.9 → 0.3 over 3 M steps lowered the training rally length (0.6 → 0.5 by
    /// 2 M steps): the policy had learnt to play through its noise, and the adaptive learning rate
    /// shrinks as σ does.
    pub max_std: Option<[f64; 2]>,
    /// Env steps over which `max_std` falls from its first value to its second.
    pub max_std_steps: u64,
    /// Weight of the bound loss (ours; rsl_rl has none, rl_games has it): the policy's means past
    /// ±`bound` are pulled back by `bound_coef · mean Σ max(|μ| − bound, 0)²`
    /// ([`loss::bound_loss`]). 0 (the default): off, rsl_rl's loss exactly.
    pub bound_coef: f64,
    /// Where the bound loss starts (the environment clips actions at ±1).
    pub bound: f64,
    /// What the critic sees (official: the privileged observation; ours by default: the actor's).
    #[serde(skip_serializing_if = "is_actor")]
    pub critic: CriticInput,
    /// Iterations at the start of a run in which only the critic learns (ours; rsl_rl has none):
    /// their loss is the value loss alone, so the policy and its σ stay as they started. For a run
    /// warm-started from a checkpoint file, which brings a policy but no critic: a fresh critic's
    /// advantages are noise, and the policy's first updates on them would undo its training.
    /// 0 (the default): off.
    #[serde(skip_serializing_if = "no_iterations")]
    pub critic_warmup: u64,
}

fn no_iterations(n: &u64) -> bool {
    *n == 0
}

impl CriticInput {
    /// Its name in a configuration.
    pub fn name(self) -> &'static str {
        match self {
            CriticInput::Actor => "actor",
            CriticInput::Privileged => "privileged",
        }
    }
}

fn is_actor(c: &CriticInput) -> bool {
    *c == CriticInput::Actor
}

impl PpoConfig {
    /// The bound on σ after `env_steps` env steps of this run, if there is one.
    pub fn std_cap(&self, env_steps: u64) -> Option<f64> {
        let [from, to] = self.max_std?;
        let f = if self.max_std_steps == 0 {
            1.0
        } else {
            (env_steps as f64 / self.max_std_steps as f64).min(1.0)
        };
        Some(from + (to - from) * f)
    }
}

impl Default for PpoConfig {
    fn default() -> Self {
        PpoConfig {
            envs: 64,
            steps_per_env: 32,
            epochs: 5,
            minibatches: 4,
            learning_rate: 5e-4,
            schedule: Schedule::Adaptive,
            desired_kl: 0.01,
            clip: 0.2,
            value_coef: 1.0,
            entropy_coef: 0.01,
            gamma: 0.99,
            lambda: 0.95,
            max_grad_norm: 1.0,
            init_std: 0.5,
            hidden: vec![128, 128],
            checkpoint_every: 10,
            reward_scale: 0.05,
            max_std: None,
            max_std_steps: 0,
            bound_coef: 0.0,
            critic: CriticInput::Actor,
            bound: 1.0,
            critic_warmup: 0,
        }
    }
}

/// The training episode: what is served.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum TrainServe {
    /// MyoChallenge P2 serves (the evaluation's distribution; the seeds differ).
    #[default]
    P2,
    /// MyoChallenge P1 serves (the easier phase: a narrower launch distribution).
    P1,
    /// The paper's rally serve from B's hitting plane (the official code's training serve).
    Rally,
    /// A robot's return from B's hitting plane: the rally serve with a stroke's error, about half
    /// of them outside the serve box (`sim::serve::ServeKind::Stroke`; ours).
    Stroke,
}

impl TrainServe {
    /// The serve distribution it names.
    pub fn kind(self) -> sim::serve::ServeKind {
        match self {
            TrainServe::P2 => sim::serve::ServeKind::P2,
            TrainServe::P1 => sim::serve::ServeKind::P1,
            TrainServe::Rally => sim::serve::ServeKind::Rally {
                server: sim::arena::Side::B,
            },
            TrainServe::Stroke => sim::serve::ServeKind::Stroke {
                server: sim::arena::Side::B,
            },
        }
    }
}

/// The training environment.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum TrainEnv {
    /// The single-serve episode (paper §IV-B): one ball, one stroke.
    #[default]
    Single,
    /// The dual-robot rally in self-play (paper §IV-C): the policy plays both robots; see
    /// [`crate::env::RallyEnv`].
    Rally,
}

impl TrainEnv {
    /// Its name on the command line and in files.
    pub fn name(self) -> &'static str {
        match self {
            TrainEnv::Single => "single",
            TrainEnv::Rally => "rally",
        }
    }

    /// Policies stepped per environment (one robot, or both).
    pub fn agents(self) -> usize {
        match self {
            TrainEnv::Single => 1,
            TrainEnv::Rally => 2,
        }
    }
}

/// The controllers' settings (the same for every run of a method).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ControllerConfig {
    /// K-MAC's length PD gains, paper's form (official K_p 10, K_d 1).
    pub kmac: PdGains,
    /// Muscle-PD's gains (official K_p 10, K_d 1).
    pub muscle_pd: PdGains,
    /// DynSyn's number of synergy groups (ours; DynSyn is not in the official code).
    pub dynsyn_groups: usize,
    /// Seed of DynSyn's grouping.
    pub dynsyn_seed: u64,
    /// Least control of the grip muscles, for every method (ours; see `controller::apply_grip_floor`).
    pub grip_floor: f64,
    /// K-MAC in the official code's form: the activation target is the control, clamped to these
    /// bounds (official [σ(−7.5), σ(2.5)]); absent: ours (the activation dynamics inverted).
    #[serde(default)]
    pub kmac_activation_clamp: Option<[f64; 2]>,
    /// K-MAC clamps coupled joints' targets to their ranges (the official code; off by default,
    /// as every checkpoint trained before the setting).
    #[serde(default)]
    pub kmac_clamp_coupled: bool,
    /// Training noise, σ, on the policy's actions (in [−1, 1] units, every method; official 0.05).
    #[serde(default)]
    pub action_noise: f64,
    /// Training noise, σ, on K-MAC's activation targets (official 0.1).
    #[serde(default)]
    pub activation_noise: f64,
}

impl Default for ControllerConfig {
    fn default() -> Self {
        ControllerConfig {
            kmac: PdGains { kp: 10.0, kd: 1.0 },
            muscle_pd: PdGains::MUSCLE_PD,
            dynsyn_groups: 12,
            dynsyn_seed: 1,
            grip_floor: 0.1,
            kmac_activation_clamp: None,
            kmac_clamp_coupled: false,
            action_noise: 0.0,
            activation_noise: 0.0,
        }
    }
}

/// Which checkpoint a run keeps besides its last (ours; rsl_rl keeps only the last). Rally training
/// peaks and then degrades (docs/runs/kmac-rally-continued: training rally length 0.92 at 1.1 M steps,
/// 0.49 at 5 M), so every `every` iterations the policy as it would play in a match (its trained
/// Gaussian, seeded) plays held-out episodes: self-play rallies in the rally environment (score: the
/// mean rally length), single serves of the training distribution otherwise (score: the success
/// rate). The best so far is written to `best.json`. Validation reads the weights and draws from
/// its own seeds only, so a run validated is the same run, bit for bit, as one that is not.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ValidationConfig {
    /// Validate every this many iterations; 0: never (the default).
    pub every: usize,
    /// Rallies (rally environment) or episodes (single serves) per validation.
    pub episodes: usize,
    /// Seed of the validation's serves; every validation of a run plays the same ones, so its
    /// checkpoints are compared on equal terms. Report figures on other seeds.
    pub seed: u64,
    /// What validation plays: "rally" (self-play rallies, score the mean rally length) or "single"
    /// (single serves of the training distribution, score the success rate); default: the
    /// training environment's.
    pub env: Option<TrainEnv>,
    /// Validation plays the policy with this many times its trained σ, and `best.json` keeps it so
    /// (`training.noise_scale`): rallies are sensitive to the noise (the bank policy rallied 4.365 at
    /// its σ, 5.57 at half of it, on the validation seed). Default 1.
    pub noise_scale: f64,
}

impl Default for ValidationConfig {
    fn default() -> Self {
        ValidationConfig {
            every: 0,
            episodes: 200,
            seed: 4242,
            env: None,
            noise_scale: 1.0,
        }
    }
}

/// Everything a run is configured by (`config/train.toml`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    /// PPO.
    pub ppo: PpoConfig,
    /// Reward weights.
    pub reward: RewardWeights,
    /// Controllers.
    pub controller: ControllerConfig,
    /// Training serves (single-serve environment; the rally serves its own).
    pub serve: TrainServe,
    /// The environment.
    pub env: TrainEnv,
    /// Held-out validation and the best checkpoint.
    pub validation: ValidationConfig,
    /// Balls recorded from rallies, served in a share of the single-serve environment's episodes.
    pub bank: BankConfig,
    /// The paper's ablations (what of the command is observed and rewarded, the task reward);
    /// the default removes nothing.
    pub ablation: crate::env::Ablation,
    /// The rules the task terms judge a return by: ours (the default) or the official code's
    /// margins (see [`crate::env::TaskRules`]).
    pub task_rules: crate::env::TaskRules,
    /// Where the position term aims the blade's centre: `strike` (ours, the default: at the strike
    /// point) or `contact` (the official code's: where it touches the ball there; see
    /// [`crate::env::PositionTarget`]).
    pub position_target: crate::env::PositionTarget,
    /// How often the planner's command is made for one ball: `once` (ours, the default) or
    /// `after_bounce`, once more from the ball's real state after its bounce (the official code's
    /// second plan; see [`crate::observation::Replan`]). The checkpoint records it.
    pub replan: crate::observation::Replan,
    /// Share of single-serve episodes that begin with a lead-in, in [0, 1] (ours, for rallies; see
    /// [`crate::env::Env::lead_in`]): the robot's own return flies away first, as between two
    /// strokes of a rally, and the `ready` term is paid meanwhile. 0 (the default): none. The
    /// checkpoint records it.
    #[serde(skip_serializing_if = "is_zero")]
    pub lead_in: f64,
    /// How long a lead-in lasts: `full` (the default: until its ball reaches the other hitting
    /// plane) or `spread` (cut after a uniform share of that).
    #[serde(skip_serializing_if = "is_full")]
    pub lead_in_length: crate::env::single::LeadInLength,
    /// Share of legal returns in single serves that a next serve follows, in [0, 1] (ours, for
    /// rallies; see [`crate::env::Env::follow_on`]): the episode goes on, its return flying away
    /// and the `ready` term paid, until the next ball comes to the robot as its stroke left it.
    /// 0 (the default): none. The checkpoint records it.
    #[serde(skip_serializing_if = "is_zero")]
    pub follow_on: f64,
}

fn is_full(l: &crate::env::single::LeadInLength) -> bool {
    *l == crate::env::single::LeadInLength::Full
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

/// A ball bank for the single-serve environment (ours; see [`crate::env::BallBank`]): the file
/// `rally match --returns` wrote and the share of episodes it serves; the rest get `serve`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BankConfig {
    /// The bank file (relative to the working directory); none: no bank (the default).
    pub file: Option<String>,
    /// Share of episodes served from it, in [0, 1].
    pub fraction: f64,
    /// Every this many iterations (a multiple of `ppo.checkpoint_every`), replace the bank with the
    /// policy's own returns in `refresh_rallies` self-play rallies, so that it trains on the balls it
    /// brings now; 0: never (the default). The refreshed bank is kept in the resumable state.
    pub refresh_every: usize,
    /// Self-play rallies a refresh plays.
    pub refresh_rallies: usize,
}

impl Default for BankConfig {
    fn default() -> Self {
        BankConfig {
            file: None,
            fraction: 0.5,
            refresh_every: 0,
            refresh_rallies: 200,
        }
    }
}

impl TrainConfig {
    /// What validation plays: `[validation] env`, else the training environment.
    pub fn validation_env(&self) -> TrainEnv {
        self.validation.env.unwrap_or(self.env)
    }

    /// The observation's blocks (every block; the command as `[ablation] command` has it).
    pub fn obs_blocks(&self) -> Vec<crate::observation::ObsBlock> {
        self.ablation.command.blocks()
    }

    /// The reward's weights, less the terms the ablation removes.
    pub fn reward_weights(&self) -> crate::env::RewardWeights {
        self.ablation.weights(self.reward)
    }

    /// The controller a method's checkpoints carry.
    pub fn controller(&self, method: Method, model: &sim::model::Model) -> ControllerSpec {
        match method {
            Method::Kmac => ControllerSpec::Kmac {
                gains: self.controller.kmac,
                activation_clamp: self.controller.kmac_activation_clamp,
                activation_noise: (self.controller.activation_noise > 0.0)
                    .then_some(self.controller.activation_noise),
                clamp_coupled: self.controller.kmac_clamp_coupled,
            },
            Method::Muscle => ControllerSpec::Direct,
            Method::MusclePd => ControllerSpec::MusclePd {
                gains: self.controller.muscle_pd,
            },
            Method::Dynsyn => ControllerSpec::Dynsyn {
                synergies: Synergies::derive(
                    model,
                    self.controller.dynsyn_groups,
                    self.controller.dynsyn_seed,
                ),
            },
        }
    }

    /// Refuses settings PPO cannot run with, naming the field.
    pub fn validate(&self) -> Result<(), String> {
        let p = &self.ppo;
        let checks: [(&str, bool); 22] = [
            ("ppo.envs", p.envs >= 1),
            ("ppo.steps_per_env", p.steps_per_env >= 1),
            ("ppo.epochs", p.epochs >= 1),
            (
                "ppo.minibatches",
                p.minibatches >= 1 && p.minibatches <= p.envs * p.steps_per_env,
            ),
            (
                "ppo.learning_rate",
                p.learning_rate > 0.0 && p.learning_rate.is_finite(),
            ),
            ("ppo.clip", p.clip > 0.0 && p.clip < 1.0),
            (
                "ppo.gamma",
                (0.0..=1.0).contains(&p.gamma) && (0.0..=1.0).contains(&p.lambda),
            ),
            ("ppo.init_std", p.init_std > 0.0 && p.init_std.is_finite()),
            ("ppo.checkpoint_every", p.checkpoint_every >= 1),
            (
                "ppo.bound_coef",
                p.bound_coef >= 0.0
                    && p.bound_coef.is_finite()
                    && p.bound > 0.0
                    && p.bound.is_finite(),
            ),
            (
                "ppo.max_std",
                p.max_std
                    .is_none_or(|m| m.iter().all(|s| *s > 0.0 && s.is_finite())),
            ),
            (
                "ppo.hidden",
                !p.hidden.is_empty() && p.hidden.iter().all(|&h| h >= 1),
            ),
            (
                "validation.episodes",
                self.validation.every == 0 || self.validation.episodes >= 1,
            ),
            (
                "validation.noise_scale",
                self.validation.noise_scale.is_finite() && self.validation.noise_scale >= 0.0,
            ),
            ("bank.fraction", (0.0..=1.0).contains(&self.bank.fraction)),
            ("lead_in", (0.0..=1.0).contains(&self.lead_in)),
            ("follow_on", (0.0..=1.0).contains(&self.follow_on)),
            (
                "bank.refresh_every",
                self.bank
                    .refresh_every
                    .is_multiple_of(p.checkpoint_every.max(1))
                    && (self.bank.refresh_every == 0 || self.bank.refresh_rallies >= 1),
            ),
            (
                "controller.grip_floor",
                (0.0..=1.0).contains(&self.controller.grip_floor),
            ),
            (
                "controller.kmac_activation_clamp",
                self.controller
                    .kmac_activation_clamp
                    .is_none_or(|[lo, hi]| 0.0 <= lo && lo < hi && hi <= 1.0),
            ),
            (
                "controller.action_noise",
                (0.0..=1.0).contains(&self.controller.action_noise),
            ),
            (
                "controller.activation_noise",
                (0.0..=1.0).contains(&self.controller.activation_noise),
            ),
        ];
        if let Some((field, _)) = checks.iter().find(|(_, ok)| !ok) {
            return Err(format!("{field}: out of range"));
        }
        let noise = self.controller.action_noise > 0.0 || self.controller.activation_noise > 0.0;
        if self.env == TrainEnv::Rally && noise {
            return Err(
                "controller.action_noise, controller.activation_noise: the rally \
                        environment draws no training noise; set both to 0 to train in it"
                    .into(),
            );
        }
        if self.lead_in == 0.0 && self.lead_in_length != crate::env::single::LeadInLength::Full {
            return Err(
                "lead_in_length: set for no lead-ins; give lead_in a share above 0, or leave \
                 lead_in_length out"
                    .into(),
            );
        }
        if self.env == TrainEnv::Rally && self.lead_in > 0.0 {
            return Err(
                "lead_in: a lead-in is for single serves; in the rally environment the robot's \
                 own returns fly away by themselves"
                    .into(),
            );
        }
        if self.env == TrainEnv::Rally && self.follow_on > 0.0 {
            return Err(
                "follow_on: a follow-on is for single serves; in the rally environment the next \
                 ball comes by itself"
                    .into(),
            );
        }
        if self.env == TrainEnv::Rally && self.ppo.critic == CriticInput::Privileged {
            return Err(
                "ppo.critic: \"privileged\" is for single serves; the rally environment's critic \
                 sees the actor's observation"
                    .into(),
            );
        }
        Ok(())
    }
}

/// A 64-bit stream seed mixed from a run seed and up to three counters (SplitMix64 steps), so
/// that every environment, episode and iteration draws from its own stream.
pub fn stream_seed(seed: u64, a: u64, b: u64, c: u64) -> u64 {
    let mix = |z: u64| crate::seeds::mix64(z.wrapping_add(crate::seeds::SPLITMIX_GAMMA));
    mix(mix(mix(mix(seed) ^ a) ^ b) ^ c)
}
