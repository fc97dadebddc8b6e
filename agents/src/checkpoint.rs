//! Policy checkpoints (docs/design.md §8): versioned JSON holding the controller (kind and gains — K-MAC's in
//! the paper's form), the observation spec and its normalisation, and the network: an MLP of any depth
//! (elu, tanh, relu or linear layers) in `policy`, or — the second format — an ONNX model (observation
//! batch → action batch, float32) embedded in base64 under `onnx` and run by tract. Loading validates
//! everything against the arena's model and refuses with a message that names the field: wrong
//! dimensions, unknown kind, non-finite weights, too large.

use serde::{Deserialize, Serialize};
use sim::ball::BallState;
use sim::model::Model;
use sim::robot::Robot;

use crate::controller::{ActionMapper, ActionSpace, ControllerSpec};
use crate::observation::{ObsBlock, Observer};
use crate::player::{InvalidAction, Player};

/// The format tag every checkpoint carries.
pub const FORMAT: &str = "muscle-rally-checkpoint";
/// The newest format version this build reads (2 added the optional `training` provenance).
pub const VERSION: u32 = 2;
/// Largest checkpoint file accepted, bytes.
pub const MAX_BYTES: usize = 64 << 20;
/// Most parameters accepted.
pub const MAX_PARAMETERS: usize = 4_000_000;

/// An activation function.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Activation {
    /// x
    Linear,
    /// max(0, x)
    Relu,
    /// tanh(x)
    Tanh,
    /// x for x > 0, eˣ − 1 otherwise.
    Elu,
}

impl Activation {
    fn apply(self, x: f64) -> f64 {
        match self {
            Activation::Linear => x,
            Activation::Relu => x.max(0.0),
            Activation::Tanh => x.tanh(),
            Activation::Elu => {
                if x > 0.0 {
                    x
                } else {
                    x.exp_m1()
                }
            }
        }
    }
}

/// One dense layer: `y = act(W·x + b)`, `W` given row by row (outputs × inputs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Layer {
    /// Weights, one row per output.
    pub weights: Vec<Vec<f64>>,
    /// Biases, one per output.
    pub bias: Vec<f64>,
    /// Activation.
    pub activation: Activation,
}

/// A multilayer perceptron.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Mlp {
    /// Layers, input first.
    pub layers: Vec<Layer>,
}

impl Mlp {
    /// Evaluates the network.
    pub fn forward(&self, input: &[f64]) -> Vec<f64> {
        let mut x = input.to_vec();
        for l in &self.layers {
            x = l
                .weights
                .iter()
                .zip(&l.bias)
                .map(|(row, b)| {
                    l.activation
                        .apply(row.iter().zip(&x).map(|(w, v)| w * v).sum::<f64>() + b)
                })
                .collect();
        }
        x
    }

    /// Input size (0 for an empty network).
    pub fn inputs(&self) -> usize {
        self.layers
            .first()
            .and_then(|l| l.weights.first())
            .map_or(0, |r| r.len())
    }

    /// Output size.
    pub fn outputs(&self) -> usize {
        self.layers.last().map_or(0, |l| l.bias.len())
    }

    /// Parameters.
    pub fn parameters(&self) -> usize {
        self.layers
            .iter()
            .map(|l| l.bias.len() * (1 + l.weights.first().map_or(0, |r| r.len())))
            .sum()
    }
}

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
    /// Least control of the grip muscles (default none; see `controller::apply_grip_floor`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub grip_floor: Option<f64>,
    /// How it was trained, if `rally train` made it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub training: Option<Training>,
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
    /// Hit rate over the last training episodes.
    pub hit_rate: f64,
    /// Success rate over the last training episodes (a training episode ends 3 steps after the
    /// hit, so its success is the planner's predicted landing).
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
    /// Mean legal returns per training rally over the last episodes (rally training only).
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
}

fn single_env() -> String {
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

/// An ONNX network embedded in a checkpoint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OnnxPolicy {
    /// The `.onnx` file, base64-encoded. Input 0: float32 `[batch, observation]`; output 0: float32
    /// `[batch, action]`.
    pub model_base64: String,
}

type OnnxPlan = std::sync::Arc<tract_onnx::prelude::TypedRunnableModel>;

/// A runnable network.
#[derive(Clone)]
pub enum Network {
    /// The checkpoint's MLP.
    Mlp(Mlp),
    /// A loaded ONNX model.
    Onnx(OnnxPlan, usize),
}

impl std::fmt::Debug for Network {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Network::Mlp(m) => write!(f, "Mlp({} layers)", m.layers.len()),
            Network::Onnx(_, n) => write!(f, "Onnx({n} inputs)"),
        }
    }
}

