//! The RL environments (paper §IV-B and §IV-C, docs/design.md §6): the single-serve episode and the
//! self-play rally, with the reward `w_g·r_g + w_c·r_c + w_s·r_s` and a reset/step API on actions in
//! [−1, 1], observing through [`crate::observation`]. Deterministic per seed.

use nalgebra::{UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use sim::arena::{self, Side};
use sim::ball::BallState;
use sim::model::Model;
use sim::predict::BounceModel;
use sim::rng::Rng;
use sim::robot::Robot;

use crate::controller::apply_grip_floor;
use crate::observation::{ObsBlock, Observer};
use crate::planner::Plan;

type V3 = Vector3<f64>;

/// The reward's terms (paper §IV-B; docs/design.md §6): `r = w_g·r_g + w_c·r_c + w_s·r_s`, each a sum of named
/// terms. One struct holds both a step's term values (each in [0, 1]) and their weights
/// ([`RewardWeights`]), so a term is named once.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RewardTerms {
    /// Grasp (dense): `exp(−20·d)`, `d` the paddle's distance from its place in the hand (official ×4
    /// for position and ×4 for orientation; our grip holds both together).
    pub grasp: f64,
    /// Command (dense): `exp(−8·d)`, `d` the blade centre's distance from the planned strike point;
    /// paid in full from contact until the stroke is judged (official ×20).
    pub position: f64,
    /// Command (dense): `exp(−2·θ)`, `θ` the angle between the blade normal and the planned one
    /// (either face); paid in full from contact until the stroke is judged (official ×10).
    pub orientation: f64,
    /// Command (sparse, at contact): `exp(−|v − v̂|)`, the paddle's velocity against the planned
    /// racket velocity (paper §IV-B; not in the official code's list: ours).
    pub velocity: f64,
    /// Command (sparse, at first contact): `exp(−|v_b − v̂_o|)`, the ball's velocity as it leaves the
    /// paddle against the planned outgoing velocity (ours; 0 unless weighted): a graded signal for
    /// the strokes the task terms only call faults (most returns that go out leave 1–2 m/s too
    /// steep, agents/examples/strokes.rs).
    #[serde(default)]
    pub ball_out: f64,
    /// Task (sparse, once per ball): the paddle touched the ball (official ×100).
    pub hit: f64,
    /// Task (sparse, once per ball): the return is predicted to land on the other half (official ×100).
    pub landing: f64,
    /// Task (sparse, once per ball): `exp(−0.5·‖(y_r, z) − (0, 1.225)‖)` of the return's predicted
    /// crossing of the other hitting plane, against the serve box's centre (official ×100).
    pub centre: f64,
    /// Task (sparse, once per ball): that crossing lies inside the serve box (official ×100).
    pub in_box: f64,
    /// Task (sparse, once per ball): a return predicted to go into the net or out (official −20).
    pub fault: f64,
    /// Dual rally only (dense): `exp(−4·d)`, `d` the paddle's distance from where it was at the
    /// rally's start, while no ball is coming and no stroke is being judged — the paper's "maintain
    /// stability after striking", so that the robot is ready for the next ball (ours).
    #[serde(default)]
    pub ready: f64,
    /// Dual rally only (sparse): the robot's return really crossed the other hitting plane inside the
    /// serve box (paper §IV-C).
    pub dual: f64,
    /// Effort (dense, ours; the official code has none): the step's mean muscle activation
    /// `‖a‖₁/n_a`, the metric `rally eval` reports beside effort (docs/design.md §7); a negative weight prices
    /// activation. 0 unless weighted.
    #[serde(default)]
    pub effort: f64,
}

impl RewardTerms {
    /// `Σ wᵢ·termᵢ`.
    pub fn total(&self, w: &RewardWeights) -> f64 {
        let w = &w.0;
        w.grasp * self.grasp
            + w.position * self.position
            + w.orientation * self.orientation
            + w.velocity * self.velocity
            + w.ball_out * self.ball_out
            + w.hit * self.hit
            + w.landing * self.landing
            + w.centre * self.centre
            + w.in_box * self.in_box
            + w.fault * self.fault
            + w.ready * self.ready
            + w.dual * self.dual
            + w.effort * self.effort
    }
}

/// The weights of the reward's terms; the defaults are the official code's (docs/design.md §11) where it has
/// the term.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct RewardWeights(pub RewardTerms);

