//! The networks a checkpoint holds: an MLP of any depth, or an ONNX model run by tract.

use serde::{Deserialize, Serialize};

use super::*;

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
            Activation::Tanh => sim::math::tanh(x),
            Activation::Elu => {
                if x > 0.0 {
                    x
                } else {
                    sim::math::exp_m1(x)
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

/// An ONNX network embedded in a checkpoint: the `.onnx` file, base64-encoded (input 0: float32
/// `[batch, observation]`; output 0: float32 `[batch, action]`). Its runnable plan is built once,
/// by the first validation or player, and shared by every player of this checkpoint and its clones
/// (tract's optimisation of a graph costs far more than a match's first steps). The file cannot be
/// changed after that, so the plan always is the file's.
#[derive(Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OnnxPolicy {
    model_base64: String,
    /// The plan, with the observation width it was built for.
    #[serde(skip)]
    plan: std::sync::OnceLock<(usize, OnnxPlan)>,
}

impl OnnxPolicy {
    /// An ONNX file's bytes.
    pub fn from_bytes(onnx: &[u8]) -> OnnxPolicy {
        use base64::Engine;
        OnnxPolicy::from_base64(base64::engine::general_purpose::STANDARD.encode(onnx))
    }

    /// An ONNX file, base64-encoded (checked when the checkpoint is validated).
    pub fn from_base64(model_base64: String) -> OnnxPolicy {
        OnnxPolicy {
            model_base64,
            plan: std::sync::OnceLock::new(),
        }
    }

    /// The file, base64-encoded, as the checkpoint stores it.
    pub fn model_base64(&self) -> &str {
        &self.model_base64
    }
}

impl PartialEq for OnnxPolicy {
    fn eq(&self, other: &OnnxPolicy) -> bool {
        self.model_base64 == other.model_base64
    }
}

impl std::fmt::Debug for OnnxPolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "OnnxPolicy({} base64 bytes{})",
            self.model_base64.len(),
            if self.plan.get().is_some() {
                ", built"
            } else {
                ""
            }
        )
    }
}

pub(crate) type OnnxPlan = std::sync::Arc<tract_onnx::prelude::TypedRunnableModel>;

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

/// The runnable plan of an embedded ONNX model for observations of `inputs` entries: built (decoded,
/// checked, optimised) on the first call, then the same one.
pub(crate) fn load_onnx(p: &OnnxPolicy, inputs: usize) -> Result<OnnxPlan, CheckpointError> {
    if let Some((n, plan)) = p.plan.get() {
        if *n == inputs {
            return Ok(plan.clone());
        }
    }
    let plan = build_onnx(p, inputs)?;
    // Two threads may build it at once; either plan is the file's, and the first one set is kept.
    let _ = p.plan.set((inputs, plan.clone()));
    Ok(plan)
}

fn build_onnx(p: &OnnxPolicy, inputs: usize) -> Result<OnnxPlan, CheckpointError> {
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
    if let Some((node, bytes)) = proto.graph.as_ref().and_then(oversized_generator) {
        return Err(refuse(format!(
            "its node '{node}' would make a tensor of {bytes} bytes; at most {MAX_TENSOR_BYTES}"
        )));
    }
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
        let optimized = m
            .with_input_fact(0, f32::fact([1, inputs]).into())?
            .into_optimized()?;
        if let Some(why) = input_dependent(&optimized) {
            return Err(TractError::msg(why));
        }
        optimized.into_runnable()
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

/// The most bytes one tensor of an ONNX policy may take (weights or any intermediate value at batch
/// 1): 64 MiB, sixteen million floats — two orders of magnitude above the trained policies' largest
/// layer, and far below what a server can afford per match and per replay.
pub const MAX_TENSOR_BYTES: usize = 64 << 20;

/// Why an optimised graph's cost could depend on its input, if it could: a control-flow node (a loop,
/// a scan, a branch), or a node whose output shape is not known once the input's is (`NonZero`, a
/// shape read from the data), or an intermediate tensor over [`MAX_TENSOR_BYTES`]. Without them every
/// call allocates the same tensors and runs the same kernels, so what an admission measured (time,
/// memory, the output's width) holds for every observation a match shows the network.
fn input_dependent(model: &tract_onnx::prelude::TypedModel) -> Option<String> {
    for node in model.nodes() {
        let op = node.op.name();
        if ["Scan", "Loop", "If"].iter().any(|c| op.contains(c)) {
            return Some(format!(
                "its node '{}' ({op}) is control flow: its work would depend on its input",
                node.name
            ));
        }
        for outlet in &node.outputs {
            let Some(shape) = outlet.fact.shape.as_concrete() else {
                return Some(format!(
                    "its node '{}' ({op}) makes a tensor of shape {:?}, known only from the input's values",
                    node.name, outlet.fact.shape
                ));
            };
            let bytes = shape
                .iter()
                .product::<usize>()
                .saturating_mul(outlet.fact.datum_type.size_of());
            if bytes > MAX_TENSOR_BYTES {
                return Some(format!(
                    "its node '{}' ({op}) makes a tensor of {bytes} bytes; at most {MAX_TENSOR_BYTES}",
                    node.name
                ));
            }
        }
    }
    None
}

/// A tensor that a node of `g` (or of a subgraph) makes from a constant shape — ConstantOfShape,
/// Expand, RandomNormal, RandomUniform — bigger than [`MAX_TENSOR_BYTES`]: its node and its bytes.
/// tract evaluates such nodes while it reads the graph (constants are folded as soon as their
/// inputs are known), so a few hundred bytes of file could take gigabytes before any check on the
/// typed graph: the shapes are read from the file first. (A shape computed from constants by other
/// nodes is not followed: the server admits a submission in a process whose memory and CPU time
/// are limited, which bounds such a graph.)
fn oversized_generator(g: &tract_onnx::pb::GraphProto) -> Option<(String, usize)> {
    let shape_of = |name: &str| -> Option<Vec<i64>> {
        let t = g.initializer.iter().find(|t| t.name == name)?;
        if !t.int64_data.is_empty() {
            return Some(t.int64_data.clone());
        }
        Some(
            t.raw_data
                .chunks_exact(8)
                .map(|b| i64::from_le_bytes(b.try_into().unwrap_or([0; 8])))
                .collect(),
        )
    };
    let bytes = |dims: &[i64]| {
        dims.iter()
            .try_fold(4usize, |n, &d| {
                n.checked_mul(usize::try_from(d.max(0)).ok()?)
            })
            .unwrap_or(usize::MAX)
    };
    let mine = g.node.iter().find_map(|n| {
        let dims = match n.op_type.as_str() {
            "ConstantOfShape" => shape_of(n.input.first()?)?,
            "Expand" => shape_of(n.input.get(1)?)?,
            "RandomNormal" | "RandomUniform" => {
                n.attribute.iter().find(|a| a.name == "shape")?.ints.clone()
            }
            _ => return None,
        };
        let b = bytes(&dims);
        let label = if n.name.is_empty() {
            &n.op_type
        } else {
            &n.name
        };
        (b > MAX_TENSOR_BYTES).then(|| (label.clone(), b))
    });
    mine.or_else(|| {
        g.node
            .iter()
            .flat_map(|n| &n.attribute)
            .flat_map(|a| a.g.iter().chain(&a.graphs))
            .find_map(oversized_generator)
    })
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

/// Checks an MLP's shapes and values for `obs` inputs; returns its output width.
pub(crate) fn validate_mlp(p: &Mlp, obs: usize) -> Result<usize, CheckpointError> {
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
