//! The RL environment over the single-serve episode (paper §IV-B, DESIGN §6): observations built from
//! the raw state `sim` exposes plus the planner's command, the reward `w_g·r_g + w_c·r_c + w_s·r_s`, and
//! a reset/step API on actions in [−1, 1]. Deterministic per seed. The observation is also what a
//! checkpoint's policy reads when it plays in evaluations and matches.

use nalgebra::{UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use sim::arena::{self, Side};
use sim::ball::BallState;
use sim::model::Model;
use sim::predict::BounceModel;
use sim::rng::Rng;
use sim::robot::Robot;

use crate::controller::ActionSpace;
use crate::planner::{self, Plan};

type V3 = Vector3<f64>;

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
        }
    }
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
}

impl Observer {
    /// An observer of `blocks` for `model`.
    pub fn new(model: &Model, blocks: Vec<ObsBlock>, seed: u64) -> Observer {
        Observer {
            blocks,
            space: ActionSpace::new(model),
            plan: None,
            rng: Rng::seeded(seed),
            bounce: BounceModel::for_table(&arena::MYOCHALLENGE.table),
        }
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

    /// The current command, if a ball is coming: the plan and the absolute strike time.
    pub fn command(&self) -> Option<&(Plan, f64)> {
        self.plan.as_ref()
    }

    /// Updates the command from the ball (world frame) at time `t`: plans once the ball flies towards
    /// this robot, drops the plan once it flies away.
    pub fn update_command(&mut self, robot: &Robot, ball: &BallState, t: f64) {
        let f = robot.frame;
        let pos = f.point_from_world(&ball.pos);
        let vel = f.vector_from_world(&ball.vel);
        if vel.x > 0.0 && pos.x < arena::STRIKE_PLANE_X {
            if self.plan.is_none() {
                if let Ok(p) =
                    planner::plan(&pos, &vel, Some(Side::A), None, &mut self.rng, &self.bounce)
                {
                    self.plan = Some((p, t + p.t_strike));
                }
            }
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
            }
        }
    }
}

/// Reward weights (paper §IV-B): `r = w_g·r_g + w_c·r_c + w_s·r_s`, plus `w_d` for the dual-rally term.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RewardWeights {
    /// Grasp: the paddle stays at its place in the hand.
    pub grasp: f64,
    /// Command tracking: blade pose towards the planned strike (dense), racket velocity at contact
    /// (sparse).
    pub command: f64,
    /// Task: contact, and a predicted legal landing after it (sparse).
    pub task: f64,
    /// Dual rally: the return crosses the other hitting plane inside the serve box (sparse).
    pub dual: f64,
}

impl Default for RewardWeights {
    fn default() -> Self {
        RewardWeights {
            grasp: 0.1,
            command: 1.0,
            task: 10.0,
            dual: 5.0,
        }
    }
}

/// Length scale of the dense pose term, m.
pub const POSE_SCALE: f64 = 0.1;
/// Speed scale of the sparse racket-velocity term, m/s.
pub const VELOCITY_SCALE: f64 = 1.0;
/// Distance scale of the grasp term, m.
pub const GRASP_SCALE: f64 = 0.05;

/// The reward terms of one control step, before weighting.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct RewardTerms {
    /// r_g ∈ [0, 1].
    pub grasp: f64,
    /// r_c ∈ [0, 2]: pose (dense) + velocity at contact (sparse).
    pub command: f64,
    /// r_s ∈ {0, 1, 2}: contact, and a predicted legal landing.
    pub task: f64,
    /// Dual term ∈ {0, 1}.
    pub dual: f64,
}

impl RewardTerms {
    /// The weighted sum.
    pub fn total(&self, w: &RewardWeights) -> f64 {
        w.grasp * self.grasp + w.command * self.command + w.task * self.task + w.dual * self.dual
    }
}

/// Grasp term: 1 while the paddle is at its place in the hand, falling off with its distance.
pub fn grasp_term(robot: &Robot, nominal: &V3) -> f64 {
    let d = (robot.paddle.pose.pos - nominal).norm();
    (-(d / GRASP_SCALE).powi(2)).exp()
}