impl std::ops::Deref for RewardWeights {
    type Target = RewardTerms;
    fn deref(&self) -> &RewardTerms {
        &self.0
    }
}

impl Default for RewardWeights {
    fn default() -> Self {
        RewardWeights(RewardTerms {
            grasp: 4.0,
            position: 20.0,
            orientation: 10.0,
            velocity: 20.0,
            ball_out: 0.0,
            hit: 100.0,
            landing: 100.0,
            centre: 100.0,
            in_box: 100.0,
            fault: -20.0,
            ready: 10.0,
            dual: 100.0,
            effort: 0.0,
        })
    }
}

/// The serve box's centre height, m (official code: the `(0, 1.225)` the `centre` term aims at).
pub const SERVE_BOX_CENTRE_Z: f64 = 0.5 * (arena::SERVE_BOX_Z.0 + arena::SERVE_BOX_Z.1);
/// Control steps after the ball leaves the paddle at which the task terms are judged and a training
/// episode ends (official code: 3).
pub const TASK_DELAY_STEPS: usize = 3;
/// A training episode without contact ends this long after the planned strike time, s (official).
pub const MISS_GRACE: f64 = 0.05;

/// Grasp term: 1 while the paddle is at its place in the hand, `exp(−20·d)` once it slips.
pub fn grasp_term(robot: &Robot) -> f64 {
    (-20.0 * robot.paddle_offset()).exp()
}

/// The robot's mean muscle activation `‖a‖₁/n_a` (docs/design.md §7's mean activation, one step).
pub fn mean_activation(robot: &Robot) -> f64 {
    let (sum, n) = robot
        .model()
        .muscles()
        .fold((0.0, 0usize), |(s, n), (i, _)| {
            (s + robot.state.act[i].abs(), n + 1)
        });
    sum / n.max(1) as f64
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
    (p.to_world(&robot.shape.blade.center), rot * V3::z())
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
    /// The ball was touched and its task terms are still to be paid.
    fn in_progress(&self) -> bool {
        self.since_contact.is_some() && !self.judged
    }
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
            effort: mean_activation(robot),
            ..RewardTerms::default()
        };
        let touched = !self.judged && (contact || self.since_contact.is_some());
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
                if terms.hit == 1.0 {
                    let v = robot.frame.vector_from_world(&ball_world.vel);
                    terms.ball_out = (-(v - plan.v_out).norm()).exp();
                }
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

/// How a single-serve episode ends for training (docs/design.md §11): the official code ends it
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
    /// Balls recorded from rallies, served instead of `kind` in a fraction of episodes.
    pub bank: Option<BallBank>,
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
            bank: None,
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
        let (serve_seed, planner_seed) = crate::seeds::episode_seeds(seed, 0);
        let mut rng = Rng::seeded(serve_seed);
        match self.bank.as_ref().and_then(|b| b.draw(&mut rng)) {
            Some(ball) => self.episode.reset_with(
                sim::serve::Serve {
                    ball,
                    server: Side::B,
                    receiver: Side::A,
                    predicted_crossing: None,
                },
                None,
            ),
            None => self.episode.reset(self.kind, &mut rng, None),
        }
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

/// The file format of a ball bank.
pub const BANK_FORMAT: &str = "muscle-rally-balls";

/// Balls recorded from rallies (`rally match --returns`), each as its receiver met it, in the frame
/// of a ball struck by B towards A: a single-serve environment serves one of them, drawn uniformly,
/// in `fraction` of its episodes (ours: training on the balls a rally brings, not only on serves).
#[derive(Debug, Clone)]
pub struct BallBank {
    /// The balls.
    pub balls: std::sync::Arc<[BallState]>,
    /// Share of episodes served from the bank, in [0, 1].
    pub fraction: f64,
}

impl BallBank {
    /// One episode's ball: with probability `fraction` a bank ball, else `None` (serve as usual).
    /// Draws: one uniform, and one more for the index when the bank serves.
    pub fn draw(&self, rng: &mut Rng) -> Option<BallState> {
        if self.balls.is_empty() || rng.unit() >= self.fraction {
            return None;
        }
        let i = ((rng.unit() * self.balls.len() as f64) as usize).min(self.balls.len() - 1);
        Some(self.balls[i])
    }

