//! A warm start from a checkpoint file: a trained policy carried into a fresh run.

use candle_core::{Device, Tensor};

use crate::checkpoint::{Activation, Checkpoint};
use crate::ppo::normalizer::EPSILON;

use super::*;

/// The observation count a checkpoint's statistics are given when it says less: a checkpoint
/// records its run's env steps, not what its normaliser saw (a warm-started run's saw more), and
/// a low count would let the new run's first batch (fresh episode starts) replace them.
pub const WARM_NORMALIZER_COUNT: u64 = 1_000_000;

impl Trainer {
    /// Starts this fresh run from `ck`'s policy: its actor's weights, its σ (as trained: a
    /// checkpoint saved with scaled noise is scaled back), its observation statistics (counted as
    /// seen over its training steps, at least [`WARM_NORMALIZER_COUNT`]). The critic, the
    /// privileged observation's statistics and the optimiser stay fresh: a checkpoint holds none
    /// of them (pair it with `ppo.critic_warmup`). `ck` must be of this run's method, controller,
    /// action noise, grip floor and observation, and its actor of this configuration's layers;
    /// nothing is changed when it is not. `source` names it in the run's provenance.
    pub fn warm_start_from_checkpoint(
        &mut self,
        ck: &Checkpoint,
        source: &str,
    ) -> Result<(), String> {
        let (weights, log_std, std_scale) = self.checked_policy(ck, source)?;
        let e = |err: candle_core::Error| format!("{source}: {err}");
        for (dense, (w, b)) in self.net.actor.iter().zip(weights) {
            dense.w.set(&w).map_err(e)?;
            dense.b.set(&b).map_err(e)?;
        }
        self.net.log_std.set(&log_std).map_err(e)?;
        self.normalizer.mean = ck.observation.mean.clone();
        self.normalizer.var = ck
            .observation
            .std
            .iter()
            .map(|s| (s - EPSILON).powi(2))
            .collect();
        let training = ck.training.as_ref();
        self.normalizer.count = training
            .map(|t| t.env_steps)
            .unwrap_or(0)
            .max(WARM_NORMALIZER_COUNT);
        let mut words = vec![format!("checkpoint '{}'", ck.name)];
        if let Some(t) = training {
            words.push(format!(
                "{} {} steps, seed {}, commit {}",
                t.method, t.env_steps, t.seed, t.git_commit
            ));
            if let Some(w) = &t.warm_start {
                words.push(format!("itself from {w}"));
            }
        }
        if std_scale != 1.0 {
            words.push(format!("its σ ÷ {std_scale}, as trained"));
        }
        words.push(format!(
            "its policy and observation statistics (count {}); critic and optimiser fresh{}",
            self.normalizer.count,
            match self.config.ppo.critic_warmup {
                0 => String::new(),
                n => format!(", the critic alone for the first {n} iterations"),
            }
        ));
        self.progress.warm_start = Some(format!("{source} ({})", words.join("; ")));
        Ok(())
    }

