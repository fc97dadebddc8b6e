//! What a run gives besides its updates: validations, checkpoints, the ball bank.

use std::sync::Arc;

use crate::checkpoint::{Checkpoint, ObservationSpec, Training, TrainingPoint, FORMAT, VERSION};
use crate::ppo::{stream_seed, TrainEnv};

use super::*;

impl Trainer {
    /// Plays the policy as a checkpoint would play it (its trained Gaussian, seeded per episode) on
    /// the validation's held-out episodes: self-play rallies in the rally environment (score: mean
    /// rally length), single serves of the training distribution otherwise (score: success rate).
    /// Reads the weights and the observation statistics, changes nothing.
    pub fn validate(&self) -> Result<ValidationPoint, String> {
        let v = &self.config.validation;
        let player = crate::factory::PlayerSpec::Checkpoint(Arc::new(self.validation_checkpoint(
            "validation",
            "",
            "",
        )?));
        let (config, preset) = (self.arena.clone(), sim::arena::MYOCHALLENGE);
        let (score, longest) = match self.config.validation_env() {
            TrainEnv::Rally => {
                let spec = self.match_spec(v.episodes as u32, v.seed);
                let lengths: Vec<u32> = crate::matchrun::play_rallies(&spec, &player, &player)?
                    .iter()
                    .map(|r| r.length)
                    .collect();
                (
                    mean_of(lengths.iter().map(|&l| l as f64)),
                    lengths.iter().copied().max().unwrap_or(0),
                )
            }
            TrainEnv::Single => {
                let e = crate::eval::Evaluation {
                    lead_in: false,
                    model: self.model.clone(),
                    config,
                    preset,
                    kind: self.config.serve.kind(),
                    episodes: v.episodes,
                    seed: v.seed,
                };
                let r = crate::eval::evaluate(&e, &player, &|| {})?;
                (r.success_rate.value, 0)
            }
        };
        Ok(ValidationPoint {
            iteration: self.progress.iteration,
            env_steps: self.progress.env_steps,
            score,
            episodes: v.episodes,
            longest,
        })
    }

    /// The checkpoint as validation plays it: [`Trainer::checkpoint`] with its noise scaled by
    /// `[validation] noise_scale` (what `best.json` holds).
    pub fn validation_checkpoint(
        &self,
        name: &str,
        command: &str,
        commit: &str,
    ) -> Result<Checkpoint, String> {
        let mut ck = self.checkpoint(name, command, commit)?;
        let scale = self.config.validation.noise_scale;
        if scale != 1.0 {
            ck.scale_noise(scale).map_err(|e| e.to_string())?;
        }
        Ok(ck)
    }

    /// A match of `rallies` rallies on `seed` in the run's arena (MyoChallenge contact laws),
    /// without replay: what validation and the bank's refresh play.
    fn match_spec(&self, rallies: u32, seed: u64) -> crate::matchrun::MatchSpec {
        crate::matchrun::MatchSpec {
            model: self.model.clone(),
            config: self.arena.clone(),
            preset: sim::arena::MYOCHALLENGE,
            rallies,
            seed,
            replay: false,
        }
    }

    /// Replaces the single-serve environments' ball bank with `balls` (served in `[bank] fraction`
    /// of the episodes from the next segment on).
    pub fn set_bank(&mut self, balls: Arc<[sim::ball::BallState]>) {
        let fraction = self.config.bank.fraction;
        for s in &mut self.slots {
            if let TrainingEnv::Single(env) = &mut s.env {
                env.bank = Some(crate::env::BallBank {
                    balls: balls.clone(),
                    fraction,
                });
            }
        }
        self.bank = Some(balls);
    }

    /// Records the policy's own legal returns in `[bank] refresh_rallies` self-play rallies (their
    /// seed from the run's seed and the iteration) and makes them the bank; returns how many. A
    /// policy that returned nothing keeps the old bank.
    pub fn refresh_bank(&mut self) -> Result<usize, String> {
        let player =
            crate::factory::PlayerSpec::Checkpoint(Arc::new(self.checkpoint("bank", "", "")?));
        let spec = self.match_spec(
            self.config.bank.refresh_rallies as u32,
            stream_seed(self.seed, STREAM_BANK, self.progress.iteration, 0),
        );
        let balls = crate::matchrun::record_returns(&spec, &player, &player)?;
        if !balls.is_empty() {
            self.set_bank(balls.clone().into());
        }
        Ok(balls.len())
    }

    /// The policy as a checkpoint in the agents' format, named `name`, with its provenance.
    pub fn checkpoint(
        &self,
        name: &str,
        command: &str,
        git_commit: &str,
    ) -> Result<Checkpoint, String> {
        let last = self.progress.curve.last().copied().unwrap_or_default();
        // At most ~200 points of the curve travel with the checkpoint.
        let stride = self.progress.curve.len().div_ceil(200).max(1);
        let curve = self
            .progress
            .curve
            .iter()
            .enumerate()
            .filter(|(i, r)| {
                r.episodes > 0 && ((i + 1) % stride == 0 || i + 1 == self.progress.curve.len())
            })
            .map(|(_, r)| TrainingPoint {
                env_steps: r.env_steps,
                reward: r.reward,
                hit_rate: r.hit_rate,
                success_rate: r.success_rate,
            })
            .collect();
        Ok(Checkpoint {
            format: FORMAT.into(),
            version: VERSION,
            name: name.into(),
            model: sim::config::robot_name(&self.model).into(),
            controller: self.controller.clone(),
            observation: ObservationSpec {
                blocks: self.config.obs_blocks(),
                mean: self.normalizer.mean.clone(),
                std: self.normalizer.scale(),
                replan: self.config.replan,
            },
            policy: Some(self.net.actor_mlp().map_err(e)?),
            onnx: None,
            policy_std: Some(
                self.net
                    .std()
                    .map_err(e)?
                    .iter()
                    .map(|&s| s as f64)
                    .collect(),
            ),
            action_noise: (self.config.controller.action_noise > 0.0)
                .then_some(self.config.controller.action_noise),
            grip_floor: (self.config.controller.grip_floor > 0.0)
                .then_some(self.config.controller.grip_floor),
            training: Some(Training {
                method: self.method.name().into(),
                command: command.into(),
                seed: self.seed,
                git_commit: git_commit.into(),
                env_steps: self.progress.env_steps,
                iterations: self.progress.iteration,
                wall_seconds: self.progress.wall_s,
                hit_rate: last.hit_rate,
                success_rate: last.success_rate,
                episodes: self.progress.recent.len() as u64,
                curve,
                env: self.config.env.name().into(),
                warm_start: self.progress.warm_start.clone(),
                rally_length: (self.config.env == TrainEnv::Rally || self.config.follow_on > 0.0)
                    .then_some(last.rally_length),
                note: None,
                noise_scale: None,
                ablation: (!self.config.ablation.is_none()).then_some(self.config.ablation),
                lead_in: (self.config.lead_in > 0.0).then_some(self.config.lead_in),
                lead_in_length: (self.config.lead_in > 0.0
                    && self.config.lead_in_length != crate::env::single::LeadInLength::Full)
                    .then_some(self.config.lead_in_length),
                follow_on: (self.config.follow_on > 0.0).then_some(self.config.follow_on),
            }),
            expected_activation_noise: false,
        })
    }
}
