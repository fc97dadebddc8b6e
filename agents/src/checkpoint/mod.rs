//! Policy checkpoints (docs/design.md §8): versioned JSON holding the controller (kind and gains — K-MAC's in
//! the paper's form), the observation spec and its normalisation, and the network: an MLP of any depth
//! (elu, tanh, relu or linear layers) in `policy`, or — the second format — an ONNX model (observation
//! batch → action batch, float32) embedded in base64 under `onnx` and run by tract. Loading validates
//! everything against the arena's model and refuses with a message that names the field: wrong
//! dimensions, unknown kind, non-finite weights, too large.
//!
//! By part: this file (the format, its validation), [`network`] (the MLP and ONNX networks),
//! [`player`] (a checkpoint playing).

mod network;
mod player;

pub use network::*;
pub use player::*;

use serde::{Deserialize, Serialize};
use sim::model::Model;

use crate::controller::{ActionMapper, ActionSpace, ControllerSpec};
use crate::observation::ObsBlock;

/// The format tag every checkpoint carries.
pub const FORMAT: &str = "muscle-rally-checkpoint";
/// The newest format version this build reads (2 added the optional `training` provenance).
pub const VERSION: u32 = 2;
/// Largest checkpoint file accepted, bytes.
pub const MAX_BYTES: usize = 64 << 20;

/// The most points a checkpoint's learning curve may have (`rally train` writes at most ~200), and
/// the most bytes its whole `training` section may take as JSON: the provenance an agent's page
/// shows to anyone, kept small.
pub const MAX_CURVE_POINTS: usize = 1000;
/// See [`MAX_CURVE_POINTS`].
pub const MAX_TRAINING_BYTES: usize = 256 << 10;
/// Most parameters accepted.
pub const MAX_PARAMETERS: usize = 4_000_000;

/// What the policy sees and how it is normalised: `(obs − mean) / std`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObservationSpec {
    /// Blocks, in order.
    pub blocks: Vec<ObsBlock>,
    /// Per-entry mean.
    pub mean: Vec<f64>,
    /// Per-entry standard deviation (> 0).
    pub std: Vec<f64>,
    /// How the player makes the command (checkpoints before the setting: once; left out then).
    #[serde(default, skip_serializing_if = "crate::observation::Replan::is_once")]
    pub replan: crate::observation::Replan,
}

/// A policy checkpoint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Checkpoint {
    /// Always [`FORMAT`].
    pub format: String,
    /// Format version.
    pub version: u32,
    /// Display name.
    pub name: String,
    /// The robot it plays ([`sim::config::robot_name`]: `default`, `myochallenge`, or an MJCF
    /// model's name); files without it play the default robot.
    #[serde(default = "default_robot")]
    pub model: String,
    /// How actions become muscle controls.
    pub controller: ControllerSpec,
    /// What the policy sees.
    pub observation: ObservationSpec,
    /// The network as an MLP: observation → action in [−1, 1] (outputs are clipped).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub policy: Option<Mlp>,
    /// The network as an ONNX model instead.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub onnx: Option<OnnxPolicy>,
    /// The policy's Gaussian σ per action entry, as trained: the player then acts with
    /// `clip(μ + σ·ε)`, `ε` from its own seeded stream (so a match stays a function of its seed).
    /// Absent, it plays the mean action. (PPO trains the stochastic policy; with K-MAC its mean can
    /// differ a lot — muscles only pull, so the noise itself stiffens the arm.)
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub policy_std: Option<Vec<f64>>,
    /// The σ of the Gaussian noise training's environment added to every action after the policy's
    /// own noise and the clip (`[controller] action_noise`, the official code's): the player adds
    /// it the same way, `clip(a + σ·ε)` from the same stream, so that it plays as it was trained.
    /// Absent: none. A policy can come to depend on it (DynSyn on MyoSuite's robot lost 15 points
    /// of hit without it: docs/training.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub action_noise: Option<f64>,
    /// Least control of the grip muscles (default none; see `controller::apply_grip_floor`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub grip_floor: Option<f64>,
    /// How it was trained, if `rally train` made it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub training: Option<Training>,
    /// A way of playing, never written to the file: K-MAC plays the expectation of the training
    /// noise on its activations (`controller.activation_noise`) instead of drawing it from the
    /// player's seeded stream as training's environment did (the mean action's play, which draws
    /// nothing; see `PlayerSpec::mean_action`).
    #[serde(skip)]
    pub expected_activation_noise: bool,
}

