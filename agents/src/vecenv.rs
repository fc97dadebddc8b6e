//! Many training environments stepped together, for callers outside `rally train` (the Python
//! package): the very environments a training run steps ([`crate::ppo::trainer::envs`]), built from
//! a method and a training configuration as `rally train` builds them, stepped in parallel on
//! rayon's threads, with observations and results written into buffers the caller owns (so a
//! binding can hand over its arrays without a copy per step).
//!
//! An environment holds one robot (single serve) or two (a self-play rally: rows `2i` and `2i + 1`
//! are robot A and B of environment `i`, each observing in its own frame). An environment whose
//! episode is over stays over until [`VecEnv::reset`]: autoreset is the caller's policy.

use std::sync::Arc;

use rayon::prelude::*;
use sim::config::ArenaConfig;
use sim::model::Model;

use crate::controller::ActionMapper;
use crate::observation::observation_names;
use crate::ppo::trainer::envs::{make_env, read_bank, TrainingEnv};
use crate::ppo::{Method, TrainConfig};

/// What one robot's step gave.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StepResult {
    /// The weighted reward (the configuration's `[reward]` weights; no `reward_scale`).
    pub reward: f64,
    /// The episode ended in a terminal state (the rules, or the training's early ends).
    pub terminated: bool,
    /// The episode ended at its time limit (or a rally at its cap) instead.
    pub truncated: bool,
    /// The robot has touched the ball (so far).
    pub hit: bool,
    /// A legal return (so far; in a rally: by this robot in this step).
    pub success: bool,
    /// Returns in the rally so far.
    pub rally_length: u32,
    /// What each reward term added to `reward`, named by [`crate::env::RewardTerms::NAMES`] (they
    /// sum to `reward`).
    pub terms: [f64; 13],
}

/// `n` environments of one method on one robot.
pub struct VecEnv {
    envs: Vec<TrainingEnv>,
    over: Vec<bool>,
    obs_dim: usize,
    act_dim: usize,
    agents: usize,
    observation_names: Vec<String>,
    action_names: Vec<String>,
}

impl VecEnv {
    /// `n` ≥ 1 environments of `method` on `model` in `arena`, as `rally train --config` builds them
    /// from `config` (its environment, serves, reward weights, controller, training noise and
    /// episode ends). Each starts an episode from seed `k` (environment `k`) until reset otherwise.
    pub fn new(
        model: Arc<Model>,
        arena: &ArenaConfig,
        method: Method,
        config: &TrainConfig,
        n: usize,
    ) -> Result<VecEnv, String> {
        if n == 0 {
            return Err("num_envs: at least 1".into());
        }
        config.validate()?;
        let controller = config.controller(method, &model);
        let bank = read_bank(config)?;
        let mut envs = Vec::with_capacity(n);
        let mut dims = (0, 0);
        for _ in 0..n {
            let (env, o, a) = make_env(&model, arena, &controller, config, bank.as_ref())?;
            envs.push(env);
            dims = (o, a);
        }
        let mut v = VecEnv {
            envs,
            over: vec![false; n],
            obs_dim: dims.0,
            act_dim: dims.1,
            agents: config.env.agents(),
            observation_names: observation_names(&model, &config.obs_blocks()),
            action_names: ActionMapper::new(&model, &controller).action_names(&model),
        };
        let mut scratch = vec![0.0; v.agents * v.obs_dim];
        for k in 0..n {
            v.reset(k, k as u64, &mut scratch)?;
        }
        Ok(v)
    }

    /// Environments.
    pub fn len(&self) -> usize {
        self.envs.len()
    }

    /// Always false: there is at least one environment.
    pub fn is_empty(&self) -> bool {
        self.envs.is_empty()
    }

    /// Robots per environment (1, or 2 in a rally).
    pub fn agents(&self) -> usize {
        self.agents
    }

    /// Observation entries per robot.
    pub fn obs_dim(&self) -> usize {
        self.obs_dim
    }

    /// Action entries per robot.
    pub fn act_dim(&self) -> usize {
        self.act_dim
    }

    /// The name of every observation entry (`rally checkpoint spec`'s).
    pub fn observation_names(&self) -> &[String] {
        &self.observation_names
    }

    /// The name of every action entry.
    pub fn action_names(&self) -> &[String] {
        &self.action_names
    }

    /// Starts environment `i`'s next episode from `seed` (the episode `rally train` would play from
    /// that seed); writes its robots' first observations to `obs` (`agents × obs_dim`).
    pub fn reset(&mut self, i: usize, seed: u64, obs: &mut [f64]) -> Result<(), String> {
        let rows = self.agents * self.obs_dim;
        if i >= self.envs.len() {
            return Err(format!("env index {i}: there are {}", self.envs.len()));
        }
        if obs.len() != rows {
            return Err(format!(
                "observation buffer: {} entries, not {rows}",
                obs.len()
            ));
        }
        self.envs[i].reset(seed);
        self.over[i] = false;
        let mut out = Vec::with_capacity(rows);
        self.envs[i].observe_into(&mut out);
        obs.copy_from_slice(&out);
        Ok(())
    }