    /// The bank file's JSON: `{"format", "version": 1, "frame", "source", "balls": [[x, y, z, vx,
    /// vy, vz, wx, wy, wz], …]}`.
    pub fn to_json(balls: &[BallState], source: serde_json::Value) -> serde_json::Value {
        let rows: Vec<Vec<f64>> = balls
            .iter()
            .map(|b| {
                b.pos
                    .iter()
                    .chain(b.vel.iter())
                    .chain(b.spin.iter())
                    .copied()
                    .collect()
            })
            .collect();
        serde_json::json!({
            "format": BANK_FORMAT,
            "version": 1,
            "frame": "struck by B (x < 0) towards A: world coordinates, m, m/s, rad/s",
            "source": source,
            "balls": rows,
        })
    }

    /// Reads a bank file's balls; the error says what is wrong and where.
    pub fn parse(text: &str) -> Result<Vec<BallState>, String> {
        #[derive(Deserialize)]
        struct File {
            format: String,
            version: u32,
            balls: Vec<Vec<f64>>,
        }
        let f: File = serde_json::from_str(text).map_err(|e| format!("not a ball bank: {e}"))?;
        if f.format != BANK_FORMAT || f.version != 1 {
            return Err(format!(
                "format {:?} version {}: expected {BANK_FORMAT:?} version 1",
                f.format, f.version
            ));
        }
        if f.balls.is_empty() {
            return Err("balls: empty".into());
        }
        f.balls
            .iter()
            .enumerate()
            .map(|(i, r)| {
                if r.len() != 9 || r.iter().any(|x| !x.is_finite()) {
                    return Err(format!("balls[{i}]: expected 9 finite numbers"));
                }
                if r[3] <= 0.0 {
                    return Err(format!("balls[{i}]: moves away from A (vx = {})", r[3]));
                }
                Ok(BallState {
                    pos: V3::new(r[0], r[1], r[2]),
                    vel: V3::new(r[3], r[4], r[5]),
                    spin: V3::new(r[6], r[7], r[8]),
                })
            })
            .collect()
    }
}

/// One robot of the rally environment, driven by the learner's policy.
struct Seat {
    side: Side,
    observer: Observer,
    stroke: StrokeReward,
    /// The paddle's position at the rally's start (robot frame): the `ready` term's target.
    ready: V3,
    obs: Vec<f64>,
    /// This side touched the ball in this rally.
    hit: bool,
    /// Legal returns by this side in this rally.
    returns: u32,
    /// Had a command at the previous step (a new one starts a new stroke).
    planned: bool,
}

/// The dual-rally RL environment (paper §IV-C), in self-play: the learner's policy plays both robots
/// (each observes in its own frame), so one simulated step gives two transitions, and the policy
/// meets exactly the balls it will meet in a `kmac-rally` against `kmac-rally` match. The server is
/// drawn from the rally's seed and serves the heuristic rally serve. Each side's reward is the
/// single-serve stroke reward for every ball that comes to it, the `ready` term between strokes
/// and the `dual` term when its return crosses the other hitting plane inside the serve box. A rally
/// ends by the rules (both sides' episodes end with it; CAPPED is a time limit, not a terminal).
pub struct RallyEnv {
    /// The rally.
    pub rally: sim::episode::Rally,
    /// Action → controls (both sides: the same controller).
    pub mapper: crate::controller::ActionMapper,
    /// Reward weights.
    pub weights: RewardWeights,
    /// Least control of the grip muscles (see [`apply_grip_floor`]).
    pub grip_floor: f64,
    seats: [Seat; 2],
    ctrl: Vec<f64>,
    bounce: BounceModel,
    crossings_seen: usize,
}

/// One step of the rally environment for one side.
#[derive(Debug, Clone, PartialEq)]
pub struct RallyTransition {
    /// The side's step, as in the single-serve environment (`hit`: this side touched the ball in
    /// this rally; `success`: it made a legal return in this rally).
    pub step: Transition,
    /// Legal returns by this side in this rally so far.
    pub returns: u32,
    /// The position term, when the side tracked a command before touching its ball.
    pub tracking: Option<f64>,
}

