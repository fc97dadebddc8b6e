//! What a policy sees (docs/design.md §6): the observation blocks a checkpoint lists and the `Observer` that
//! builds them for one robot from the raw state `sim` exposes, keeping the planner's command (strike
//! point, racket velocity and orientation, time to the strike). Training and playing read the same
//! observation through this module.

use serde::{Deserialize, Serialize};
use sim::arena::{self, Side};
use sim::ball::BallState;
use sim::model::Model;
use sim::predict::BounceModel;
use sim::rng::Rng;
use sim::robot::Robot;

use crate::controller::ActionSpace;
use crate::planner::{self, Plan};

/// The blocks an observation can hold, in the order a checkpoint lists them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ObsBlock {
    /// Positions of the independent joints.
    Qpos,
    /// Velocities of the independent joints.
    Qvel,
    /// Muscle activations.
    Act,
    /// Muscle lengths, normalised to their length range (0 at the shortest, 1 at the longest).
    MuscleLength,
    /// Ball centre (robot frame).
    BallPos,
    /// Ball velocity (robot frame).
    BallVel,
    /// Paddle position (3), orientation (w, x, y, z), velocity (3), angular velocity (3).
    Paddle,
    /// The planner's command: strike position (3), racket velocity (3), racket orientation (4),
    /// time to the strike (1); zeros while no ball is coming.
    Command,
    /// The planner's strike position alone (3; zeros while no ball is coming): the paper's
    /// Position-only ablation.
    CommandPosition,
}

impl ObsBlock {
    /// Every block, in the default order.
    pub const ALL: [ObsBlock; 8] = [
        ObsBlock::Qpos,
        ObsBlock::Qvel,
        ObsBlock::Act,
        ObsBlock::MuscleLength,
        ObsBlock::BallPos,
        ObsBlock::BallVel,
        ObsBlock::Paddle,
        ObsBlock::Command,
    ];

    /// Entries of this block for `space`.
    pub fn size(self, space: &ActionSpace) -> usize {
        match self {
            ObsBlock::Qpos | ObsBlock::Qvel => space.joints.len(),
            ObsBlock::Act | ObsBlock::MuscleLength => space.muscles.len(),
            ObsBlock::BallPos | ObsBlock::BallVel => 3,
            ObsBlock::Paddle => 13,
            ObsBlock::Command => 11,
            ObsBlock::CommandPosition => 3,
        }
    }

    /// Names of this block's entries for `model` (its joints' and muscles' names), e.g.
    /// `qpos.elbow_flex`, `act.FDS`, `ball_pos.x`, `command.t_strike`.
    pub fn names(self, model: &Model, space: &ActionSpace) -> Vec<String> {
        let tag = |prefix: &str, parts: &[&str]| -> Vec<String> {
            parts.iter().map(|p| format!("{prefix}.{p}")).collect()
        };
        let joints = |prefix: &str| -> Vec<String> {
            let n: Vec<&str> = space
                .joints
                .iter()
                .map(|&j| model.joints[j].name.as_str())
                .collect();
            tag(prefix, &n)
        };
        let muscles = |prefix: &str| -> Vec<String> {
            let n: Vec<&str> = space
                .muscles
                .iter()
                .map(|&a| model.actuators[a].name.as_str())
                .collect();
            tag(prefix, &n)
        };
        match self {
            ObsBlock::Qpos => joints("qpos"),
            ObsBlock::Qvel => joints("qvel"),
            ObsBlock::Act => muscles("act"),
            ObsBlock::MuscleLength => muscles("muscle_length"),
            ObsBlock::BallPos => tag("ball_pos", &["x", "y", "z"]),
            ObsBlock::BallVel => tag("ball_vel", &["x", "y", "z"]),
            ObsBlock::Paddle => tag(
                "paddle",
                &[
                    "x", "y", "z", "qw", "qx", "qy", "qz", "vx", "vy", "vz", "wx", "wy", "wz",
                ],
            ),
            ObsBlock::Command => tag(
                "command",
                &[
                    "strike_x",
                    "strike_y",
                    "strike_z",
                    "racket_vx",
                    "racket_vy",
                    "racket_vz",
                    "racket_qw",
                    "racket_qx",
                    "racket_qy",
                    "racket_qz",
                    "t_strike",
                ],
            ),
            ObsBlock::CommandPosition => tag("command", &["strike_x", "strike_y", "strike_z"]),
        }
    }
}

