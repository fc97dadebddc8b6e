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

/// Reward weights (paper §IV-B; the values are the official code's, DESIGN §11):
/// `r = w_g·r_g + w_c·r_c + w_s·r_s`, each a sum of named terms, plus `dual` in the rally arena.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RewardWeights {
    /// Grasp (dense): `exp(−20·d)`, `d` the paddle's distance from its place in the hand (official ×4
    /// for position and ×4 for orientation; our grip holds both together).
    pub grasp: f64,
    /// Command (dense): `exp(−8·d)`, `d` the blade centre's distance from the planned strike point;
    /// paid in full from contact on (official ×20).
    pub position: f64,
    /// Command (dense): `exp(−2·θ)`, `θ` the angle between the blade normal and the planned one
    /// (either face); paid in full from contact on (official ×10).
    pub orientation: f64,
    /// Command (sparse, at contact): `exp(−|v − v̂|)`, the paddle's velocity against the planned
    /// racket velocity (paper §IV-B; not in the official code's list: ours).
    pub velocity: f64,
    /// Task (sparse, once): the paddle touched the ball (official ×100).
    pub hit: f64,
    /// Task (sparse, once): the return is predicted to land on the other half (official ×100).
    pub landing: f64,
    /// Task (sparse, once): `exp(−0.5·‖(y_r, z) − (0, 1.225)‖)` of the return's predicted crossing of
    /// the other hitting plane, against the serve box's centre (official ×100).
    pub centre: f64,
    /// Task (sparse, once): that crossing lies inside the serve box (official ×100).
    pub in_box: f64,
    /// Task (sparse, once): a return predicted to go into the net or out (official −20).
    pub fault: f64,
    /// Dual rally: the learner's return really crossed the other hitting plane inside the serve box.
    pub dual: f64,
}

impl Default for RewardWeights {
    fn default() -> Self {
        RewardWeights {
            grasp: 4.0,
            position: 20.0,
            orientation: 10.0,
            velocity: 20.0,
            hit: 100.0,
            landing: 100.0,
            centre: 100.0,
            in_box: 100.0,
            fault: -20.0,
            dual: 100.0,
        }
    }
}

/// The serve box's centre height, m (official code: the `(0, 1.225)` the `centre` term aims at).
pub const SERVE_BOX_CENTRE_Z: f64 = 0.5 * (arena::SERVE_BOX_Z.0 + arena::SERVE_BOX_Z.1);
/// Control steps after the ball leaves the paddle at which the task terms are judged and a training
/// episode ends (official code: 3).
pub const TASK_DELAY_STEPS: usize = 3;
/// A training episode without contact ends this long after the planned strike time, s (official).
pub const MISS_GRACE: f64 = 0.05;

/// The reward terms of one control step, before weighting (each in [0, 1]).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct RewardTerms {
    /// Paddle in the hand.
    pub grasp: f64,
    /// Blade centre at the planned strike point.
    pub position: f64,
    /// Blade normal along the planned one.
    pub orientation: f64,
    /// Paddle velocity at contact.
    pub velocity: f64,
    /// First contact with this ball.
    pub hit: f64,
    /// Predicted landing on the other half.
    pub landing: f64,
    /// Closeness of the predicted crossing to the serve box's centre.
    pub centre: f64,
    /// Predicted crossing inside the serve box.
    pub in_box: f64,
    /// Predicted net or out.
    pub fault: f64,
    /// Dual rally: a real crossing of the other plane in the box.
    pub dual: f64,
}

impl RewardTerms {
    /// The weighted sum.
    pub fn total(&self, w: &RewardWeights) -> f64 {
        w.grasp * self.grasp
            + w.position * self.position
            + w.orientation * self.orientation
            + w.velocity * self.velocity
            + w.hit * self.hit
            + w.landing * self.landing
            + w.centre * self.centre
            + w.in_box * self.in_box
            + w.fault * self.fault
            + w.dual * self.dual
    }
}

/// Grasp term: 1 while the paddle is at its place in the hand, `exp(−20·d)` once it slips.
pub fn grasp_term(robot: &Robot) -> f64 {
    (-20.0 * robot.paddle_offset()).exp()
}

/// Dense pose terms against the plan: `exp(−8·d)` of the blade centre's distance to the strike point,
/// `exp(−2·θ)` of the angle between the blade normal (either face) and the planned normal.
pub fn pose_terms(blade: &V3, normal: &V3, plan: &Plan) -> (f64, f64) {
    let u: V3 = plan.racket_quat * V3::z();
    let d = (blade - plan.strike_pos).norm();
    let theta = normal.dot(&u).abs().min(1.0).acos();
    ((-8.0 * d).exp(), (-2.0 * theta).exp())
}

/// Sparse velocity term at contact.
pub fn velocity_term(paddle_vel: &V3, plan: &Plan) -> f64 {
    (-(paddle_vel - plan.racket_vel).norm()).exp()
}