impl RallyEnv {
    /// A rally environment for the robot `model`, `controller` on both sides.
    pub fn new(
        model: std::sync::Arc<Model>,
        config: &sim::config::ArenaConfig,
        preset: sim::Preset,
        controller: &crate::controller::ControllerSpec,
        blocks: Vec<ObsBlock>,
        weights: RewardWeights,
    ) -> Result<RallyEnv, String> {
        let rally = sim::episode::Rally::new(model.clone(), config, preset)?;
        let bounce = BounceModel::for_table(&preset.table);
        let seat = |side| Seat {
            side,
            observer: Observer::new(&model, blocks.clone(), 0).with_bounce(bounce),
            stroke: StrokeReward::default(),
            ready: V3::zeros(),
            obs: Vec::new(),
            hit: false,
            returns: 0,
            planned: false,
        };
        Ok(RallyEnv {
            mapper: crate::controller::ActionMapper::new(&model, controller),
            ctrl: vec![0.0; model.actuators.len()],
            rally,
            weights,
            grip_floor: 0.0,
            seats: [seat(Side::A), seat(Side::B)],
            bounce,
            crossings_seen: 0,
        })
    }

    /// Observation length (per side).
    pub fn obs_dim(&self) -> usize {
        self.seats[0].observer.size()
    }

    /// Action length (per side).
    pub fn action_dim(&self) -> usize {
        self.mapper.action_dim()
    }

    /// Side `i`'s observation of the current state (0 = A, 1 = B).
    pub fn observation(&self, i: usize) -> &[f64] {
        &self.seats[i].obs
    }

    /// Side `i`'s current command.
    pub fn command(&self, i: usize) -> Option<&(Plan, f64)> {
        self.seats[i].observer.command()
    }

    /// A new rally from `seed`: the server is drawn from it, then the serve and both planners'
    /// samplers.
    pub fn reset(&mut self, seed: u64) {
        let (serve_seed, agent_seed) = crate::seeds::episode_seeds(seed, 0);
        let mut rng = Rng::seeded(serve_seed);
        let server = if rng.unit() < 0.5 { Side::A } else { Side::B };
        self.rally.reset(server, &mut rng, None);
        self.crossings_seen = 0;
        let (ball, t) = (self.rally.arena.world.ball, self.rally.arena.world.time);
        for (i, seat) in self.seats.iter_mut().enumerate() {
            let robot = &self.rally.arena.robots[i];
            seat.observer.reset(agent_seed.wrapping_add(i as u64));
            seat.stroke = StrokeReward::default();
            seat.ready = robot.paddle.pose.pos;
            seat.hit = false;
            seat.returns = 0;
            seat.observer.update_command(robot, &ball, t);
            seat.planned = seat.observer.command().is_some();
            seat.observer.observe(robot, &ball, t, &mut seat.obs);
        }
    }