/// What of the planner's command a policy sees and is rewarded for tracking (the paper's §V-C
/// ablations): all of it (Diff-Muscle), the strike position alone (Position-only), or nothing
/// (Without-Planner).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CommandVariant {
    /// The whole command: position, velocity, orientation and time to the strike.
    #[default]
    Full,
    /// The strike position alone.
    Position,
    /// No command.
    None,
}

impl CommandVariant {
    /// The observation's blocks: every block, with the command as the variant has it.
    pub fn blocks(self) -> Vec<ObsBlock> {
        let command = match self {
            CommandVariant::Full => Some(ObsBlock::Command),
            CommandVariant::Position => Some(ObsBlock::CommandPosition),
            CommandVariant::None => None,
        };
        ObsBlock::ALL
            .iter()
            .filter_map(|&b| {
                if b == ObsBlock::Command {
                    command
                } else {
                    Some(b)
                }
            })
            .collect()
    }

    /// The variant's name in a configuration (`full`, `position`, `none`).
    pub fn name(self) -> &'static str {
        match self {
            CommandVariant::Full => "full",
            CommandVariant::Position => "position",
            CommandVariant::None => "none",
        }
    }
}

/// How often the planner's command is made for one incoming ball (`replan` in a training
/// configuration; a checkpoint records it with its observation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Replan {
    /// Once, as soon as the ball flies towards the robot (ours, and every checkpoint before the
    /// setting).
    #[default]
    Once,
    /// Once more from the ball's real state after it has bounced on the robot's half and left the
    /// table, keeping the first plan's outgoing velocity (the official code plans again there and
    /// draws a new one): the first plan's predicted bounce is off by up to a few centimetres on the
    /// soft table, the second has no bounce to predict.
    AfterBounce,
}

impl Replan {
    /// Whether this is the default, [`Replan::Once`] (which checkpoints leave out).
    pub fn is_once(&self) -> bool {
        *self == Replan::Once
    }

    /// The setting's name in a configuration (`once`, `after_bounce`).
    pub fn name(self) -> &'static str {
        match self {
            Replan::Once => "once",
            Replan::AfterBounce => "after_bounce",
        }
    }
}

/// Names of the entries of an observation of `blocks` on `model`, in order.
pub fn observation_names(model: &Model, blocks: &[ObsBlock]) -> Vec<String> {
    let space = ActionSpace::new(model);
    blocks.iter().flat_map(|b| b.names(model, &space)).collect()
}

/// Builds observations for one robot, keeping the planner's current command.
#[derive(Debug, Clone)]
pub struct Observer {
    /// Which blocks, in order.
    pub blocks: Vec<ObsBlock>,
    space: ActionSpace,
    plan: Option<(Plan, f64)>,
    rng: Rng,
    bounce: BounceModel,
    replan: Replan,
    /// Where the incoming ball is in its second plan's timeline.
    stage: ReplanStage,
    /// The ball's vertical velocity (robot frame) at the last update with a plan.
    last_vz: f64,
}

/// The second plan's progress for the incoming ball.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ReplanStage {
    /// Waiting for the bounce on this robot's half.
    Incoming,
    /// Bounced; waiting for the ball to leave the table.
    Bounced,
    /// Planned again (or not to be).
    Done,
}

impl Observer {
    /// The muscles (actuator indices) the observation's muscle blocks list, in order.
    pub fn muscles(&self) -> &[usize] {
        &self.space.muscles
    }

    /// An observer of `blocks` for `model`.
    pub fn new(model: &Model, blocks: Vec<ObsBlock>, seed: u64) -> Observer {
        Observer {
            blocks,
            space: ActionSpace::new(model),
            plan: None,
            rng: Rng::seeded(seed),
            bounce: BounceModel::for_table(&arena::MYOCHALLENGE.table),
            replan: Replan::Once,
            stage: ReplanStage::Done,
            last_vz: 0.0,
        }
    }

    /// Makes the command as `replan` says from the next incoming ball on.
    pub fn set_replan(&mut self, replan: Replan) {
        self.replan = replan;
    }

    /// How the command is made.
    pub fn replan(&self) -> Replan {
        self.replan
    }

    /// The same observer planning with `bounce` (the arena preset's table bounce; the default is
    /// the MyoChallenge table's).
    pub fn with_bounce(mut self, bounce: BounceModel) -> Observer {
        self.bounce = bounce;
        self
    }

    /// Observation length.
    pub fn size(&self) -> usize {
        self.blocks.iter().map(|b| b.size(&self.space)).sum()
    }

    /// Forgets the command (new episode) and reseeds the planner's sampler.
    pub fn reset(&mut self, seed: u64) {
        self.plan = None;
        self.rng = Rng::seeded(seed);
    }