    /// Checks `ck` against this run and returns its actor's tensors (weights, biases per layer),
    /// its trained log σ and the noise scale it was saved at.
    #[allow(clippy::type_complexity)]
    fn checked_policy(
        &self,
        ck: &Checkpoint,
        source: &str,
    ) -> Result<(Vec<(Tensor, Tensor)>, Tensor, f64), String> {
        let training = ck.training.as_ref();
        if let Some(m) = training.map(|t| t.method.as_str()) {
            if m != self.method.name() {
                return Err(format!(
                    "{source}: training.method is {m}, this run trains {}",
                    self.method.name()
                ));
            }
        }
        if ck.controller != self.controller {
            let (a, b) = (
                serde_json::to_value(&ck.controller).unwrap_or_default(),
                serde_json::to_value(&self.controller).unwrap_or_default(),
            );
            let differ: Vec<String> = match (a.as_object(), b.as_object()) {
                (Some(a), Some(b)) => a
                    .keys()
                    .chain(b.keys())
                    .filter(|k| a.get(*k) != b.get(*k))
                    .map(|k| format!("controller.{k}"))
                    .collect::<std::collections::BTreeSet<_>>()
                    .into_iter()
                    .collect(),
                _ => vec!["controller".into()],
            };
            return Err(format!(
                "{source}: {} differ from this run's (its [controller] configuration)",
                differ.join(", ")
            ));
        }
        let scale = training.and_then(|t| t.noise_scale).unwrap_or(1.0);
        if scale.is_nan() || scale <= 0.0 {
            return Err(format!(
                "{source}: training.noise_scale is {scale}: it plays without its trained σ, \
                 which training needs"
            ));
        }
        let noise = ck.action_noise.unwrap_or(0.0) / scale;
        if (noise - self.config.controller.action_noise).abs() > 1e-9 {
            return Err(format!(
                "{source}: action_noise {noise} as trained, this run's [controller] action_noise is {}",
                self.config.controller.action_noise
            ));
        }
        let floor = ck.grip_floor.unwrap_or(0.0);
        if floor != self.config.controller.grip_floor {
            return Err(format!(
                "{source}: grip_floor {floor}, this run's [controller] grip_floor is {}",
                self.config.controller.grip_floor
            ));
        }
        let blocks = self.config.obs_blocks();
        if ck.observation.blocks != blocks {
            return Err(format!(
                "{source}: observation.blocks {:?}, this run observes {:?}",
                ck.observation.blocks, blocks
            ));
        }
        if ck.observation.replan != self.config.replan {
            return Err(format!(
                "{source}: observation.replan {:?}, this run's replan is {:?}",
                ck.observation.replan, self.config.replan
            ));
        }
        if ck.observation.mean.len() != self.obs_dim {
            return Err(format!(
                "{source}: observation.mean holds {} entries, this run observes {}",
                ck.observation.mean.len(),
                self.obs_dim
            ));
        }
        if let Some(i) = ck.observation.std.iter().position(|&s| s < EPSILON) {
            return Err(format!(
                "{source}: observation.std[{i}] is below the trainer's ε {EPSILON}: not a \
                 statistic this trainer wrote"
            ));
        }
        let mlp = ck.policy.as_ref().ok_or_else(|| {
            format!("{source}: its policy is an ONNX network (onnx); training starts only from an MLP (policy)")
        })?;
        if mlp.layers.len() != self.net.actor.len() {
            return Err(format!(
                "{source}: an actor of {} layers, this configuration's has {} (ppo.hidden)",
                mlp.layers.len(),
                self.net.actor.len()
            ));
        }
        let std = ck.policy_std.as_ref().ok_or_else(|| {
            format!("{source}: no policy_std (it plays its mean action); training needs its σ")
        })?;
        if std.len() != self.act_dim || std.iter().any(|s| s.is_nan() || *s <= 0.0) {
            return Err(format!(
                "{source}: policy_std must hold {} entries > 0",
                self.act_dim
            ));
        }
        let e = |err: candle_core::Error| format!("{source}: {err}");
        let last = mlp.layers.len() - 1;
        let mut weights = Vec::new();
        for (k, (layer, dense)) in mlp.layers.iter().zip(&self.net.actor).enumerate() {
            let want = if k == last {
                Activation::Linear
            } else {
                Activation::Elu
            };
            if layer.activation != want {
                return Err(format!(
                    "{source}: policy.layers[{k}].activation is {:?}; the trainer's actor has {want:?} there",
                    layer.activation
                ));
            }
            let (outputs, inputs) = dense.w.as_tensor().dims2().map_err(e)?;
            if layer.bias.len() != outputs
                || layer.weights.len() != outputs
                || layer.weights.iter().any(|r| r.len() != inputs)
            {
                return Err(format!(
                    "{source}: policy.layers[{k}] is not {outputs}×{inputs} as this configuration's actor (ppo.hidden)"
                ));
            }
            let w: Vec<f32> = layer.weights.iter().flatten().map(|&x| x as f32).collect();
            let b: Vec<f32> = layer.bias.iter().map(|&x| x as f32).collect();
            weights.push((
                Tensor::from_vec(w, (outputs, inputs), &Device::Cpu).map_err(e)?,
                Tensor::from_vec(b, outputs, &Device::Cpu).map_err(e)?,
            ));
        }
        let log_std: Vec<f32> = std.iter().map(|s| (s / scale).ln() as f32).collect();
        let log_std = Tensor::from_vec(log_std, self.act_dim, &Device::Cpu).map_err(e)?;
        Ok((weights, log_std, scale))
    }
}