/// Dense pose term: how close the blade centre is to the planned strike and how well the blade normal
/// (either face) lines up with the planned one.
pub fn pose_term(blade: &V3, normal: &V3, plan: &Plan) -> f64 {
    let u: V3 = plan.racket_quat * V3::z();
    let d = (blade - plan.strike_pos).norm();
    (-(d / POSE_SCALE).powi(2)).exp() * normal.dot(&u).powi(2)
}

/// Sparse velocity term at contact.
pub fn velocity_term(paddle_vel: &V3, plan: &Plan) -> f64 {
    (-((paddle_vel - plan.racket_vel).norm() / VELOCITY_SCALE).powi(2)).exp()
}

/// Whether the ball (robot frame), just returned by this robot, is predicted to land on the other half.
pub fn predicted_legal(ball: &BallState, bounce: &BounceModel) -> bool {
    sim::predict::next_bounce(&ball.pos, &ball.vel, bounce).is_some_and(|b| b.pos.x < 0.0)
}

/// Blade centre and normal of a robot's paddle (robot frame).
pub fn blade(robot: &Robot) -> (V3, V3) {
    let p = &robot.paddle.pose;
    let rot: UnitQuaternion<f64> = p.rot;
    (p.to_world(&V3::from(arena::BLADE_OFFSET)), rot * V3::z())
}

/// One step of the environment.
#[derive(Debug, Clone, PartialEq)]
pub struct Transition {
    /// Observation after the step.
    pub obs: Vec<f64>,
    /// Weighted reward.
    pub reward: f64,
    /// Its terms.
    pub terms: RewardTerms,
    /// The episode is over.
    pub done: bool,
    /// The robot has touched the ball (so far).
    pub hit: bool,
    /// The return was legal.
    pub success: bool,
}

/// The single-serve RL environment: actions in [−1, 1] through a controller, observations and rewards
/// as above.
pub struct Env {
    /// The episode.
    pub episode: sim::episode::SingleServe,
    /// Observation builder.
    pub observer: Observer,
    /// Action → controls.
    pub mapper: crate::controller::ActionMapper,
    /// Reward weights.
    pub weights: RewardWeights,
    /// Serve distribution.
    pub kind: sim::serve::ServeKind,
    obs: Vec<f64>,
    ctrl: Vec<f64>,
    bounce: BounceModel,
    contact_rewarded: bool,
}

impl Env {
    /// An environment for the robot `model`.
    pub fn new(
        model: std::sync::Arc<Model>,
        config: &sim::config::ArenaConfig,
        preset: sim::Preset,
        controller: &crate::controller::ControllerSpec,
        blocks: Vec<ObsBlock>,
        weights: RewardWeights,
        kind: sim::serve::ServeKind,
    ) -> Result<Env, String> {
        let episode = sim::episode::SingleServe::new(model.clone(), config, preset)?;
        Ok(Env {
            observer: Observer::new(&model, blocks, 0),
            mapper: crate::controller::ActionMapper::new(&model, controller),
            ctrl: vec![0.0; model.actuators.len()],
            episode,
            weights,
            kind,
            obs: Vec::new(),
            bounce: BounceModel::for_table(&preset.table),
            contact_rewarded: false,
        })
    }

    /// Observation length.
    pub fn obs_dim(&self) -> usize {
        self.observer.size()
    }

    /// Action length.
    pub fn action_dim(&self) -> usize {
        self.mapper.action_dim()
    }

    /// A new episode from `seed`; returns the first observation.
    pub fn reset(&mut self, seed: u64) -> Vec<f64> {
        let (serve_seed, planner_seed) = crate::eval::episode_seeds(seed, 0);
        self.episode
            .reset(self.kind, &mut Rng::seeded(serve_seed), None);
        self.observer.reset(planner_seed);
        self.contact_rewarded = false;
        let (robot, ball, t) = (
            &self.episode.robot,
            self.episode.world.ball,
            self.episode.world.time,
        );
        self.observer.update_command(robot, &ball, t);
        self.observer.observe(robot, &ball, t, &mut self.obs);
        self.obs.clone()
    }

