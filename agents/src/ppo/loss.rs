//! PPO's losses on candle tensors, with rsl_rl's definitions (docs/design.md §11): the diagonal Gaussian's
//! log-density and entropy, the clipped surrogate, the clipped value loss and the KL divergence
//! between the rollout's policy and the current one (which drives the adaptive learning rate).
//! Autodiff is candle's; these functions only write the formulas.

use candle_core::{Result, Tensor, D};

const HALF_LN_2PI: f64 = 0.918_938_533_204_672_7;

/// log π(a) of a diagonal Gaussian: `actions`, `mean` `[batch, n]`, `log_std` `[n]` → `[batch]`.
pub fn log_prob(actions: &Tensor, mean: &Tensor, log_std: &Tensor) -> Result<Tensor> {
    let n = log_std.dims1()? as f64;
    let z = (actions - mean)?.broadcast_div(&log_std.exp()?)?;
    let quad = (z.sqr()?.sum(D::Minus1)? * -0.5)?;
    let norm = (log_std.sum_all()? + n * HALF_LN_2PI)?;
    quad.broadcast_sub(&norm)
}

/// Entropy of the diagonal Gaussian (the same for every state): `Σ (½ + ½ ln 2π + log σ)`.
pub fn entropy(log_std: &Tensor) -> Result<Tensor> {
    let n = log_std.dims1()? as f64;
    log_std.sum_all()? + n * (0.5 + HALF_LN_2PI)
}

/// The bound on `logp − old_logp` in [`surrogate_loss`]: ρ stays within [e^−20, e^20] ≈
/// [2·10⁻⁹, 5·10⁸].
pub const MAX_LOG_RATIO: f64 = 20.0;

/// The clipped surrogate `mean(max(−A·ρ, −A·clip(ρ, 1 − ε, 1 + ε)))`, `ρ = exp(logp − old_logp)`.
///
/// `logp − old_logp` is held within ±[`MAX_LOG_RATIO`] before the exponential: summed over a few
/// hundred action entries, one large update can take it past 88.7, where f32's `exp` overflows,
/// and an infinite ρ makes the whole gradient NaN (a Muscle-PD run on MyoSuite's robot lost its
/// policy so at 3.6 M steps). Past the bound a row gives no gradient, as a clipped row gives none.
pub fn surrogate_loss(
    logp: &Tensor,
    old_logp: &Tensor,
    advantages: &Tensor,
    clip: f64,
) -> Result<Tensor> {
    let ratio = (logp - old_logp)?
        .clamp(-MAX_LOG_RATIO, MAX_LOG_RATIO)?
        .exp()?;
    let unclipped = (advantages.neg()? * &ratio)?;
    let clipped = (advantages.neg()? * ratio.clamp(1.0 - clip, 1.0 + clip)?)?;
    unclipped.maximum(&clipped)?.mean_all()
}

/// The clipped value loss `mean(max((V − R)², (V_old + clip(V − V_old, −ε, ε) − R)²))`.
pub fn value_loss(
    values: &Tensor,
    old_values: &Tensor,
    returns: &Tensor,
    clip: f64,
) -> Result<Tensor> {
    let clipped = (old_values + (values - old_values)?.clamp(-clip, clip)?)?;
    let a = (values - returns)?.sqr()?;
    let b = (clipped - returns)?.sqr()?;
    a.maximum(&b)?.mean_all()
}

/// How far the policy's means lie past the action bounds: `mean over the batch of Σ_d
/// max(|μ_d| − b, 0)²` (`mean` `[batch, n]`). The environment clips actions to [−1, 1], so a mean
/// far past a bound gives the same clipped action for almost every sample: its surrogate gradient
/// vanishes and nothing in the reward can bring it back (the bound loss of rl_games, the PPO of
/// IsaacGymEnvs, answers the same; rsl_rl has none).
pub fn bound_loss(mean: &Tensor, bound: f64) -> Result<Tensor> {
    (mean.abs()? - bound)?
        .relu()?
        .sqr()?
        .sum(D::Minus1)?
        .mean_all()
}

