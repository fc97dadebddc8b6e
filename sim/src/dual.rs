//! The dual arena (docs/design.md §3): two robots and the ball world. Robot A stands at x > 0; robot B is the
//! same model turned 180° about the vertical line through (0, 0.04). Each physics step moves both
//! robots (muscles, joints, grip), then the ball against both paddles, then hands each paddle the
//! ball's impulse for the next step. The episode and rally state machines (issue 4) build on this.
//!
//! Reads the model and configuration; writes the robots, the ball and contact events. No I/O.

use std::sync::Arc;

use crate::arena::{self, Preset, Side};
use crate::ball::BallState;
use crate::config::ArenaConfig;
use crate::events::ContactEvent;
use crate::model::Model;
use crate::robot::{GripEvent, Robot};
use crate::world::BallWorld;

/// Two robots and a ball.
#[derive(Debug, Clone)]
pub struct DualArena {
    /// The ball world (its clock is the arena's).
    pub world: BallWorld,
    /// Robot A (index 0) and robot B (index 1).
    pub robots: [Robot; 2],
}

impl DualArena {
    /// Both robots at `qpos` (or the reference configuration), paddles held, the ball at `ball`.
    pub fn new(
        model: Arc<Model>,
        config: &ArenaConfig,
        preset: Preset,
        ball: BallState,
    ) -> Result<DualArena, String> {
        if (model.timestep - arena::TIMESTEP).abs() > 1e-12 {
            return Err(format!(
                "the robot model's timestep {} s differs from the arena's {} s",
                model.timestep,
                arena::TIMESTEP
            ));
        }
        Ok(DualArena {
            world: BallWorld::new(preset, ball),
            robots: [
                Robot::new(model.clone(), &config.grip, Side::A)?,
                Robot::new(model, &config.grip, Side::B)?,
            ],
        })
    }

    /// The robot of `side`.
    pub fn robot(&mut self, side: Side) -> &mut Robot {
        match side {
            Side::A => &mut self.robots[0],
            Side::B => &mut self.robots[1],
        }
    }

    /// One physics step; returns the grip events of A and B.
    pub fn physics_step(&mut self, events: &mut Vec<ContactEvent>) -> [Option<GripEvent>; 2] {
        let grip = [self.robots[0].physics_step(), self.robots[1].physics_step()];
        let paddles = [self.robots[0].ball_paddle(), self.robots[1].ball_paddle()];
        self.world.physics_step(&paddles, events);
        for (owner, point, impulse) in self.world.paddle_impulses.clone() {
            self.robot(owner).receive_ball_impulse(&point, &impulse);
        }
        grip
    }

    /// One control step (`SUBSTEPS` physics steps); grip events of each side, in order.
    pub fn control_step(&mut self, events: &mut Vec<ContactEvent>) -> Vec<(Side, GripEvent)> {
        let mut grip = Vec::new();
        for _ in 0..arena::SUBSTEPS {
            let [a, b] = self.physics_step(events);
            grip.extend(a.map(|e| (Side::A, e)));
            grip.extend(b.map(|e| (Side::B, e)));
        }
        grip
    }
}
