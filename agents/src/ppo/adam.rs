//! Adam (Kingma & Ba 2015, PyTorch's defaults β = (0.9, 0.999), ε = 1e-8, no weight decay) over
//! candle variables, with its moments in the open so that a training run can save them and resume
//! exactly where it stopped. (candle-nn's `AdamW` keeps its moments private: a run resumed with it
//! would restart them at zero and no longer be the same run.) Also gradient-norm clipping as
//! `torch.nn.utils.clip_grad_norm_`.

use candle_core::backprop::GradStore;
use candle_core::{Result, Tensor, Var};

/// Adam's first and second moments per variable, and its step counts.
pub struct Adam {
    vars: Vec<Var>,
    /// First moments, one per variable.
    pub m: Vec<Tensor>,
    /// Second moments, one per variable.
    pub v: Vec<Tensor>,
    /// Steps taken.
    pub t: u64,
    /// Steps each variable took part in (had a gradient), as PyTorch counts them per parameter:
    /// the bias correction of a variable's moments counts its own updates, so a variable that
    /// sat out steps (the policy during a critic warm-up) starts as a fresh Adam would start it.
    /// Equal to `t` for every variable when every step updates all of them.
    pub var_steps: Vec<u64>,
    /// Learning rate.
    pub lr: f64,
}

const BETA1: f64 = 0.9;
const BETA2: f64 = 0.999;
const EPS: f64 = 1e-8;

impl Adam {
    /// Adam over `vars` at learning rate `lr`, moments zero.
    pub fn new(vars: Vec<Var>, lr: f64) -> Result<Adam> {
        let m = vars
            .iter()
            .map(|v| v.as_tensor().zeros_like())
            .collect::<Result<Vec<_>>>()?;
        let v = m.clone();
        Ok(Adam {
            var_steps: vec![0; vars.len()],
            vars,
            m,
            v,
            t: 0,
            lr,
        })
    }

    /// One step on `grads` (variables without a gradient keep their value and moments).
    pub fn step(&mut self, grads: &GradStore) -> Result<()> {
        self.t += 1;
        for (k, var) in self.vars.iter().enumerate() {
            let Some(g) = grads.get(var) else { continue };
            self.var_steps[k] += 1;
            let c1 = 1.0 - BETA1.powi(self.var_steps[k] as i32);
            let c2 = 1.0 - BETA2.powi(self.var_steps[k] as i32);
            let m = ((&self.m[k] * BETA1)? + (g * (1.0 - BETA1))?)?;
            let v = ((&self.v[k] * BETA2)? + (g.sqr()? * (1.0 - BETA2))?)?;
            let step = ((&m / c1)? / ((&v / c2)?.sqrt()? + EPS)?)?;
            var.set(&(var.as_tensor() - (step * self.lr)?)?)?;
            // Detached: each moment would otherwise keep the graph of every step before it, a
            // chain as long as the run (memory, and a stack overflow when it is dropped).
            self.m[k] = m.detach();
            self.v[k] = v.detach();
        }
        Ok(())
    }
}

/// Scales `grads` of `vars` so that their joint L2 norm is at most `max_norm`; returns the norm
/// before clipping (as `clip_grad_norm_` does, with its 1e-6 in the divisor).
pub fn clip_grad_norm(grads: &mut GradStore, vars: &[Var], max_norm: f64) -> Result<f64> {
    let mut total = 0.0f64;
    for var in vars {
        if let Some(g) = grads.get(var) {
            total += g.sqr()?.sum_all()?.to_scalar::<f32>()? as f64;
        }
    }
    let norm = total.sqrt();
    let coef = max_norm / (norm + 1e-6);
    if coef < 1.0 {
        for var in vars {
            if let Some(g) = grads.remove(var) {
                grads.insert(var, (g * coef)?);
            }
        }
    }
    Ok(norm)
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Tensor};

    #[test]
    fn first_step_moves_each_weight_by_the_learning_rate() {
        // Adam's first bias-corrected step is lr · g/|g| per entry (up to ε).
        let x =
            Var::from_tensor(&Tensor::new(&[1.0f32, -2.0, 3.0], &Device::Cpu).unwrap()).unwrap();
        let mut adam = Adam::new(vec![x.clone()], 0.1).unwrap();
        let loss = (x.as_tensor().sqr().unwrap().sum_all().unwrap() * 0.5).unwrap();
        let grads = loss.backward().unwrap();
        adam.step(&grads).unwrap();
        let got = x.as_tensor().to_vec1::<f32>().unwrap();
        for (g, w) in got.iter().zip([0.9f32, -1.9, 2.9]) {
            assert!((g - w).abs() < 1e-6, "{got:?}");
        }
    }

    #[test]
    fn a_variable_that_sat_out_steps_starts_as_a_fresh_adam_would() {
        // y takes no part in the first 50 steps (no gradient); its first step is then lr · sign(g),
        // the bias correction counting its own updates, not the optimiser's.
        let dev = &Device::Cpu;
        let x = Var::from_tensor(&Tensor::new(&[1.0f32], dev).unwrap()).unwrap();
        let y = Var::from_tensor(&Tensor::new(&[2.0f32], dev).unwrap()).unwrap();
        let mut adam = Adam::new(vec![x.clone(), y.clone()], 0.1).unwrap();
        for _ in 0..50 {
            let loss = x.as_tensor().sqr().unwrap().sum_all().unwrap();
            adam.step(&loss.backward().unwrap()).unwrap();
        }
        assert_eq!((adam.t, adam.var_steps.clone()), (50, vec![50, 0]));
        let loss = (x.as_tensor().sqr().unwrap() + y.as_tensor().sqr().unwrap())
            .unwrap()
            .sum_all()
            .unwrap();
        adam.step(&loss.backward().unwrap()).unwrap();
        let got = y.as_tensor().to_vec1::<f32>().unwrap()[0];
        assert!((got - 1.9).abs() < 1e-6, "{got}");
    }

    #[test]
    fn clipping_scales_to_the_max_norm() {
        let x = Var::from_tensor(&Tensor::new(&[3.0f32, 4.0], &Device::Cpu).unwrap()).unwrap();
        let loss = (x.as_tensor().sqr().unwrap().sum_all().unwrap() * 0.5).unwrap();
        let mut grads = loss.backward().unwrap(); // gradient (3, 4), norm 5
        let norm = clip_grad_norm(&mut grads, std::slice::from_ref(&x), 1.0).unwrap();
        assert!((norm - 5.0).abs() < 1e-6);
        let g = grads.get(&x).unwrap().to_vec1::<f32>().unwrap();
        assert!(
            (g[0] - 0.6).abs() < 1e-5 && (g[1] - 0.8).abs() < 1e-5,
            "{g:?}"
        );
    }
}