/// The task terms of a ball (robot frame) that this robot (side A of its frame) has just returned:
/// predicted landing on the other half, closeness of the crossing of the other plane to the serve
/// box's centre, that crossing in the box, or a predicted fault.
pub fn task_terms(ball: &BallState, bounce: &BounceModel, terms: &mut RewardTerms) {
    let lands = predicted_legal(ball, bounce);
    if !lands {
        terms.fault = 1.0;
        return;
    }
    terms.landing = 1.0;
    let crossing =
        sim::predict::plane_crossing(&ball.pos, &ball.vel, Side::B.strike_plane_x(), bounce);
    if let Some(c) = &crossing {
        let (y_r, z) = Side::B.receiver_frame(&c.pos);
        terms.centre = (-0.5 * (y_r * y_r + (z - SERVE_BOX_CENTRE_Z).powi(2)).sqrt()).exp();
    }
    if sim::predict::return_is_in_box(Side::A, &crossing) {
        terms.in_box = 1.0;
    }
}

/// Whether the ball (robot frame), just returned by this robot, is predicted to land on the other half:
/// its next bounce is there and it passes over the net on the way.
pub fn predicted_legal(ball: &BallState, bounce: &BounceModel) -> bool {
    sim::predict::next_bounce(&ball.pos, &ball.vel, bounce).is_some_and(|b| b.pos.x < 0.0)
        && sim::predict::clears_net(&ball.pos, &ball.vel)
}

/// Blade centre and normal of a robot's paddle (robot frame).
pub fn blade(robot: &Robot) -> (V3, V3) {
    let p = &robot.paddle.pose;
    let rot: UnitQuaternion<f64> = p.rot;
    (p.to_world(&V3::from(arena::BLADE_OFFSET)), rot * V3::z())
}

/// The reward of one incoming ball, step by step: dense pose terms against the plan (in full once
/// the ball was touched), the velocity term at contact, and the task terms once, `TASK_DELAY_STEPS`
/// after the ball left the paddle.
#[derive(Debug, Clone, Default)]
struct StrokeReward {
    /// Steps since the last control step with a paddle contact, once there was one.
    since_contact: Option<usize>,
    /// The task terms were paid for this ball.
    judged: bool,
}

impl StrokeReward {
    /// This step's terms for `robot` (robot frame), `contact` whether the paddle touched the ball in
    /// it, `plan` the command. Returns the terms and whether the task terms were paid now.
    fn step(
        &mut self,
        robot: &Robot,
        ball_world: &BallState,
        contact: bool,
        plan: Option<&Plan>,
        bounce: &BounceModel,
    ) -> (RewardTerms, bool) {
        let mut terms = RewardTerms {
            grasp: grasp_term(robot),
            ..RewardTerms::default()
        };
        let touched = contact || self.since_contact.is_some();
        if contact {
            if self.since_contact.is_none() {
                terms.hit = 1.0;
            }
            self.since_contact = Some(0);
        } else if let Some(k) = self.since_contact.as_mut() {
            *k += 1;
        }
        if touched {
            terms.position = 1.0;
            terms.orientation = 1.0;
        } else if let Some(plan) = plan {
            let (c, n) = blade(robot);
            (terms.position, terms.orientation) = pose_terms(&c, &n, plan);
        }
        if contact {
            if let Some(plan) = plan {
                terms.velocity = velocity_term(&robot.paddle.lin_vel, plan);
            }
        }
        let mut paid = false;
        if !self.judged && self.since_contact == Some(TASK_DELAY_STEPS) {
            self.judged = true;
            paid = true;
            let f = robot.frame;
            let local = BallState {
                pos: f.point_from_world(&ball_world.pos),
                vel: f.vector_from_world(&ball_world.vel),
                spin: ball_world.spin,
            };
            task_terms(&local, bounce, &mut terms);
        }
        (terms, paid)
    }
}

/// How a single-serve episode ends for training (DESIGN §11): the official code ends it
/// `TASK_DELAY_STEPS` after the ball left the paddle and `MISS_GRACE` after the planned strike
/// without contact, besides the rules; evaluation plays every episode to its rules' end.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum EpisodeEnd {
    /// The rules and the time limit only (evaluation).
    #[default]
    Rules,
    /// Also the official code's early ends (training).
    Training,
}

/// Keeps the grip muscles' controls at `floor` or above, whatever the controller asked: a trained
/// checkpoint's `grip_floor` (the house agent does the same with its `grip_activation`). Our grip
/// holds by the squeeze of three flexors; a policy trained with exploration noise gets that squeeze
/// from the noise itself (muscles only pull, so jittered targets co-contract), and its noise-free
/// mean action then lets the paddle slip — the floor keeps evaluation what training saw.
pub fn apply_grip_floor(robot: &Robot, floor: f64, ctrl: &mut [f64]) {
    if floor > 0.0 {
        for &m in robot.grip_muscles() {
            ctrl[m] = ctrl[m].max(floor);
        }
    }
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
    /// The return was legal (so far; in a rally: a legal return by the learner in this step).
    pub success: bool,
}