    /// One control step of every environment whose episode is not over, in parallel, with its
    /// robots' rows of `actions` (`len·agents × act_dim`, entries clipped to [−1, 1]; a non-finite one
    /// ends the episode as an invalid action). Writes every robot's observation to `obs`
    /// (`len·agents × obs_dim`) and its result to `results` (`len·agents`); an environment already
    /// over is not stepped and reports its last observation, no reward and `terminated`.
    pub fn step(
        &mut self,
        actions: &[f64],
        obs: &mut [f64],
        results: &mut [StepResult],
    ) -> Result<(), String> {
        let (n, ag, od, ad) = (self.envs.len(), self.agents, self.obs_dim, self.act_dim);
        let want = [
            ("actions", actions.len(), n * ag * ad),
            ("observation buffer", obs.len(), n * ag * od),
            ("results", results.len(), n * ag),
        ];
        for (what, got, need) in want {
            if got != need {
                return Err(format!("{what}: {got} entries, not {need}"));
            }
        }
        self.envs
            .par_iter_mut()
            .zip(self.over.par_iter_mut())
            .zip(actions.par_chunks(ag * ad))
            .zip(obs.par_chunks_mut(ag * od))
            .zip(results.par_chunks_mut(ag))
            .for_each(|((((env, over), a), o), r)| {
                if !*over {
                    let rows: Vec<Vec<f64>> = a.chunks(ad).map(|x| x.to_vec()).collect();
                    for (k, s) in env.step(&rows).into_iter().enumerate() {
                        r[k] = StepResult {
                            reward: s.reward,
                            terminated: s.done && !s.time_limit,
                            truncated: s.done && s.time_limit,
                            hit: s.hit,
                            success: s.success,
                            rally_length: s.rally_length,
                            terms: s.terms,
                        };
                    }
                    *over = r.iter().any(|x| x.terminated || x.truncated);
                } else {
                    for x in r.iter_mut() {
                        *x = StepResult {
                            terminated: true,
                            ..StepResult::default()
                        };
                    }
                }
                let mut out = Vec::with_capacity(o.len());
                env.observe_into(&mut out);
                o.copy_from_slice(&out);
            });
        Ok(())
    }
}

impl VecEnv {
    /// Steps every environment with the same `actions` (one robot's row, or `agents` rows) for
    /// about `seconds`, starting each ended episode again from the next seed: the environments'
    /// own speed, without a caller between the steps (the Python package's benchmark sets it beside
    /// the same stepping from Python). Returns the robot-steps taken.
    pub fn run_fixed(&mut self, actions: &[f64], seconds: f64) -> Result<u64, String> {
        let rows = self.agents * self.act_dim;
        if actions.len() != rows {
            return Err(format!("actions: {} entries, not {rows}", actions.len()));
        }
        let n = self.envs.len();
        let all: Vec<f64> = actions.iter().copied().cycle().take(n * rows).collect();
        let mut obs = vec![0.0; n * self.agents * self.obs_dim];
        let mut results = vec![StepResult::default(); n * self.agents];
        let mut scratch = vec![0.0; self.agents * self.obs_dim];
        let (start, mut steps, mut seed) = (std::time::Instant::now(), 0u64, n as u64);
        while steps == 0 || start.elapsed().as_secs_f64() < seconds {
            self.step(&all, &mut obs, &mut results)?;
            steps += (n * self.agents) as u64;
            for i in 0..n {
                if self.over[i] {
                    self.reset(i, seed, &mut scratch)?;
                    seed += 1;
                }
            }
        }
        Ok(steps)
    }
}

