//! The actor-critic of PPO on candle: an actor MLP (observation → the Gaussian's mean action), a
//! critic MLP (observation → value) and a learned log standard deviation per action entry
//! (state-independent, as rsl_rl's). Weights are initialised as PyTorch's `nn.Linear`
//! (uniform ±1/√fan_in) but from our own seeded stream, so a training seed fixes them on every
//! machine. The actor exports to the checkpoint format's MLP, which players run without candle.

use candle_core::{DType, Device, Result, Tensor, Var};
use sim::rng::Rng;

use crate::checkpoint::{Activation, Layer, Mlp};

/// One dense layer's variables: `w` `[out, in]` (a row per output, as the checkpoint stores it), `b`.
pub struct Dense {
    /// Weights.
    pub w: Var,
    /// Biases.
    pub b: Var,
}

fn dense(rng: &mut Rng, inputs: usize, outputs: usize, scale: f64) -> Result<Dense> {
    let bound = scale / (inputs as f64).sqrt();
    let w: Vec<f32> = (0..inputs * outputs)
        .map(|_| rng.uniform(-bound, bound) as f32)
        .collect();
    let b: Vec<f32> = (0..outputs)
        .map(|_| rng.uniform(-bound, bound) as f32)
        .collect();
    Ok(Dense {
        w: Var::from_tensor(&Tensor::from_vec(w, (outputs, inputs), &Device::Cpu)?)?,
        b: Var::from_tensor(&Tensor::from_vec(b, outputs, &Device::Cpu)?)?,
    })
}

fn mlp(
    rng: &mut Rng,
    inputs: usize,
    hidden: &[usize],
    outputs: usize,
    last: f64,
) -> Result<Vec<Dense>> {
    let mut layers = Vec::new();
    let mut width = inputs;
    for &h in hidden {
        layers.push(dense(rng, width, h, 1.0)?);
        width = h;
    }
    layers.push(dense(rng, width, outputs, last)?);
    Ok(layers)
}

fn forward(layers: &[Dense], x: &Tensor) -> Result<Tensor> {
    let mut x = x.clone();
    for (k, l) in layers.iter().enumerate() {
        x = x
            .matmul(&l.w.as_tensor().t()?)?
            .broadcast_add(l.b.as_tensor())?;
        if k + 1 < layers.len() {
            x = x.elu(1.0)?;
        }
    }
    Ok(x)
}

/// Actor, critic and the policy's log standard deviation.
pub struct ActorCritic {
    /// Observation → mean action (ELU hidden layers, linear output).
    pub actor: Vec<Dense>,
    /// Observation → value.
    pub critic: Vec<Dense>,
    /// log σ per action entry.
    pub log_std: Var,
}

impl ActorCritic {
    /// A fresh network: hidden layers `hidden` for both, σ = `init_std`, weights from `seed`. The
    /// actor's output layer starts 100× smaller than PyTorch's default, so the first mean action is
    /// close to zero (the middle of every range) whatever the observation. The critic reads
    /// `critic_obs` ≥ `obs` entries: the actor's observation, then what only the critic sees.
    pub fn new(
        obs: usize,
        critic_obs: usize,
        actions: usize,
        hidden: &[usize],
        init_std: f64,
        seed: u64,
    ) -> Result<ActorCritic> {
        let mut rng = Rng::seeded(seed);
        let actor = mlp(&mut rng, obs, hidden, actions, 0.01)?;
        let critic = mlp(&mut rng, critic_obs, hidden, 1, 1.0)?;
        let log_std = Var::from_tensor(&Tensor::from_vec(
            vec![init_std.ln() as f32; actions],
            actions,
            &Device::Cpu,
        )?)?;
        Ok(ActorCritic {
            actor,
            critic,
            log_std,
        })
    }

    /// Every trained variable, in a fixed order (actor w, b per layer; critic; log σ).
    pub fn vars(&self) -> Vec<Var> {
        let mut v = Vec::new();
        for l in self.actor.iter().chain(&self.critic) {
            v.push(l.w.clone());
            v.push(l.b.clone());
        }
        v.push(self.log_std.clone());
        v
    }

    /// Mean actions `[batch, actions]` for normalised observations `[batch, obs]`.
    pub fn mean(&self, obs: &Tensor) -> Result<Tensor> {
        forward(&self.actor, obs)
    }

    /// Values `[batch]` of the critic's inputs `[batch, critic_obs]`.
    pub fn value(&self, obs: &Tensor) -> Result<Tensor> {
        forward(&self.critic, obs)?.squeeze(1)
    }

    /// σ per action entry.
    pub fn std(&self) -> Result<Vec<f32>> {
        self.log_std.as_tensor().exp()?.to_vec1::<f32>()
    }

    /// The actor as the checkpoint format's MLP (ELU hidden layers, linear output).
    pub fn actor_mlp(&self) -> Result<Mlp> {
        let n = self.actor.len();
        let layers = self
            .actor
            .iter()
            .enumerate()
            .map(|(k, l)| {
                let w = l.w.as_tensor().to_dtype(DType::F64)?.to_vec2::<f64>()?;
                let b = l.b.as_tensor().to_dtype(DType::F64)?.to_vec1::<f64>()?;
                Ok(Layer {
                    weights: w,
                    bias: b,
                    activation: if k + 1 < n {
                        Activation::Elu
                    } else {
                        Activation::Linear
                    },
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Mlp { layers })
    }

    /// Every variable's tensor, by a stable name (for saving).
    pub fn named(&self) -> Vec<(String, Tensor)> {
        let mut out = Vec::new();
        for (net, layers) in [("actor", &self.actor), ("critic", &self.critic)] {
            for (k, l) in layers.iter().enumerate() {
                out.push((format!("{net}.{k}.w"), l.w.as_tensor().clone()));
                out.push((format!("{net}.{k}.b"), l.b.as_tensor().clone()));
            }
        }
        out.push(("log_std".into(), self.log_std.as_tensor().clone()));
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exported_actor_matches_the_candle_forward() {
        let ac = ActorCritic::new(5, 5, 3, &[8, 4], 0.5, 9).unwrap();
        // Scale the output layer up so the comparison is not of near-zero numbers.
        let last = ac.actor.last().unwrap();
        last.w.set(&(last.w.as_tensor() * 100.0).unwrap()).unwrap();
        let x = [0.3f32, -1.2, 0.8, 2.0, -0.1];
        let t = Tensor::from_vec(x.to_vec(), (1, 5), &Device::Cpu).unwrap();
        let got = ac.mean(&t).unwrap().to_vec2::<f32>().unwrap()[0].clone();
        let x64: Vec<f64> = x.iter().map(|&v| v as f64).collect();
        let want = ac.actor_mlp().unwrap().forward(&x64);
        for (g, w) in got.iter().zip(&want) {
            assert!((*g as f64 - w).abs() < 1e-5, "{got:?} vs {want:?}");
        }
        assert!(ac.std().unwrap().iter().all(|s| (s - 0.5).abs() < 1e-6));
    }

    #[test]
    fn same_seed_same_weights() {
        let a = ActorCritic::new(4, 4, 2, &[6], 1.0, 3).unwrap();
        let b = ActorCritic::new(4, 4, 2, &[6], 1.0, 3).unwrap();
        for ((_, x), (_, y)) in a.named().iter().zip(b.named()) {
            assert_eq!(
                x.flatten_all().unwrap().to_vec1::<f32>().unwrap(),
                y.flatten_all().unwrap().to_vec1::<f32>().unwrap()
            );
        }
    }
}