fn paddle_contact(report: &sim::episode::StepReport, side: Side) -> bool {
    report
        .events
        .iter()
        .any(|e| e.kind == sim::ContactKind::Paddle { owner: side })
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
    /// When an episode ends.
    pub end: EpisodeEnd,
    /// Least control of the grip muscles (see [`apply_grip_floor`]).
    pub grip_floor: f64,
    obs: Vec<f64>,
    ctrl: Vec<f64>,
    bounce: BounceModel,
    stroke: StrokeReward,
    predicted_success: bool,
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
            observer: Observer::new(&model, blocks, 0)
                .with_bounce(BounceModel::for_table(&preset.table)),
            mapper: crate::controller::ActionMapper::new(&model, controller),
            ctrl: vec![0.0; model.actuators.len()],
            episode,
            weights,
            kind,
            end: EpisodeEnd::Rules,
            grip_floor: 0.0,
            obs: Vec::new(),
            bounce: BounceModel::for_table(&preset.table),
            stroke: StrokeReward::default(),
            predicted_success: false,
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

    /// The observation of the current state.
    pub fn observation(&self) -> &[f64] {
        &self.obs
    }

    /// A new episode from `seed`; returns the first observation.
    pub fn reset(&mut self, seed: u64) -> Vec<f64> {
        let (serve_seed, planner_seed) = crate::eval::episode_seeds(seed, 0);
        self.episode
            .reset(self.kind, &mut Rng::seeded(serve_seed), None);
        self.observer.reset(planner_seed);
        self.stroke = StrokeReward::default();
        self.predicted_success = false;
        let (robot, ball, t) = (
            &self.episode.robot,
            self.episode.world.ball,
            self.episode.world.time,
        );
        self.observer.update_command(robot, &ball, t);
        self.observer.observe(robot, &ball, t, &mut self.obs);
        self.obs.clone()
    }

    /// Whether the return of this episode is judged legal: by the rules once the ball landed, or, in
    /// a training episode that ended before, by the predicted landing.
    pub fn success(&self) -> bool {
        self.episode.success || (self.end == EpisodeEnd::Training && self.predicted_success)
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
        apply_grip_floor(&self.episode.robot, self.grip_floor, &mut self.ctrl);
        self.episode.robot.state.ctrl.copy_from_slice(&self.ctrl);
        let report = self.episode.step();
        let robot = &self.episode.robot;
        let ball = self.episode.world.ball;
        let t = self.episode.world.time;
        let contact = paddle_contact(&report, Side::A);
        let plan = self.observer.command().map(|(p, _)| *p);
        let strike_time = self.observer.command().map(|(_, t_hit)| *t_hit);
        let (terms, judged) = self
            .stroke
            .step(robot, &ball, contact, plan.as_ref(), &self.bounce);
        if judged {
            self.predicted_success = terms.landing > 0.0;
        }
        let mut done = report.done;
        if self.end == EpisodeEnd::Training {
            let missed =
                !self.episode.hit && strike_time.is_some_and(|t_hit| t > t_hit + MISS_GRACE);
            done |= judged || missed;
        }
        self.observer.update_command(robot, &ball, t);
        self.observer.observe(robot, &ball, t, &mut self.obs);
        Transition {
            obs: self.obs.clone(),
            reward: terms.total(&self.weights),
            terms,
            done,
            hit: self.episode.hit,
            success: self.success(),
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
    stroke: StrokeReward,
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
            observer: Observer::new(&model, blocks, 0)
                .with_bounce(BounceModel::for_table(&preset.table)),
            mapper: crate::controller::ActionMapper::new(&model, controller),
            opponent: opponent.build(&model, &preset, 0)?,
            ctrl: vec![0.0; model.actuators.len()],
            rally,
            weights,
            obs: Vec::new(),
            bounce: BounceModel::for_table(&preset.table),
            crossings_seen: 0,
            stroke: StrokeReward::default(),
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
        self.stroke = StrokeReward::default();
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
        let contact = paddle_contact(&report, Side::A);
        let plan = self.observer.command().map(|(p, _)| *p);
        let (mut terms, _) = self
            .stroke
            .step(robot, &ball, contact, plan.as_ref(), &self.bounce);
        // A new incoming ball for A starts a new stroke; A's return crossing B's plane in the serve
        // box earns the dual term.
        for c in &self.rally.crossings[self.crossings_seen..] {
            match c.receiver {
                Side::B if c.exchange > 0 && c.in_box => terms.dual += 1.0,
                Side::A => self.stroke = StrokeReward::default(),
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