    /// One control step with both sides' actions (entries clipped to [−1, 1] by the caller; a NaN
    /// or infinite entry loses the rally for that side with INVALID_ACTION and no reward).
    pub fn step(&mut self, actions: [&[f64]; 2]) -> [RallyTransition; 2] {
        let model = self.rally.arena.robots[0].held_model().clone();
        let mut invalid = None;
        for (i, action) in actions.iter().enumerate() {
            if action.len() != self.action_dim() || action.iter().any(|a| !a.is_finite()) {
                invalid.get_or_insert(self.seats[i].side);
                continue;
            }
            let robot = &self.rally.arena.robots[i];
            self.ctrl.copy_from_slice(&robot.state.ctrl);
            self.mapper.controls(
                &model,
                &robot.state,
                action,
                arena::CONTROL_DT,
                &mut self.ctrl,
            );
            apply_grip_floor(robot, self.grip_floor, &mut self.ctrl);
            self.rally.arena.robots[i]
                .state
                .ctrl
                .copy_from_slice(&self.ctrl);
        }
        let report = match invalid {
            Some(side) => {
                self.rally.invalid_action(side);
                sim::episode::StepReport {
                    done: true,
                    ..Default::default()
                }
            }
            None => self.rally.step(),
        };
        let (ball, t) = (self.rally.arena.world.ball, self.rally.arena.world.time);
        let new_crossings = &self.rally.crossings[self.crossings_seen..];
        let out = std::array::from_fn(|i| {
            let seat = &mut self.seats[i];
            let robot = &self.rally.arena.robots[i];
            let side = seat.side;
            if invalid.is_some() {
                return RallyTransition {
                    step: Transition {
                        obs: seat.obs.clone(),
                        reward: 0.0,
                        terms: RewardTerms::default(),
                        done: true,
                        hit: seat.hit,
                        success: seat.returns > 0,
                    },
                    returns: seat.returns,
                    tracking: None,
                };
            }
            let contact = paddle_contact(&report, side);
            seat.hit |= contact;
            let plan = seat.observer.command().map(|(p, _)| *p);
            let tracking = plan.is_some() && seat.stroke.since_contact.is_none() && !contact;
            let (mut terms, _) =
                seat.stroke
                    .step(robot, &ball, contact, plan.as_ref(), &self.bounce);
            if plan.is_none() && !seat.stroke.in_progress() {
                let d = (robot.paddle.pose.pos - seat.ready).norm();
                terms.ready = (-4.0 * d).exp();
            }
            // This side's return (exchange ≥ 1) crossing the other side's plane in the box.
            terms.dual = new_crossings
                .iter()
                .filter(|c| c.receiver == side.other() && c.exchange > 0 && c.in_box)
                .count() as f64;
            seat.returns += report
                .calls
                .iter()
                .filter(|c| matches!(c, sim::rules::Call::LegalReturn { hitter, .. } if *hitter == side))
                .count() as u32;
            seat.observer.update_command(robot, &ball, t);
            let planned = seat.observer.command().is_some();
            if planned && !seat.planned {
                // A new ball is coming: a new stroke.
                seat.stroke = StrokeReward::default();
            }
            seat.planned = planned;
            seat.observer.observe(robot, &ball, t, &mut seat.obs);
            RallyTransition {
                step: Transition {
                    obs: seat.obs.clone(),
                    reward: terms.total(&self.weights),
                    terms,
                    done: report.done,
                    hit: seat.hit,
                    success: seat.returns > 0,
                },
                returns: seat.returns,
                tracking: tracking.then_some(terms.position),
            }
        });
        self.crossings_seen = self.rally.crossings.len();
        out
    }

    /// Whether the rally ended by its cap or time limit (CAPPED), not by a failure.
    pub fn capped(&self) -> bool {
        self.rally
            .referee
            .end()
            .is_some_and(|e| e.failing_side.is_none())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ball(vx: f64) -> BallState {
        BallState {
            pos: V3::new(-1.8, 0.1, 1.2),
            vel: V3::new(vx, 0.2, 1.0),
            spin: V3::new(0.0, -5.0, 0.0),
        }
    }

    #[test]
    fn a_bank_serves_its_share_of_episodes_and_only_its_balls() {
        let balls: Vec<BallState> = (0..5).map(|i| ball(5.0 + i as f64)).collect();
        let share = |fraction: f64| {
            let bank = BallBank {
                balls: balls.clone().into(),
                fraction,
            };
            let mut rng = Rng::seeded(3);
            let drawn: Vec<Option<BallState>> = (0..4000).map(|_| bank.draw(&mut rng)).collect();
            assert!(drawn.iter().flatten().all(|b| balls.contains(b)));
            drawn.iter().filter(|b| b.is_some()).count() as f64 / 4000.0
        };
        assert_eq!(share(0.0), 0.0);
        assert_eq!(share(1.0), 1.0);
        assert!((share(0.5) - 0.5).abs() < 0.03, "{}", share(0.5));
    }

    #[test]
    fn a_bank_file_round_trips_and_bad_ones_say_where() {
        let balls = vec![ball(6.0), ball(5.5)];
        let text = BallBank::to_json(&balls, serde_json::json!({"seed": 1})).to_string();
        assert_eq!(BallBank::parse(&text).unwrap(), balls);
        let bad = |edit: &dyn Fn(&mut serde_json::Value)| {
            let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
            edit(&mut v);
            BallBank::parse(&v.to_string()).unwrap_err()
        };
        assert!(bad(&|v| v["format"] = "x".into()).contains("expected"));
        assert!(bad(&|v| v["balls"] = serde_json::json!([])).contains("empty"));
        let short = bad(&|v| v["balls"][1] = serde_json::json!([1.0, 2.0]));
        assert!(short.contains("balls[1]"), "{short}");
        let away = bad(&|v| v["balls"][0][3] = (-6.0).into());
        assert!(away.contains("balls[0]") && away.contains("away"), "{away}");
        assert!(BallBank::parse("{")
            .unwrap_err()
            .contains("not a ball bank"));
    }
}