    /// Drops the current command, so that the next ball coming is planned afresh.
    pub fn clear_command(&mut self) {
        self.plan = None;
    }

    /// The current command, if a ball is coming: the plan and the absolute strike time.
    pub fn command(&self) -> Option<&(Plan, f64)> {
        self.plan.as_ref()
    }

    /// Updates the command from the ball (world frame) at time `t`: plans once the ball flies towards
    /// this robot (and, with [`Replan::AfterBounce`], once more when it has bounced on this robot's
    /// half and left the table), drops the plan once it flies away.
    pub fn update_command(&mut self, robot: &Robot, ball: &BallState, t: f64) {
        let f = robot.frame;
        let pos = f.point_from_world(&ball.pos);
        let vel = f.vector_from_world(&ball.vel);
        if vel.x > 0.0 && pos.x < arena::STRIKE_PLANE_X {
            match self.plan {
                None => {
                    if let Ok(p) =
                        planner::plan(&pos, &vel, Some(Side::A), None, &mut self.rng, &self.bounce)
                    {
                        self.plan = Some((p, t + p.t_strike));
                        self.stage = match self.replan {
                            Replan::Once => ReplanStage::Done,
                            Replan::AfterBounce => ReplanStage::Incoming,
                        };
                    }
                }
                Some((first, _)) => {
                    // A bounce on this half turns the falling ball up; the contact with the soft
                    // table lasts about a control step, so the second plan waits for the ball to
                    // be clear of it.
                    if self.stage == ReplanStage::Incoming
                        && self.last_vz < 0.0
                        && vel.z > 0.0
                        && pos.x > 0.0
                    {
                        self.stage = ReplanStage::Bounced;
                    }
                    if self.stage == ReplanStage::Bounced
                        && vel.z > 0.0
                        && pos.z > arena::TABLE_TOP_Z + arena::BALL_RADIUS
                    {
                        self.stage = ReplanStage::Done;
                        if let Ok(p) = planner::plan(
                            &pos,
                            &vel,
                            Some(Side::A),
                            Some(first.v_out),
                            &mut self.rng,
                            &self.bounce,
                        ) {
                            self.plan = Some((p, t + p.t_strike));
                        }
                    }
                }
            }
            self.last_vz = vel.z;
        } else if vel.x < 0.0 {
            self.plan = None;
        }
    }

    /// Writes the observation of `robot` and `ball` (world frame) at time `t` into `out`.
    pub fn observe(&self, robot: &Robot, ball: &BallState, t: f64, out: &mut Vec<f64>) {
        out.clear();
        let model = robot.held_model();
        let f = robot.frame;
        for block in &self.blocks {
            match block {
                ObsBlock::Qpos => out.extend(
                    self.space
                        .joints
                        .iter()
                        .map(|&j| robot.state.qpos[model.joints[j].qpos_adr]),
                ),
                ObsBlock::Qvel => out.extend(
                    self.space
                        .joints
                        .iter()
                        .map(|&j| robot.state.qvel[model.joints[j].dof_adr]),
                ),
                ObsBlock::Act => out.extend(self.space.muscles.iter().map(|&a| robot.state.act[a])),
                ObsBlock::MuscleLength => out.extend(self.space.muscles.iter().map(|&a| {
                    let lr = model.actuators[a].lengthrange;
                    (robot.data.actuator_length[a] - lr[0]) / (lr[1] - lr[0]).max(1e-9)
                })),
                ObsBlock::BallPos => out.extend(f.point_from_world(&ball.pos).iter()),
                ObsBlock::BallVel => out.extend(f.vector_from_world(&ball.vel).iter()),
                ObsBlock::Paddle => {
                    let p = &robot.paddle;
                    let q = p.pose.rot.quaternion();
                    out.extend(p.pose.pos.iter());
                    out.extend([q.w, q.i, q.j, q.k]);
                    out.extend(p.lin_vel.iter());
                    out.extend(p.ang_vel.iter());
                }
                ObsBlock::Command => match &self.plan {
                    Some((p, t_hit)) => {
                        let q = p.racket_quat.quaternion();
                        out.extend(p.strike_pos.iter());
                        out.extend(p.racket_vel.iter());
                        out.extend([q.w, q.i, q.j, q.k]);
                        out.push((t_hit - t).max(0.0));
                    }
                    None => out.extend([0.0; 11]),
                },
                ObsBlock::CommandPosition => match &self.plan {
                    Some((p, _)) => out.extend(p.strike_pos.iter()),
                    None => out.extend([0.0; 3]),
                },
            }
        }
    }
}