    /// One control step with `action` (entries clipped to [−1, 1]; a NaN or infinite entry ends the
    /// episode with INVALID_ACTION and no reward).
    pub fn step(&mut self, action: &[f64]) -> Transition {
        if action.len() != self.action_dim() || action.iter().any(|a| !a.is_finite()) {
            self.episode.invalid_action();
            return Transition {
                obs: self.obs.clone(),
                reward: 0.0,
                terms: RewardTerms::default(),
                done: true,
                hit: self.episode.hit,
                success: false,
            };
        }
        let model = self.episode.robot.held_model().clone();
        self.ctrl.copy_from_slice(&self.episode.robot.state.ctrl);
        self.mapper.controls(
            &model,
            &self.episode.robot.state,
            action,
            arena::CONTROL_DT,
            &mut self.ctrl,
        );
        self.episode.robot.state.ctrl.copy_from_slice(&self.ctrl);
        let report = self.episode.step();
        let robot = &self.episode.robot;
        let ball = self.episode.world.ball;
        let t = self.episode.world.time;
        let mut terms = RewardTerms {
            grasp: (-(robot.paddle_offset() / GRASP_SCALE).powi(2)).exp(),
            ..RewardTerms::default()
        };
        let contact = report
            .events
            .iter()
            .any(|e| e.kind == sim::ContactKind::Paddle { owner: Side::A });
        if let Some((plan, _)) = self.observer.command() {
            let (c, n) = blade(robot);
            terms.command = pose_term(&c, &n, plan);
            if contact {
                terms.command += velocity_term(&robot.paddle.lin_vel, plan);
            }
        }
        if contact && !self.contact_rewarded {
            self.contact_rewarded = true;
            terms.task += 1.0;
            let f = robot.frame;
            let local = BallState {
                pos: f.point_from_world(&ball.pos),
                vel: f.vector_from_world(&ball.vel),
                spin: ball.spin,
            };
            if predicted_legal(&local, &self.bounce) {
                terms.task += 1.0;
            }
        }
        self.observer.update_command(robot, &ball, t);
        self.observer.observe(robot, &ball, t, &mut self.obs);
        Transition {
            obs: self.obs.clone(),
            reward: terms.total(&self.weights),
            terms,
            done: report.done,
            hit: self.episode.hit,
            success: self.episode.success,
        }
    }
}

/// The dual-rally RL environment (paper §IV-C): the learner plays side A through a controller, an
/// opponent player plays side B, rallies alternate their server. The reward adds the dual term: +1
/// when the learner's return crosses B's hitting plane inside the serve box.
pub struct RallyEnv {
    /// The rally.
    pub rally: sim::episode::Rally,
    /// Observation builder (side A).
    pub observer: Observer,
    /// Action → controls (side A).
    pub mapper: crate::controller::ActionMapper,
    /// The opponent on side B.
    pub opponent: Box<dyn crate::player::Player>,
    /// Reward weights.
    pub weights: RewardWeights,
    obs: Vec<f64>,
    ctrl: Vec<f64>,
    bounce: BounceModel,
    crossings_seen: usize,
    contact_rewarded: bool,
    rallies: u64,
}

impl RallyEnv {
    /// A rally environment for the robot `model` against `opponent`.
    pub fn new(
        model: std::sync::Arc<Model>,
        config: &sim::config::ArenaConfig,
        preset: sim::Preset,
        controller: &crate::controller::ControllerSpec,
        blocks: Vec<ObsBlock>,
        weights: RewardWeights,
        opponent: &crate::player::PlayerSpec,
    ) -> Result<RallyEnv, String> {
        let rally = sim::episode::Rally::new(model.clone(), config, preset)?;
        Ok(RallyEnv {
            observer: Observer::new(&model, blocks, 0),
            mapper: crate::controller::ActionMapper::new(&model, controller),
            opponent: opponent.build(&model, Side::B, 0)?,
            ctrl: vec![0.0; model.actuators.len()],
            rally,
            weights,
            obs: Vec::new(),
            bounce: BounceModel::for_table(&preset.table),
            crossings_seen: 0,
            contact_rewarded: false,
            rallies: 0,
        })
    }

    /// Observation length.
    pub fn obs_dim(&self) -> usize {
        self.observer.size()
    }

    /// Action length.
    pub fn action_dim(&self) -> usize {
        self.mapper.action_dim()
    }