/// A trained checkpoint's provenance: what made it, from what, how long, how well it did in training.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Training {
    /// The method (`kmac`, `muscle`, `muscle-pd`, `dynsyn`).
    pub method: String,
    /// The command line that trained it.
    pub command: String,
    /// The training seed.
    pub seed: u64,
    /// The git commit of the code that trained it (`unknown` outside a checkout).
    pub git_commit: String,
    /// Control steps simulated in training.
    pub env_steps: u64,
    /// PPO iterations.
    pub iterations: u64,
    /// Training wall time, s.
    pub wall_seconds: f64,
    /// Hit rate over the last training episodes (with follow-ons, of their last balls).
    pub hit_rate: f64,
    /// Success rate over the last training episodes (a training episode ends 3 steps after the
    /// hit, so its success is the planner's predicted landing; with follow-ons, its last ball's).
    pub success_rate: f64,
    /// Episodes those rates are over.
    pub episodes: u64,
    /// The learning curve, at most a few hundred points.
    #[serde(default)]
    pub curve: Vec<TrainingPoint>,
    /// The training environment: `single` (single serves) or `rally` (dual-arena self-play).
    #[serde(default = "single_env")]
    pub env: String,
    /// The run whose weights this one started from (a warm start), if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub warm_start: Option<String>,
    /// Mean legal returns per training rally over the last episodes (rally training; with
    /// follow-ons, per single-serve episode).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rally_length: Option<f64>,
    /// How this checkpoint was chosen among the ones its run wrote, when it is not the last (e.g.
    /// the best on validation seeds that no reported figure uses), and anything else a reader of the
    /// provenance must know.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
    /// `policy_std` is the trained σ times this (`rally checkpoint scale-noise`); absent: 1, the
    /// checkpoint plays with the noise it was trained with.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise_scale: Option<f64>,
    /// The ablation it was trained under (the paper's §V-C); absent: none, Diff-Muscle itself.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ablation: Option<crate::env::Ablation>,
    /// The share of its single-serve episodes that began with a lead-in (`lead_in` of the training
    /// configuration); absent: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lead_in: Option<f64>,
    /// How long those lead-ins lasted (`lead_in_length`), when not `full`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lead_in_length: Option<crate::env::single::LeadInLength>,
    /// The share of its legal single-serve returns that a next serve followed (`follow_on` of the
    /// training configuration); absent: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub follow_on: Option<f64>,
}

fn default_robot() -> String {
    sim::config::DEFAULT_ROBOT.into()
}

pub(crate) fn single_env() -> String {
    "single".into()
}

/// One point of a checkpoint's learning curve.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainingPoint {
    /// Control steps simulated so far.
    pub env_steps: u64,
    /// Mean training episode reward.
    pub reward: f64,
    /// Training hit rate.
    pub hit_rate: f64,
    /// Training success rate.
    pub success_rate: f64,
}

/// Why a checkpoint was refused: the field and what is wrong with it.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckpointError {
    /// JSON path of the offending field, e.g. `policy.layers[1].weights`.
    pub field: String,
    /// What is wrong.
    pub message: String,
}

impl std::fmt::Display for CheckpointError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.field, self.message)
    }
}

impl std::error::Error for CheckpointError {}

pub(crate) fn bad(field: impl Into<String>, message: impl Into<String>) -> CheckpointError {
    CheckpointError {
        field: field.into(),
        message: message.into(),
    }
}