impl Network {
    /// Evaluates the network on one observation; `None` if the ONNX runtime failed.
    pub fn forward(&self, obs: &[f64]) -> Option<Vec<f64>> {
        use tract_onnx::prelude::*;
        match self {
            Network::Mlp(m) => Some(m.forward(obs)),
            Network::Onnx(plan, n) => {
                let data: Vec<f32> = obs.iter().map(|&x| x as f32).collect();
                let input = Tensor::from_shape(&[1, *n], &data).ok()?;
                // tract may panic on a graph it accepted (the fuzz target found two at load time):
                // contained here, it is an invalid action, not a crashed worker.
                let run = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                    plan.run(tvec!(input.into()))
                }));
                let out = run.ok()?.ok()?;
                let view = out.first()?.to_plain_array_view::<f32>().ok()?;
                Some(view.iter().map(|&x| x as f64).collect())
            }
        }
    }
}

/// Decodes and prepares an embedded ONNX model for observations of `inputs` entries.
fn load_onnx(p: &OnnxPolicy, inputs: usize) -> Result<OnnxPlan, CheckpointError> {
    use base64::Engine;
    use tract_onnx::prelude::*;
    let bytes = base64::engine::general_purpose::STANDARD
        .decode(p.model_base64.trim())
        .map_err(|e| bad("onnx.model_base64", format!("not base64: {e}")))?;
    let refuse = |e: String| {
        bad(
            "onnx.model_base64",
            format!("not an ONNX model taking [1, {inputs}] float32: {e}"),
        )
    };
    let onnx = tract_onnx::onnx();
    let proto = onnx
        .proto_model_for_read(&mut &bytes[..])
        .map_err(|e| refuse(e.to_string()))?;
    if let Some(name) = proto
        .graph
        .as_ref()
        .and_then(|g| output_naming_nothing(g, &std::collections::HashSet::new()))
    {
        return Err(refuse(format!(
            "the graph's output '{name}' is no input, initializer or node's output"
        )));
    }
    // tract's own checks are not all errors: a model that passes ours may still make it panic
    // (the fuzz target found two), so its work is contained here and a panic refuses the model.
    let built = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        let m = onnx.model_for_proto_model(&proto)?;
        let n = m.input_outlets()?.len();
        if n != 1 {
            return Err(TractError::msg(format!("it takes {n} inputs, not one")));
        }
        m.with_input_fact(0, f32::fact([1, inputs]).into())?
            .into_optimized()?
            .into_runnable()
    }));
    match built {
        Ok(plan) => plan.map_err(|e| refuse(e.to_string())),
        Err(panic) => {
            let why = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "no message".into());
            Err(refuse(format!(
                "tract could not read it (it panicked: {why})"
            )))
        }
    }
}

/// A graph output (of `g` or of a subgraph in one of its nodes' attributes) that names no input,
/// initializer or node input or output, with `outer` the names an enclosing graph makes visible.
/// tract-onnx 0.23 indexes its map of names with each output and panics on such a graph (found by
/// the `checkpoint_onnx` fuzz target), so the reader refuses it first.
fn output_naming_nothing<'a>(
    g: &'a tract_onnx::pb::GraphProto,
    outer: &std::collections::HashSet<&'a str>,
) -> Option<String> {
    let mut known = outer.clone();
    known.extend(g.input.iter().map(|i| i.name.as_str()));
    known.extend(g.initializer.iter().map(|t| t.name.as_str()));
    for n in &g.node {
        known.extend(n.input.iter().chain(&n.output).map(String::as_str));
    }
    if let Some(o) = g.output.iter().find(|o| !known.contains(o.name.as_str())) {
        return Some(o.name.clone());
    }
    g.node
        .iter()
        .flat_map(|n| &n.attribute)
        .flat_map(|a| a.g.iter().chain(&a.graphs))
        .find_map(|sub| output_naming_nothing(sub, &known))
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

fn bad(field: impl Into<String>, message: impl Into<String>) -> CheckpointError {
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
        let space = ActionSpace::new(model);
        if let ControllerSpec::Kmac { gains } | ControllerSpec::MusclePd { gains } =
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
        if let Some(f) = self.grip_floor {
            if !(0.0..=1.0).contains(&f) {
                return Err(bad("grip_floor", "must be a control between 0 and 1"));
            }
        }
        let o = &self.observation;
        if o.blocks.is_empty() {
            return Err(bad("observation.blocks", "empty"));
        }
        let obs: usize = o.blocks.iter().map(|b| b.size(&space)).sum();
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
        let width = match (&self.policy, &self.onnx) {
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
        };
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
            controller,
            observation: ObservationSpec {
                blocks,
                mean: vec![0.0; obs],
                std: vec![1.0; obs],
            },
            policy: Some(Mlp { layers }),
            onnx: None,
            policy_std: None,
            grip_floor: None,
            training: None,
        }
    }
}

