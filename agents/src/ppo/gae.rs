//! Generalised advantage estimation (Schulman et al. 2016) as rsl_rl computes it: per environment,
//! backwards over the rollout, `δ_t = r_t + γ·(1 − d_t)·V_{t+1} − V_t`,
//! `A_t = δ_t + γ·λ·(1 − d_t)·A_{t+1}`, returns `R_t = A_t + V_t`. An episode cut by a time limit
//! (not a terminal state) is bootstrapped as rsl_rl does: its last reward gains `γ·V_t`.
//!
//! Rollouts are stored step-major: entry `t·envs + e` is step `t` of environment `e`.

/// One rollout's advantages and value targets, step-major like its inputs.
#[derive(Debug, Clone, PartialEq)]
pub struct Advantages {
    /// A_t.
    pub advantages: Vec<f32>,
    /// R_t = A_t + V_t.
    pub returns: Vec<f32>,
}

/// What a rollout step ended with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum StepEnd {
    /// The episode goes on.
    #[default]
    Running,
    /// A terminal state: nothing follows, the value after it is zero.
    Terminal,
    /// Cut by a time limit: the state after it still had a value (bootstrapped).
    TimeLimit,
}

/// GAE over `rewards`, `values`, `ends` (each `steps·envs`, step-major) with the critic's values
/// `last_values` (one per environment) of the states after the last step.
pub fn gae(
    rewards: &[f32],
    values: &[f32],
    ends: &[StepEnd],
    last_values: &[f32],
    gamma: f32,
    lambda: f32,
) -> Advantages {
    let envs = last_values.len();
    let n = rewards.len();
    assert!(
        envs > 0 && n.is_multiple_of(envs),
        "rollout of {n} entries for {envs} environments"
    );
    assert!(
        values.len() == n && ends.len() == n,
        "rewards, values and ends differ in length"
    );
    let steps = n / envs;
    let mut advantages = vec![0.0f32; n];
    let mut returns = vec![0.0f32; n];
    for (e, &last) in last_values.iter().enumerate() {
        let mut next_advantage = 0.0f32;
        let mut next_value = last;
        for t in (0..steps).rev() {
            let i = t * envs + e;
            let mut r = rewards[i];
            if ends[i] == StepEnd::TimeLimit {
                r += gamma * values[i];
            }
            let not_done = if ends[i] == StepEnd::Running {
                1.0
            } else {
                0.0
            };
            let delta = r + gamma * not_done * next_value - values[i];
            next_advantage = delta + gamma * lambda * not_done * next_advantage;
            advantages[i] = next_advantage;
            returns[i] = next_advantage + values[i];
            next_value = values[i];
        }
    }
    Advantages {
        advantages,
        returns,
    }
}

/// Normalises `x` to zero mean and unit (sample) standard deviation, as rsl_rl does per minibatch.
pub fn normalise(x: &mut [f32]) {
    if x.len() < 2 {
        return;
    }
    let n = x.len() as f64;
    let mean = x.iter().map(|&v| v as f64).sum::<f64>() / n;
    let var = x.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / (n - 1.0);
    let std = var.sqrt() + 1e-8;
    for v in x.iter_mut() {
        *v = ((*v as f64 - mean) / std) as f32;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_computed_trajectory() {
        // One environment, three steps, terminal at the last: γ = 0.5, λ = 0.5.
        // V = (1, 2, 3), r = (1, 1, 1), last value 10 (ignored: the episode ended).
        // δ2 = 1 − 3 = −2;             A2 = −2
        // δ1 = 1 + 0.5·3 − 2 = 0.5;    A1 = 0.5 + 0.25·(−2) = 0
        // δ0 = 1 + 0.5·2 − 1 = 1;      A0 = 1 + 0.25·0 = 1
        let ends = [StepEnd::Running, StepEnd::Running, StepEnd::Terminal];
        let a = gae(&[1.0; 3], &[1.0, 2.0, 3.0], &ends, &[10.0], 0.5, 0.5);
        assert_eq!(a.advantages, vec![1.0, 0.0, -2.0]);
        assert_eq!(a.returns, vec![2.0, 2.0, 1.0]);
    }

    #[test]
    fn bootstraps_the_last_value_and_time_limits() {
        // Two environments interleaved, two steps. Env 0 runs on (bootstrapped by its last value 4);
        // env 1 is cut by a time limit at step 0, then starts a new episode.
        let rewards = [1.0, 2.0, 0.0, 1.0];
        let values = [0.5, 1.0, 2.0, 3.0];
        let ends = [
            StepEnd::Running,
            StepEnd::TimeLimit,
            StepEnd::Running,
            StepEnd::Running,
        ];
        let (g, l) = (0.9f32, 0.8f32);
        let a = gae(&rewards, &values, &ends, &[4.0, 5.0], g, l);
        // Env 0: δ1 = 0 + 0.9·4 − 2 = 1.6, A1 = 1.6; δ0 = 1 + 0.9·2 − 0.5 = 2.3, A0 = 2.3 + 0.72·1.6.
        let a01 = 2.3 + g * l * 1.6;
        // Env 1: δ1 = 1 + 0.9·5 − 3 = 2.5; step 0 is cut: r = 2 + 0.9·1 = 2.9, δ0 = 2.9 − 1 = 1.9.
        let expect = [a01, 1.9, 1.6, 2.5];
        for (got, want) in a.advantages.iter().zip(expect) {
            assert!(
                (got - want).abs() < 1e-6,
                "{:?} vs {expect:?}",
                a.advantages
            );
        }
        for ((r, adv), v) in a.returns.iter().zip(&a.advantages).zip(values) {
            assert!((r - adv - v).abs() < 1e-6);
        }
    }

    #[test]
    fn normalise_gives_zero_mean_unit_std() {
        let mut x = vec![1.0, 2.0, 3.0, 4.0, 10.0];
        normalise(&mut x);
        let m: f32 = x.iter().sum::<f32>() / 5.0;
        let v: f32 = x.iter().map(|a| (a - m).powi(2)).sum::<f32>() / 4.0;
        assert!(m.abs() < 1e-6 && (v - 1.0).abs() < 1e-5, "{m} {v}");
    }
}