impl Checkpoint {
    /// Multiplies the action noise it plays with (`policy_std`) by `factor` ≥ 0 and records the
    /// product of all such factors in its provenance (a checkpoint without one keeps none).
    pub fn scale_noise(&mut self, factor: f64) -> Result<(), CheckpointError> {
        if !(factor.is_finite() && factor >= 0.0) {
            return Err(bad(
                "factor",
                format!("{factor}: expected a finite number ≥ 0"),
            ));
        }
        let std = self.policy_std.as_mut().ok_or_else(|| {
            bad(
                "policy_std",
                "absent: the checkpoint plays its mean action, there is no noise to scale",
            )
        })?;
        std.iter_mut().for_each(|s| *s *= factor);
        if let Some(sigma) = self.action_noise.as_mut() {
            *sigma *= factor;
        }
        if let Some(t) = self.training.as_mut() {
            t.noise_scale = Some(t.noise_scale.unwrap_or(1.0) * factor);
        }
        Ok(())
    }

    /// Parses and validates a checkpoint for `model`.
    pub fn from_json(text: &str, model: &Model) -> Result<Checkpoint, CheckpointError> {
        if text.len() > MAX_BYTES {
            return Err(bad(
                "(file)",
                format!("{} bytes; at most {MAX_BYTES}", text.len()),
            ));
        }
        let c: Checkpoint = serde_json::from_str(text).map_err(|e| {
            let msg = e.to_string();
            // serde names unknown variants and fields itself; keep its words.
            bad(
                format!("(json line {} column {})", e.line(), e.column()),
                msg,
            )
        })?;
        c.validate(model)?;
        Ok(c)
    }

    /// Checks every field against `model`.
    pub fn validate(&self, model: &Model) -> Result<(), CheckpointError> {
        self.validate_header()?;
        self.validate_robot(model)?;
        let space = ActionSpace::new(model);
        self.validate_controller(&space)?;
        let obs = self.validate_observation(&space)?;
        let width = self.network_width(obs)?;
        self.validate_actions(model, width)
    }

    /// Format, version and name.
    fn validate_header(&self) -> Result<(), CheckpointError> {
        if self.format != FORMAT {
            return Err(bad(
                "format",
                format!("'{}'; expected '{FORMAT}'", self.format),
            ));
        }
        if self.version == 0 || self.version > VERSION {
            return Err(bad(
                "version",
                format!("{}; this build reads versions 1 to {VERSION}", self.version),
            ));
        }
        if self.name.trim().is_empty() || self.name.len() > 100 {
            return Err(bad("name", "must be 1 to 100 characters"));
        }
        if let Some(t) = &self.training {
            if t.curve.len() > MAX_CURVE_POINTS {
                return Err(bad(
                    "training.curve",
                    format!("{} points; at most {MAX_CURVE_POINTS}", t.curve.len()),
                ));
            }
            let bytes = serde_json::to_string(t).map_or(usize::MAX, |s| s.len());
            if bytes > MAX_TRAINING_BYTES {
                return Err(bad(
                    "training",
                    format!("{bytes} bytes of JSON; at most {MAX_TRAINING_BYTES}"),
                ));
            }
        }
        Ok(())
    }

    /// The controller's gains or synergies against the model's muscles, and the grip floor.
    fn validate_controller(&self, space: &ActionSpace) -> Result<(), CheckpointError> {
        if let ControllerSpec::Kmac {
            activation_clamp: Some([lo, hi]),
            ..
        } = self.controller
        {
            if !(lo.is_finite() && hi.is_finite() && 0.0 <= lo && lo < hi && hi <= 1.0) {
                return Err(bad(
                    "controller.activation_clamp",
                    format!("[{lo}, {hi}]: must be [low, high] with 0 <= low < high <= 1"),
                ));
            }
        }
        if let ControllerSpec::Kmac {
            activation_noise: Some(sigma),
            ..
        } = self.controller
        {
            if !(0.0..=1.0).contains(&sigma) {
                return Err(bad(
                    "controller.activation_noise",
                    format!("{sigma}: must be a σ in [0, 1]"),
                ));
            }
        }
        if let ControllerSpec::Kmac { gains, .. } | ControllerSpec::MusclePd { gains } =
            &self.controller
        {
            if !(gains.kp.is_finite() && gains.kp > 0.0 && gains.kd.is_finite() && gains.kd >= 0.0)
            {
                return Err(bad(
                    "controller.gains",
                    "kp must be a positive number and kd a number ≥ 0",
                ));
            }
        }
        if let ControllerSpec::Dynsyn { synergies } = &self.controller {
            if synergies.group_of.len() != space.muscles.len() {
                return Err(bad(
                    "controller.synergies.group_of",
                    format!(
                        "{} entries for a model with {} muscles",
                        synergies.group_of.len(),
                        space.muscles.len()
                    ),
                ));
            }
            if synergies.groups == 0 || synergies.group_of.iter().any(|&g| g >= synergies.groups) {
                return Err(bad(
                    "controller.synergies",
                    "group indices must be below `groups` (≥ 1)",
                ));
            }
        }
        if let Some(sigma) = self.action_noise {
            if !(0.0..=1.0).contains(&sigma) {
                return Err(bad(
                    "action_noise",
                    format!("{sigma}: must be a σ in [0, 1]"),
                ));
            }
        }
        if let Some(f) = self.grip_floor {
            if !(0.0..=1.0).contains(&f) {
                return Err(bad("grip_floor", "must be a control between 0 and 1"));
            }
        }
        Ok(())
    }

