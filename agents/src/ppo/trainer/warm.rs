//! A warm start from a checkpoint file: a trained policy carried into a fresh run.

use candle_core::{Device, Tensor};

use crate::checkpoint::Checkpoint;
use crate::ppo::normalizer::EPSILON;

use super::*;

impl Trainer {
    /// Starts this fresh run from `ck`'s policy: its actor's weights, its σ (as trained: a
    /// checkpoint saved with scaled noise is scaled back), its observation statistics (counted as
    /// seen over its training steps, so they move as slowly as they would have in its run). The
    /// critic, the privileged observation's statistics and the optimiser stay fresh: a checkpoint
    /// holds none of them (pair it with `ppo.critic_warmup`). `ck` must be of this run's method,
    /// controller and observation, and its actor of this configuration's layers; `source` names
    /// it in the run's provenance.
    pub fn warm_start_from_checkpoint(
        &mut self,
        ck: &Checkpoint,
        source: &str,
    ) -> Result<(), String> {
        let training = ck.training.as_ref();
        if let Some(m) = training.map(|t| t.method.as_str()) {
            if m != self.method.name() {
                return Err(format!(
                    "{source} holds a {m} policy, not {}",
                    self.method.name()
                ));
            }
        }
        if ck.controller != self.controller {
            return Err(format!(
                "{source}: its controller ({}) is not this run's ({}): check the configuration's \
                 [controller] against the checkpoint's",
                serde_json::to_string(&ck.controller).unwrap_or_default(),
                serde_json::to_string(&self.controller).unwrap_or_default()
            ));
        }
        let blocks = self.config.obs_blocks();
        if ck.observation.blocks != blocks || ck.observation.replan != self.config.replan {
            return Err(format!(
                "{source}: observation {:?} ({:?}), this run's is {:?} ({:?})",
                ck.observation.blocks, ck.observation.replan, blocks, self.config.replan
            ));
        }
        if ck.observation.mean.len() != self.obs_dim {
            return Err(format!(
                "{source}: observations of {} entries, this run has {}",
                ck.observation.mean.len(),
                self.obs_dim
            ));
        }
        let mlp = ck.policy.as_ref().ok_or_else(|| {
            format!("{source}: its policy is an ONNX network; training starts only from an MLP")
        })?;
        if mlp.layers.len() != self.net.actor.len() {
            return Err(format!(
                "{source}: an actor of {} layers, this configuration's has {} (ppo.hidden)",
                mlp.layers.len(),
                self.net.actor.len()
            ));
        }
        let scale = training.and_then(|t| t.noise_scale).unwrap_or(1.0);
        if scale.is_nan() || scale <= 0.0 {
            return Err(format!(
                "{source}: it plays with {scale} times its trained noise, so its trained σ is lost"
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
        for (k, (layer, dense)) in mlp.layers.iter().zip(&self.net.actor).enumerate() {
            let (outputs, inputs) = dense.w.as_tensor().dims2().map_err(e)?;
            if layer.bias.len() != outputs
                || layer.weights.iter().any(|r| r.len() != inputs)
                || layer.weights.len() != outputs
            {
                return Err(format!(
                    "{source}: actor layer {k} is not {outputs}×{inputs} as this configuration's (ppo.hidden)"
                ));
            }
            let w: Vec<f32> = layer.weights.iter().flatten().map(|&x| x as f32).collect();
            let b: Vec<f32> = layer.bias.iter().map(|&x| x as f32).collect();
            dense
                .w
                .set(&Tensor::from_vec(w, (outputs, inputs), &Device::Cpu).map_err(e)?)
                .map_err(e)?;
            dense
                .b
                .set(&Tensor::from_vec(b, outputs, &Device::Cpu).map_err(e)?)
                .map_err(e)?;
        }
        let log_std: Vec<f32> = std.iter().map(|s| (s / scale).ln() as f32).collect();
        self.net
            .log_std
            .set(&Tensor::from_vec(log_std, self.act_dim, &Device::Cpu).map_err(e)?)
            .map_err(e)?;
        self.normalizer.mean = ck.observation.mean.clone();
        self.normalizer.var = ck
            .observation
            .std
            .iter()
            .map(|s| (s - EPSILON).max(0.0).powi(2))
            .collect();
        self.normalizer.count = training.map(|t| t.env_steps).unwrap_or(0).max(1);
        self.progress.warm_start = Some(format!(
            "{source} (checkpoint '{}'{}; policy only: critic and optimiser fresh, the critic alone \
             for the first {} iterations)",
            ck.name,
            training
                .map(|t| format!(", {} steps", t.env_steps))
                .unwrap_or_default(),
            self.config.ppo.critic_warmup
        ));
        Ok(())
    }
}