/// Checks an MLP's shapes and values for `obs` inputs; returns its output width.
fn validate_mlp(p: &Mlp, obs: usize) -> Result<usize, CheckpointError> {
    if p.layers.is_empty() {
        return Err(bad("policy.layers", "empty"));
    }
    let mut width = obs;
    let mut params = 0usize;
    for (k, l) in p.layers.iter().enumerate() {
        let f = |s: &str| format!("policy.layers[{k}].{s}");
        if l.weights.is_empty() || l.weights.len() != l.bias.len() {
            return Err(bad(
                f("weights"),
                format!("{} rows for {} biases", l.weights.len(), l.bias.len()),
            ));
        }
        if let Some(r) = l.weights.iter().position(|row| row.len() != width) {
            return Err(bad(
                format!("{}[{r}]", f("weights")),
                format!(
                    "{} inputs; the layer below gives {width}",
                    l.weights[r].len()
                ),
            ));
        }
        params += l.bias.len() * (width + 1);
        if params > MAX_PARAMETERS {
            return Err(bad(
                "policy",
                format!("more than {MAX_PARAMETERS} parameters"),
            ));
        }
        if let Some(r) = l
            .weights
            .iter()
            .position(|row| row.iter().any(|x| !x.is_finite()))
        {
            return Err(bad(
                format!("{}[{r}]", f("weights")),
                "holds a NaN or infinite weight",
            ));
        }
        if let Some(i) = l.bias.iter().position(|x| !x.is_finite()) {
            return Err(bad(format!("{}[{i}]", f("bias")), "not a finite number"));
        }
        width = l.bias.len();
    }
    Ok(width)
}

/// A checkpoint playing: observe, normalise, run the network, map the action through the controller.
#[derive(Debug, Clone)]
pub struct CheckpointPlayer {
    checkpoint: std::sync::Arc<Checkpoint>,
    network: Network,
    observer: Observer,
    mapper: ActionMapper,
    obs: Vec<f64>,
    mean: Vec<f64>,
    seed: u64,
    noise: sim::rng::Rng,
}

/// The stream of a checkpoint player's action noise for the agent seed `seed`.
fn noise_stream(seed: u64) -> sim::rng::Rng {
    sim::rng::Rng::seeded(seed ^ 0x6e6f_6973_655f_7374)
}

impl CheckpointPlayer {
    /// A player for `checkpoint` (validated against `model`) whose planner predicts with `bounce`.
    pub fn new(
        checkpoint: std::sync::Arc<Checkpoint>,
        model: &Model,
        bounce: sim::predict::BounceModel,
        seed: u64,
    ) -> Result<CheckpointPlayer, CheckpointError> {
        let network = checkpoint.network()?;
        Ok(CheckpointPlayer {
            network,
            observer: Observer::new(model, checkpoint.observation.blocks.clone(), seed)
                .with_bounce(bounce),
            mapper: ActionMapper::new(model, &checkpoint.controller),
            checkpoint,
            obs: Vec::new(),
            mean: Vec::new(),
            seed,
            noise: noise_stream(seed),
        })
    }

    /// The planner's current command (the plan and its absolute strike time), if a ball is coming.
    pub fn command(&self) -> Option<&(crate::planner::Plan, f64)> {
        self.observer.command()
    }

    /// The network's output at the last `act`: the mean of its Gaussian policy, before the noise
    /// and the clip to [−1, 1], in the controller's layout.
    pub fn last_mean(&self) -> &[f64] {
        &self.mean
    }
}

impl Player for CheckpointPlayer {
    fn reset(&mut self) {
        self.observer.reset(self.seed);
        self.noise = noise_stream(self.seed);
    }

    fn reseed(&mut self, seed: u64) {
        self.seed = seed;
        self.observer.reset(seed);
        self.noise = noise_stream(seed);
    }

    fn act(
        &mut self,
        robot: &Robot,
        ball: &BallState,
        t: f64,
        ctrl: &mut [f64],
    ) -> Result<(), InvalidAction> {
        self.observer.update_command(robot, ball, t);
        self.observer.observe(robot, ball, t, &mut self.obs);
        let o = &self.checkpoint.observation;
        for (x, (m, s)) in self.obs.iter_mut().zip(o.mean.iter().zip(&o.std)) {
            *x = (*x - m) / s;
        }
        let mut action = self.network.forward(&self.obs).ok_or(InvalidAction)?;
        // Validation ran the network on one observation only: an ONNX graph may answer others with
        // another width.
        if action.len() != self.mapper.action_dim() || action.iter().any(|a| !a.is_finite()) {
            return Err(InvalidAction);
        }
        self.mean.clone_from(&action);
        if let Some(std) = &self.checkpoint.policy_std {
            for (a, s) in action.iter_mut().zip(std) {
                *a = (*a + s * self.noise.normal()).clamp(-1.0, 1.0);
            }
        }
        let model = robot.held_model().clone();
        self.mapper
            .controls(&model, &robot.state, &action, sim::arena::CONTROL_DT, ctrl);
        crate::controller::apply_grip_floor(robot, self.checkpoint.grip_floor.unwrap_or(0.0), ctrl);
        Ok(())
    }
}
