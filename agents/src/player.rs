//! Who plays: anything that turns the robot's state and the ball into muscle controls each control
//! step — the scripted house agents and trained checkpoints — behind one trait, so the evaluation
//! and the match runner treat them alike. How a player is built from a name or a checkpoint is
//! [`crate::factory`].

use sim::ball::BallState;
use sim::robot::Robot;

/// The player produced controls that are not finite numbers (NaN or infinite), or its network failed
/// or answered with an action of the wrong width: INVALID_ACTION.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InvalidAction;

/// A controller of one robot.
pub trait Player: Send {
    /// Forgets everything about the previous episode or rally.
    fn reset(&mut self);
    /// Sets the seed of the player's own randomness (the evaluation gives each episode its own).
    fn reseed(&mut self, seed: u64);
    /// Writes the robot's controls for this control step; `ball` is in the world frame, `t` the
    /// arena's time.
    fn act(
        &mut self,
        robot: &Robot,
        ball: &BallState,
        t: f64,
        ctrl: &mut [f64],
    ) -> Result<(), InvalidAction>;

    /// What a network decided at the last `act`: the observation it was given (before the
    /// checkpoint's normalisation) and its output (the mean action, before any noise). `None` for
    /// players without a network.
    fn last_decision(&self) -> Option<(&[f64], &[f64])> {
        None
    }
}