    /// The observation's blocks and normalisation; returns its size.
    fn validate_observation(&self, space: &ActionSpace) -> Result<usize, CheckpointError> {
        let o = &self.observation;
        if o.blocks.is_empty() {
            return Err(bad("observation.blocks", "empty"));
        }
        let obs: usize = o.blocks.iter().map(|b| b.size(space)).sum();
        for (field, v) in [("observation.mean", &o.mean), ("observation.std", &o.std)] {
            if v.len() != obs {
                return Err(bad(
                    field,
                    format!("{} entries; the observation has {obs}", v.len()),
                ));
            }
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                return Err(bad(format!("{field}[{i}]"), "not a finite number"));
            }
        }
        if let Some(i) = o.std.iter().position(|s| *s <= 0.0) {
            return Err(bad(format!("observation.std[{i}]"), "must be positive"));
        }
        Ok(obs)
    }

    /// The robot it names is `model`: a checkpoint of one robot is refused by another's arena
    /// before anything else is compared, with both names.
    fn validate_robot(&self, model: &Model) -> Result<(), CheckpointError> {
        let here = sim::config::robot_name(model);
        if self.model != here {
            return Err(bad(
                "model",
                format!(
                    "'{}': this checkpoint plays the {} robot, not {here} (play it with \
                     --model {}, or train one with --model {here})",
                    self.model, self.model, self.model
                ),
            ));
        }
        Ok(())
    }

    /// The network (an MLP or an ONNX model, which must run on a zero observation) for `obs`
    /// inputs; returns its output width.
    fn network_width(&self, obs: usize) -> Result<usize, CheckpointError> {
        Ok(match (&self.policy, &self.onnx) {
            (Some(p), None) => validate_mlp(p, obs)?,
            (None, Some(o)) => {
                let plan = load_onnx(o, obs)?;
                let probe = Network::Onnx(plan, obs)
                    .forward(&vec![0.0; obs])
                    .ok_or_else(|| {
                        bad(
                            "onnx.model_base64",
                            "the model does not run on a zero observation",
                        )
                    })?;
                if probe.iter().any(|x| !x.is_finite()) {
                    return Err(bad(
                        "onnx.model_base64",
                        "the model gives NaN or infinite actions for a zero observation",
                    ));
                }
                probe.len()
            }
            (Some(_), Some(_)) => {
                return Err(bad(
                    "policy",
                    "give either `policy` (an MLP) or `onnx`, not both",
                ))
            }
            (None, None) => return Err(bad("policy", "missing: give `policy` (an MLP) or `onnx`")),
        })
    }

    /// The policy noise and the network's width against the controller's actions on `model`.
    fn validate_actions(&self, model: &Model, width: usize) -> Result<(), CheckpointError> {
        let mapper = ActionMapper::new(model, &self.controller);
        if let Some(std) = &self.policy_std {
            if std.len() != mapper.action_dim() {
                return Err(bad(
                    "policy_std",
                    format!(
                        "{} entries; the controller takes {} actions",
                        std.len(),
                        mapper.action_dim()
                    ),
                ));
            }
            if let Some(i) = std
                .iter()
                .position(|s| !(s.is_finite() && *s >= 0.0 && *s <= 10.0))
            {
                return Err(bad(
                    format!("policy_std[{i}]"),
                    "must be a number from 0 to 10",
                ));
            }
        }
        if width != mapper.action_dim() {
            let field = match &self.policy {
                Some(p) => format!("policy.layers[{}].bias", p.layers.len() - 1),
                None => "onnx.model_base64".to_string(),
            };
            return Err(bad(
                field,
                format!(
                    "the network gives {width} actions; a {:?} controller on this model takes {}",
                    self.controller.kind(),
                    mapper.action_dim()
                ),
            ));
        }
        Ok(())
    }

    /// The runnable network (decodes and prepares an ONNX model).
    pub fn network(&self) -> Result<Network, CheckpointError> {
        let inputs = self.observation.mean.len();
        match (&self.policy, &self.onnx) {
            (Some(m), _) => Ok(Network::Mlp(m.clone())),
            (None, Some(o)) => Ok(Network::Onnx(load_onnx(o, inputs)?, inputs)),
            (None, None) => Err(bad("policy", "missing: give `policy` (an MLP) or `onnx`")),
        }
    }

    /// A zero-initialised checkpoint of the right shape (a template for users and tests): hidden
    /// layers of `hidden` units with `activation`, all weights zero, identity normalisation.
    pub fn template(
        model: &Model,
        name: &str,
        controller: ControllerSpec,
        hidden: &[usize],
        activation: Activation,
    ) -> Checkpoint {
        let space = ActionSpace::new(model);
        let blocks = ObsBlock::ALL.to_vec();
        let obs: usize = blocks.iter().map(|b| b.size(&space)).sum();
        let out = ActionMapper::new(model, &controller).action_dim();
        let mut layers = Vec::new();
        let mut width = obs;
        for (k, &h) in hidden.iter().chain(std::iter::once(&out)).enumerate() {
            layers.push(Layer {
                weights: vec![vec![0.0; width]; h],
                bias: vec![0.0; h],
                activation: if k == hidden.len() {
                    Activation::Linear
                } else {
                    activation
                },
            });
            width = h;
        }
        Checkpoint {
            format: FORMAT.into(),
            version: VERSION,
            name: name.into(),
            model: sim::config::robot_name(model).into(),
            controller,
            observation: ObservationSpec {
                blocks,
                mean: vec![0.0; obs],
                std: vec![1.0; obs],
                replan: Default::default(),
            },
            policy: Some(Mlp { layers }),
            onnx: None,
            policy_std: None,
            action_noise: None,
            grip_floor: None,
            training: None,
            expected_activation_noise: false,
        }
    }

    /// A checkpoint around an ONNX network trained elsewhere: `controller` maps its actions (the
    /// network's output, clipped to [−1, 1]) to muscle controls, and `norm` (mean, std) is applied to
    /// the observation before the network (`None`: mean 0, std 1, the raw observation). Plays the
    /// network's mean action (no `policy_std`). Validated against `model`, ONNX graph included, with
    /// the offending field named.
    pub fn from_onnx(
        model: &Model,
        name: &str,
        controller: ControllerSpec,
        onnx: &[u8],
        norm: Option<(Vec<f64>, Vec<f64>)>,
        grip_floor: Option<f64>,
    ) -> Result<Checkpoint, CheckpointError> {
        let space = ActionSpace::new(model);
        let blocks = ObsBlock::ALL.to_vec();
        let obs: usize = blocks.iter().map(|b| b.size(&space)).sum();
        let (mean, std) = norm.unwrap_or_else(|| (vec![0.0; obs], vec![1.0; obs]));
        let c = Checkpoint {
            format: FORMAT.into(),
            version: VERSION,
            name: name.into(),
            model: sim::config::robot_name(model).into(),
            controller,
            observation: ObservationSpec {
                blocks,
                mean,
                std,
                replan: Default::default(),
            },
            policy: None,
            onnx: Some(OnnxPolicy::from_bytes(onnx)),
            policy_std: None,
            action_noise: None,
            grip_floor,
            training: None,
            expected_activation_noise: false,
        };
        c.validate(model)?;
        Ok(c)
    }
}