    /// A new rally from `seed` (A serves the even rallies of this environment, B the odd ones).
    pub fn reset(&mut self, seed: u64) -> Vec<f64> {
        let (serve_seed, agent_seed) = crate::eval::episode_seeds(seed, 0);
        let server = if self.rallies.is_multiple_of(2) {
            Side::A
        } else {
            Side::B
        };
        self.rallies += 1;
        self.rally.reset(server, &mut Rng::seeded(serve_seed), None);
        self.observer.reset(agent_seed);
        self.opponent.reset();
        self.opponent.reseed(agent_seed.wrapping_add(1));
        self.crossings_seen = 0;
        self.contact_rewarded = false;
        let (robot, ball, t) = (
            &self.rally.arena.robots[0],
            self.rally.arena.world.ball,
            self.rally.arena.world.time,
        );
        self.observer.update_command(robot, &ball, t);
        self.observer.observe(robot, &ball, t, &mut self.obs);
        self.obs.clone()
    }

    /// One control step: the learner's `action` on A, the opponent on B.
    pub fn step(&mut self, action: &[f64]) -> Transition {
        if action.len() != self.action_dim() || action.iter().any(|a| !a.is_finite()) {
            self.rally.invalid_action(Side::A);
            return Transition {
                obs: self.obs.clone(),
                reward: 0.0,
                terms: RewardTerms::default(),
                done: true,
                hit: false,
                success: false,
            };
        }
        let model = self.rally.arena.robots[0].held_model().clone();
        let (ball, t) = (self.rally.arena.world.ball, self.rally.arena.world.time);
        let a = &self.rally.arena.robots[0];
        self.ctrl.copy_from_slice(&a.state.ctrl);
        self.mapper
            .controls(&model, &a.state, action, arena::CONTROL_DT, &mut self.ctrl);
        self.rally.arena.robots[0]
            .state
            .ctrl
            .copy_from_slice(&self.ctrl);
        let b = &self.rally.arena.robots[1];
        self.ctrl.copy_from_slice(&b.state.ctrl);
        let ok = self.opponent.act(b, &ball, t, &mut self.ctrl).is_ok()
            && self.ctrl.iter().all(|c| c.is_finite());
        if ok {
            self.rally.arena.robots[1]
                .state
                .ctrl
                .copy_from_slice(&self.ctrl);
        } else {
            self.rally.invalid_action(Side::B);
        }
        let report = self.rally.step();
        let robot = &self.rally.arena.robots[0];
        let (ball, t) = (self.rally.arena.world.ball, self.rally.arena.world.time);
        let mut terms = RewardTerms {
            grasp: (-(robot.paddle_offset() / GRASP_SCALE).powi(2)).exp(),
            ..RewardTerms::default()
        };
        let contact = report
            .events
            .iter()
            .any(|e| e.kind == sim::ContactKind::Paddle { owner: Side::A });
        if let Some((plan, _)) = self.observer.command() {
            let (c, n) = blade(robot);
            terms.command = pose_term(&c, &n, plan);
            if contact {
                terms.command += velocity_term(&robot.paddle.lin_vel, plan);
            }
        }
        if contact {
            if !self.contact_rewarded {
                terms.task += 1.0;
                let local = BallState {
                    pos: robot.frame.point_from_world(&ball.pos),
                    vel: robot.frame.vector_from_world(&ball.vel),
                    spin: ball.spin,
                };
                if predicted_legal(&local, &self.bounce) {
                    terms.task += 1.0;
                }
            }
            self.contact_rewarded = true;
        }
        // A new incoming ball for A re-arms the contact reward; A's return crossing B's plane in the
        // serve box earns the dual term.
        for c in &self.rally.crossings[self.crossings_seen..] {
            match c.receiver {
                Side::B if c.exchange > 0 && c.in_box => terms.dual += 1.0,
                Side::A => self.contact_rewarded = false,
                Side::B => {}
            }
        }
        self.crossings_seen = self.rally.crossings.len();
        self.observer.update_command(robot, &ball, t);
        self.observer.observe(robot, &ball, t, &mut self.obs);
        let returns_by_a = report.calls.iter().any(|c| {
            matches!(
                c,
                sim::rules::Call::LegalReturn {
                    hitter: Side::A,
                    ..
                }
            )
        });
        Transition {
            obs: self.obs.clone(),
            reward: terms.total(&self.weights),
            terms,
            done: report.done,
            hit: contact,
            success: returns_by_a,
        }
    }
}