/// `rally bench train`'s ceiling: `envs` single-serve worlds of `model` (P2 serves, MyoChallenge
/// contact laws) stepped for about `seconds` on every core with fixed controls (every muscle at 0.1),
/// without controller, observation or reward. Physics steps per second.
pub fn physics_alone(
    model: &Arc<Model>,
    arena: &ArenaConfig,
    envs: usize,
    seconds: f64,
) -> Result<f64, String> {
    use sim::episode::SingleServe;
    use sim::rng::Rng;
    use sim::serve::ServeKind;
    let mut worlds: Vec<SingleServe> = (0..envs)
        .map(|k| {
            let mut w = SingleServe::new(model.clone(), arena, sim::arena::MYOCHALLENGE)?;
            w.reset(ServeKind::P2, &mut Rng::seeded(k as u64), None);
            Ok(w)
        })
        .collect::<Result<_, String>>()?;
    let start = std::time::Instant::now();
    let mut physics_steps = 0u64;
    while physics_steps == 0 || start.elapsed().as_secs_f64() < seconds {
        worlds.par_iter_mut().enumerate().for_each(|(k, w)| {
            for _ in 0..10 {
                if w.done {
                    w.reset(ServeKind::P2, &mut Rng::seeded(k as u64), None);
                }
                for (i, _) in model.muscles() {
                    w.robot.state.ctrl[i] = 0.1;
                }
                w.step();
            }
        });
        physics_steps += 10 * envs as u64;
    }
    Ok(physics_steps as f64 / start.elapsed().as_secs_f64())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vec_env(n: usize) -> VecEnv {
        let m = Arc::new(sim::config::default_model());
        VecEnv::new(
            m,
            &ArenaConfig::default(),
            Method::Kmac,
            &TrainConfig::default(),
            n,
        )
        .unwrap()
    }

    /// Steps with zero actions from `seed` until the episode ends; (rewards, last observation).
    fn episode(v: &mut VecEnv, seed: u64) -> (Vec<f64>, Vec<f64>) {
        let (od, ad, n) = (v.obs_dim(), v.act_dim(), v.len());
        let mut obs = vec![0.0; n * od];
        for i in 0..n {
            v.reset(i, seed, &mut obs[i * od..(i + 1) * od]).unwrap();
        }
        let mut rewards = Vec::new();
        let mut results = vec![StepResult::default(); n];
        for _ in 0..400 {
            v.step(&vec![0.0; n * ad], &mut obs, &mut results).unwrap();
            rewards.push(results[0].reward);
            let sum = results[0].terms.iter().fold(0.0, |s, x| s + x);
            assert_eq!(
                sum.to_bits(),
                results[0].reward.to_bits(),
                "the terms add up"
            );
            if results[0].terminated || results[0].truncated {
                break;
            }
        }
        for k in 1..n {
            assert_eq!(obs[..od], obs[k * od..(k + 1) * od], "environment {k}");
        }
        (rewards, obs[..od].to_vec())
    }

    #[test]
    fn a_seed_gives_the_same_episode_in_every_environment_and_every_time() {
        let mut v = vec_env(3);
        assert_eq!((v.obs_dim(), v.act_dim(), v.agents()), (206, 13, 1));
        assert_eq!(v.observation_names().len(), 206);
        assert_eq!(v.action_names().len(), 13);
        let (r1, o1) = episode(&mut v, 7);
        let (r2, o2) = episode(&mut v, 7);
        assert!(r1.len() > 10, "{} steps", r1.len());
        let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&r1), bits(&r2));
        assert_eq!(bits(&o1), bits(&o2));
        let (r3, _) = episode(&mut v, 8);
        assert_ne!(bits(&r1), bits(&r3), "another seed, another serve");
    }

    #[test]
    fn an_episode_over_stays_over_and_bad_buffers_are_refused() {
        let mut v = vec_env(2);
        let (od, ad) = (v.obs_dim(), v.act_dim());
        let mut obs = vec![0.0; 2 * od];
        let mut results = vec![StepResult::default(); 2];
        // A non-finite action ends environment 0's episode; environment 1 plays on.
        let mut a = vec![0.0; 2 * ad];
        a[0] = f64::NAN;
        v.step(&a, &mut obs, &mut results).unwrap();
        assert!(results[0].terminated && !results[1].terminated);
        v.step(&vec![0.0; 2 * ad], &mut obs, &mut results).unwrap();
        assert_eq!(results[0].reward, 0.0);
        assert!(results[0].terminated);
        assert!(v.step(&[0.0; 3], &mut obs, &mut results).is_err());
        assert!(v.reset(2, 0, &mut obs[..od]).is_err());
        assert!(v.reset(0, 0, &mut obs).is_err());
        v.reset(0, 0, &mut obs[..od]).unwrap();
        v.step(&vec![0.0; 2 * ad], &mut obs, &mut results).unwrap();
        assert!(!results[0].terminated, "reset: it plays again");
        // Stepping without a caller: episodes start again as they end; one row of actions.
        assert!(v.run_fixed(&[0.0; 3], 0.0).is_err());
        // Without restarts the count would stop below two episodes' 600 steps; timed calls, so
        // a loaded machine takes more of them (at most a minute).
        let (mut steps, started) = (0, std::time::Instant::now());
        while steps <= 1000 && started.elapsed().as_secs() < 60 {
            let s = v.run_fixed(&vec![0.0; ad], 0.3).unwrap();
            assert!(s.is_multiple_of(2), "{s}");
            steps += s;
        }
        assert!(steps > 1000, "{steps} steps: episodes were started again");
    }
}
