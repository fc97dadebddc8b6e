//! A checkpoint playing: observe, normalise, run the network, map the action.

use sim::ball::BallState;
use sim::model::Model;
use sim::robot::Robot;

use crate::controller::ActionMapper;
use crate::observation::Observer;
use crate::player::{InvalidAction, Player};

use super::*;

/// A checkpoint playing: observe, normalise, run the network, map the action through the controller.
#[derive(Debug, Clone)]
pub struct CheckpointPlayer {
    checkpoint: std::sync::Arc<Checkpoint>,
    network: Network,
    observer: Observer,
    mapper: ActionMapper,
    obs: Vec<f64>,
    raw: Vec<f64>,
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
        let mut observer =
            Observer::new(model, checkpoint.observation.blocks.clone(), seed).with_bounce(bounce);
        observer.set_replan(checkpoint.observation.replan);
        let mut player = CheckpointPlayer {
            network,
            observer,
            mapper: ActionMapper::new(model, &checkpoint.controller),
            checkpoint,
            obs: Vec::new(),
            raw: Vec::new(),
            mean: Vec::new(),
            seed,
            noise: noise_stream(seed),
        };
        player.restart_noise();
        Ok(player)
    }

    /// The planner's current command (the plan and its absolute strike time), if a ball is coming.
    pub fn command(&self) -> Option<&(crate::planner::Plan, f64)> {
        self.observer.command()
    }

    /// Restarts the noise streams of agent seed `self.seed`: the action noise's, and K-MAC's on the
    /// activations when the checkpoint was trained with it (a stream of its own), unless it plays
    /// that noise's expectation.
    fn restart_noise(&mut self) {
        self.noise = noise_stream(self.seed);
        if !self.checkpoint.expected_activation_noise {
            if let ControllerSpec::Kmac {
                activation_noise: Some(sigma),
                ..
            } = self.checkpoint.controller
            {
                let seed = crate::seeds::mix64(self.seed ^ 0x6163_745f_6e6f_6973);
                self.mapper.set_activation_noise(sigma, seed);
            }
        }
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
        self.restart_noise();
    }

    fn reseed(&mut self, seed: u64) {
        self.seed = seed;
        self.observer.reset(seed);
        self.restart_noise();
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
        self.raw.clone_from(&self.obs);
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
        if let Some(sigma) = self.checkpoint.action_noise.filter(|&s| s > 0.0) {
            for a in action.iter_mut() {
                *a = (*a + sigma * self.noise.normal()).clamp(-1.0, 1.0);
            }
        }
        let model = robot.held_model().clone();
        self.mapper
            .controls(&model, &robot.state, &action, sim::arena::CONTROL_DT, ctrl);
        crate::controller::apply_grip_floor(robot, self.checkpoint.grip_floor.unwrap_or(0.0), ctrl);
        Ok(())
    }

    fn last_decision(&self) -> Option<(&[f64], &[f64])> {
        (!self.mean.is_empty()).then_some((&self.raw, &self.mean))
    }
}