/// Mean over the batch of KL(old ‖ new) between diagonal Gaussians, summed over the action entries:
/// `Σ log(σ/σ_old) + (σ_old² + (μ_old − μ)²)/(2σ²) − ½`. `*_mean` `[batch, n]`, `*_log_std` `[n]`.
pub fn gaussian_kl(
    old_mean: &Tensor,
    old_log_std: &Tensor,
    mean: &Tensor,
    log_std: &Tensor,
) -> Result<Tensor> {
    let var = (log_std * 2.0)?.exp()?;
    let old_var = (old_log_std * 2.0)?.exp()?;
    let log_ratio = (log_std - old_log_std)?;
    let quad = (old_mean - mean)?
        .sqr()?
        .broadcast_add(&old_var)?
        .broadcast_div(&(var * 2.0)?)?;
    let per = (quad.broadcast_add(&log_ratio)? - 0.5)?;
    per.sum(D::Minus1)?.mean_all()
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    fn t(x: &[f32]) -> Tensor {
        Tensor::new(x, &Device::Cpu).unwrap()
    }

    fn scalar(x: &Tensor) -> f32 {
        x.to_scalar::<f32>().unwrap()
    }

    #[test]
    fn a_ratio_past_f32s_range_gives_a_finite_loss_and_no_gradient() {
        // logp − old_logp = 200: exp would overflow to inf, and with A < 0 the unclipped −A·ρ
        // would be the larger term: the loss and its gradient would be inf and NaN.
        let x = Var::from_tensor(&t(&[200.0, 0.1])).unwrap();
        let l = surrogate_loss(x.as_tensor(), &t(&[0.0, 0.0]), &t(&[-1.0, -1.0]), 0.2).unwrap();
        let want = (MAX_LOG_RATIO.exp() + 0.1f64.exp()) / 2.0;
        assert!(
            (scalar(&l) as f64 / want - 1.0).abs() < 1e-5,
            "{}",
            scalar(&l)
        );
        let g = l
            .backward()
            .unwrap()
            .get(&x)
            .unwrap()
            .to_vec1::<f32>()
            .unwrap();
        assert_eq!(g[0], 0.0, "past the bound the row pulls on nothing");
        assert!((g[1] as f64 - 0.1f64.exp() / 2.0).abs() < 1e-6, "{g:?}");
    }

    #[test]
    fn surrogate_inside_at_and_past_the_clip() {
        let clip = 0.2;
        // ρ = 1.1 (inside), A = 1: −1.1.
        let l = surrogate_loss(&t(&[1.1f32.ln()]), &t(&[0.0]), &t(&[1.0]), clip).unwrap();
        assert!((scalar(&l) + 1.1).abs() < 1e-6);
        // ρ = 1.2 (at the clip), A = 1: −1.2.
        let l = surrogate_loss(&t(&[1.2f32.ln()]), &t(&[0.0]), &t(&[1.0]), clip).unwrap();
        assert!((scalar(&l) + 1.2).abs() < 1e-6);
        // ρ = 1.5 past it, A = 1: the clipped −1.2 is the larger, so the loss is −1.2 ...
        let x = Var::from_tensor(&t(&[1.5f32.ln()])).unwrap();
        let l = surrogate_loss(x.as_tensor(), &t(&[0.0]), &t(&[1.0]), clip).unwrap();
        assert!((scalar(&l) + 1.2).abs() < 1e-6);
        // ... and it no longer pulls on the policy.
        let g = l.backward().unwrap();
        assert_eq!(g.get(&x).unwrap().to_vec1::<f32>().unwrap(), vec![0.0]);
        // ρ = 0.5, A = −1 (pessimistic side): max(0.5, 0.8) = 0.8.
        let l = surrogate_loss(&t(&[0.5f32.ln()]), &t(&[0.0]), &t(&[-1.0]), clip).unwrap();
        assert!((scalar(&l) - 0.8).abs() < 1e-6);
        // Batch mean: (−1.1 + 0.8) / 2.
        let l = surrogate_loss(
            &t(&[1.1f32.ln(), 0.5f32.ln()]),
            &t(&[0.0, 0.0]),
            &t(&[1.0, -1.0]),
            clip,
        )
        .unwrap();
        assert!((scalar(&l) + 0.15).abs() < 1e-6);
    }

    #[test]
    fn value_loss_takes_the_worse_of_clipped_and_not() {
        // V_old = 0, R = 1, ε = 0.2. V = 0.5: unclipped 0.25, clipped (0.2 − 1)² = 0.64 → 0.64.
        let l = value_loss(&t(&[0.5]), &t(&[0.0]), &t(&[1.0]), 0.2).unwrap();
        assert!((scalar(&l) - 0.64).abs() < 1e-6);
        // V = 0.1 (inside the clip): both 0.81.
        let l = value_loss(&t(&[0.1]), &t(&[0.0]), &t(&[1.0]), 0.2).unwrap();
        assert!((scalar(&l) - 0.81).abs() < 1e-6);
        // V = 1.5 overshoots: unclipped 0.25, clipped 0.64 → 0.64.
        let l = value_loss(&t(&[1.5]), &t(&[0.0]), &t(&[1.0]), 0.2).unwrap();
        assert!((scalar(&l) - 0.64).abs() < 1e-6);
    }

    #[test]
    fn bound_loss_is_zero_inside_and_quadratic_past_the_bound() {
        // Two samples of two entries: inside, at the bound, past it on either side.
        let mean =
            Var::from_tensor(&Tensor::new(&[[0.5f32, 1.0], [1.5, -3.0]], &Device::Cpu).unwrap())
                .unwrap();
        let loss = bound_loss(mean.as_tensor(), 1.0).unwrap();
        // (0 + 0 + 0.25 + 4) / 2 samples.
        assert!((scalar(&loss) - 2.125).abs() < 1e-6);
        let g = loss.backward().unwrap();
        let g = g.get(&mean).unwrap().to_vec2::<f32>().unwrap();
        // d/dμ = 2 (|μ| − b) sign(μ) / 2: nothing inside, pulls back towards the bound past it.
        assert_eq!(g[0], vec![0.0, 0.0]);
        assert!((g[1][0] - 0.5).abs() < 1e-6, "{g:?}");
        assert!((g[1][1] + 2.0).abs() < 1e-6, "{g:?}");
        // A wider bound leaves these means alone.
        assert_eq!(scalar(&bound_loss(mean.as_tensor(), 3.0).unwrap()), 0.0);
    }

    #[test]
    fn kl_of_two_gaussians_closed_form() {
        // KL(N(0, 1) ‖ N(1, 2²)) = ln 2 + (1 + 1)/(2·4) − ½.
        let old_mean = Tensor::new(&[[0.0f32]], &Device::Cpu).unwrap();
        let mean = Tensor::new(&[[1.0f32]], &Device::Cpu).unwrap();
        let kl = gaussian_kl(&old_mean, &t(&[0.0]), &mean, &t(&[2.0f32.ln()])).unwrap();
        let want = 2.0f32.ln() + 0.25 - 0.5;
        assert!((scalar(&kl) - want).abs() < 1e-6, "{}", scalar(&kl));
        // Two entries add; identical distributions give zero.
        let m2 = Tensor::new(&[[0.3f32, -0.7]], &Device::Cpu).unwrap();
        let s2 = t(&[0.1, -0.4]);
        assert!(scalar(&gaussian_kl(&m2, &s2, &m2, &s2).unwrap()).abs() < 1e-7);
    }

    #[test]
    fn log_prob_and_entropy_of_a_standard_normal() {
        // log N(1; 0, 1) = −½ − ½ ln 2π; H(N(0, 1)) = ½ + ½ ln 2π.
        let a = Tensor::new(&[[1.0f32]], &Device::Cpu).unwrap();
        let m = Tensor::new(&[[0.0f32]], &Device::Cpu).unwrap();
        let lp = log_prob(&a, &m, &t(&[0.0]))
            .unwrap()
            .to_vec1::<f32>()
            .unwrap();
        assert!((lp[0] as f64 + 0.5 + HALF_LN_2PI).abs() < 1e-6);
        let h = scalar(&entropy(&t(&[0.0, 0.0])).unwrap()) as f64;
        assert!((h - 2.0 * (0.5 + HALF_LN_2PI)).abs() < 1e-6);
    }
}
