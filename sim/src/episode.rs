//! The paper's two environments as state machines over the physics (docs/design.md §4, paper §V-A):
//!
//! - [`SingleServe`]: a MyoChallenge serve (P0/P1/P2) to robot A; 300 control steps at 100 Hz, ending
//!   early on the rules — a legal return (success), or the first failure. Optionally after a lead-in
//!   (ours): the robot's own return flying away from it until the other side would strike it.
//! - [`Rally`]: the dual arena; the paper's heuristic serve from the server's hitting plane, then
//!   play until the first failure, or CAPPED after `rally.cap` legal returns or `rally.max_seconds`.
//!   Every incoming ball's crossing of its receiver's hitting plane is recorded for the drift
//!   statistics (docs/design.md §7).
//!
//! Whoever drives the robots sets their controls before each [`SingleServe::step`] / [`Rally::step`].
//! No I/O; randomness only from the caller's [`Rng`].

use std::sync::Arc;

use nalgebra::Vector3;

use crate::arena::{self, Preset, Side};
use crate::ball::BallState;
use crate::config::{ArenaConfig, RallyParams};
use crate::dual::DualArena;
use crate::events::{ContactEvent, ContactKind};
use crate::model::Model;
use crate::predict::{self, BounceModel};
use crate::rng::Rng;
use crate::robot::{GripEvent, Robot};
use crate::rules::{Call, Failure, Referee};
use crate::serve::{self, Serve, ServeKind};
use crate::world::BallWorld;

type V3 = Vector3<f64>;

/// What one control step produced.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StepReport {
    /// Contacts that began.
    pub events: Vec<ContactEvent>,
    /// The referee's calls.
    pub calls: Vec<Call>,
    /// Grip changes, by side.
    pub grip: Vec<(Side, GripEvent)>,
    /// Whether the episode or rally is over.
    pub done: bool,
}

/// Feeds a physics step's events, the ball's height and grip changes to the referee.
fn judge(
    referee: &mut Referee,
    events: &[ContactEvent],
    t: f64,
    z: f64,
    grip: &[(Side, GripEvent)],
    calls: &mut Vec<Call>,
) {
    for e in events {
        calls.extend(referee.on_contact(e));
    }
    calls.extend(referee.on_ball_height(t, z));
    for (side, g) in grip {
        if *g == GripEvent::Dropped {
            calls.extend(referee.report(*side, Failure::DroppedPaddle, t));
        }
    }
}

/// The start pose of a robot: the model's "ready" keyframe, else its first keyframe (MyoSuite's
/// robot has one, "default"), else none (the reference configuration).
pub fn ready_pose(model: &Model) -> Option<Vec<f64>> {
    model
        .keyframes
        .iter()
        .find(|k| k.name == "ready")
        .or(model.keyframes.first())
        .map(|k| k.qpos.clone())
}

/// MyoChallenge's single-serve episode for robot A.
#[derive(Debug, Clone)]
pub struct SingleServe {
    /// The robot (side A).
    pub robot: Robot,
    /// The ball world.
    pub world: BallWorld,
    /// Judges the serve and the return.
    pub referee: Referee,
    /// The serve of this episode.
    pub serve: Serve,
    /// Control steps taken.
    pub steps: usize,
    /// Episode length in control steps.
    pub max_steps: usize,
    /// Whether the robot touched the ball.
    pub hit: bool,
    /// Whether its return was legal.
    pub success: bool,
    /// Whether the episode is over.
    pub done: bool,
    /// The ball's sliding friction this episode (P2's draw, else the scene's 1). Drawn and kept as
    /// MyoChallenge does, it changes none of our contact laws: in MuJoCo's scene, over P2's range,
    /// it moves a table bounce's rebound by 0.1–0.3% and its horizontal speed by 3e-5
    /// (`tools/mujoco_ball_friction.py`; docs/simulator.md), below what our laws, fitted to that
    /// scene, resolve.
    pub ball_friction: f64,
    /// The contact laws before any per-episode draw.
    preset: Preset,
    /// What P2 draws besides the ball (the arena configuration's `[p2]`).
    p2: Option<crate::config::P2Draws>,
    /// In the lead-in (see [`SingleServe::start_lead_in`]).
    lead_in: bool,
    /// The control step by which the lead-in ends at the latest.
    lead_in_until: usize,
    /// The control step at which the serve came into play (0 without a lead-in).
    serve_step: usize,
}

/// The longest lead-in, in control steps (a return from A's hitting plane reaches B's in about
/// 0.3–0.6 s).
pub const LEAD_IN_STEPS: usize = 150;

impl SingleServe {
    /// An episode environment (call [`SingleServe::reset`] before stepping).
    pub fn new(
        model: Arc<Model>,
        config: &ArenaConfig,
        preset: Preset,
    ) -> Result<SingleServe, String> {
        let robot = Robot::new(model, &config.grip, Side::A)?;
        let ball = BallState::new(V3::new(0.0, 0.0, 2.0), V3::zeros());
        Ok(SingleServe {
            robot,
            world: BallWorld::new(preset, ball),
            referee: Referee::new(Side::B),
            serve: serve::generate(
                ServeKind::P0,
                &mut Rng::seeded(0),
                &BounceModel::for_table(&preset.table),
            ),
            steps: 0,
            max_steps: arena::EPISODE_STEPS,
            hit: false,
            success: false,
            done: false,
            ball_friction: 1.0,
            preset,
            p2: config.p2.clone(),
            lead_in: false,
            lead_in_until: LEAD_IN_STEPS,
            serve_step: 0,
        })
    }

    /// A new episode: the robot at `qpos` (default: "ready"), a serve of `kind` drawn from `rng`;
    /// a P2 serve of an arena whose configuration has `[p2]` also draws, after the ball, the
    /// paddle's mass and the ball's friction (MyoChallenge's P2).
    pub fn reset(&mut self, kind: ServeKind, rng: &mut Rng, qpos: Option<&[f64]>) {
        let model = BounceModel::for_table(&self.preset.table);
        let serve = serve::generate(kind, rng, &model);
        let (mass, friction) = match (&self.p2, kind) {
            (Some(p2), ServeKind::P2) => {
                let [m0, m1] = p2.paddle_mass;
                let [f0, f1] = p2.ball_friction;
                (Some(rng.uniform(m0, m1)), rng.uniform(f0, f1))
            }
            _ => (None, 1.0),
        };
        self.start(serve, qpos, mass, friction);
    }

    /// A new episode with a given ball: the robot at `qpos` (default: "ready"), `serve` in play,
    /// the model's own paddle and the scene's friction.
    pub fn reset_with(&mut self, serve: Serve, qpos: Option<&[f64]>) {
        self.start(serve, qpos, None, 1.0);
    }

    fn start(&mut self, serve: Serve, qpos: Option<&[f64]>, mass: Option<f64>, friction: f64) {
        self.robot.set_paddle_mass(mass);
        self.ball_friction = friction;
        let ready = ready_pose(self.robot.held_model());
        self.robot.reset(qpos.or(ready.as_deref()));
        self.serve = serve;
        self.world = BallWorld::new(self.preset, self.serve.ball);
        self.referee = Referee::new(self.serve.server);
        self.steps = 0;
        self.hit = false;
        self.success = false;
        self.done = false;
        self.lead_in = false;
        self.serve_step = 0;
        self.max_steps = arena::EPISODE_STEPS;
    }

    /// Puts a lead-in before the serve of the episode just reset (ours, for rallies): `away`, a ball
    /// struck by the robot towards B, is in play first, unjudged, as a return of its own is between
    /// two strokes of a rally; once it reaches B's hitting plane (or falls below the table, or after
    /// `steps` control steps, at most [`LEAD_IN_STEPS`]), the episode's serve comes into play from
    /// its start and the episode goes on as any other for its full length, the robot as the lead-in
    /// left it. Nothing the robot does in the lead-in counts as a hit.
    pub fn start_lead_in(&mut self, away: BallState, steps: usize) {
        debug_assert!(self.steps == 0 && !self.done, "a lead-in starts an episode");
        if steps == 0 {
            return;
        }
        self.world = BallWorld::new(self.preset, away);
        self.lead_in = true;
        self.lead_in_until = steps.min(LEAD_IN_STEPS);
        self.max_steps = self.lead_in_until + arena::EPISODE_STEPS;
    }

    /// Brings `serve` to the robot after its stroke (ours, for rallies): the ball in play, the
    /// robot's return, flies on unjudged as a lead-in's does (see [`SingleServe::start_lead_in`]),
    /// and once it reaches B's hitting plane (or falls below the table, or no longer flies away,
    /// or after [`LEAD_IN_STEPS`]) `serve` comes into play from its start, the robot as its own
    /// stroke left it, for a full episode's time. The referee, `hit` and `success` start over
    /// with the new ball, the elapsed share (see [`SingleServe::elapsed_share`]) over from here;
    /// the paddle's mass and the ball's friction stay the episode's.
    pub fn follow_on(&mut self, serve: Serve) {
        debug_assert!(
            !self.done && !self.lead_in,
            "a follow-on comes after a stroke"
        );
        self.referee = Referee::new(serve.server);
        self.serve = serve;
        self.hit = false;
        self.success = false;
        self.lead_in = true;
        self.serve_step = self.steps;
        self.lead_in_until = self.steps + LEAD_IN_STEPS;
        self.max_steps = self.lead_in_until + arena::EPISODE_STEPS;
    }

    /// Draws a lead-in's ball from `rng` (a stroke ball struck by A: [`ServeKind::Stroke`]) and
    /// starts it (see [`SingleServe::start_lead_in`]); when `cut`, the lead-in ends after a share of
    /// that ball's flight to B's hitting plane drawn next from `rng`, uniformly from (0, 1].
    pub fn draw_lead_in(&mut self, rng: &mut Rng, cut: bool) {
        let bounce = BounceModel::for_table(&self.preset.table);
        let away = serve::generate(ServeKind::Stroke { server: Side::A }, rng, &bounce).ball;
        let steps = if cut {
            let flight =
                predict::plane_crossing(&away.pos, &away.vel, Side::B.strike_plane_x(), &bounce)
                    .map_or(LEAD_IN_STEPS as f64, |c| c.t / arena::CONTROL_DT);
            (rng.unit() * flight).ceil().max(1.0) as usize
        } else {
            LEAD_IN_STEPS
        };
        self.start_lead_in(away, steps);
    }

    /// Whether the ball in play is still the lead-in's.
    pub fn in_lead_in(&self) -> bool {
        self.lead_in
    }

    /// One lead-in step: physics and grip only; then, once the lead-in's ball is away (at B's
    /// hitting plane, below the table, or no longer flying away from the robot) or its time is up,
    /// the serve, so that a player's next look at the ball finds the serve coming.
    fn lead_in_step(&mut self, report: &mut StepReport) {
        self.substeps(false, report);
        self.steps += 1;
        let ball = &self.world.ball;
        if ball.pos.x <= Side::B.strike_plane_x()
            || ball.pos.z < arena::TABLE_TOP_Z - 0.3
            || Side::A.sign() * ball.vel.x >= 0.0
            || self.steps >= self.lead_in_until
        {
            let time = self.world.time;
            self.world = BallWorld::new(self.preset, self.serve.ball);
            self.world.time = time;
            self.lead_in = false;
            self.serve_step = self.steps;
            self.max_steps = self.steps + arena::EPISODE_STEPS;
        }
        self.done = self.referee.end().is_some();
        report.done = self.done;
    }

    /// The physics steps of one control step; the referee judges them when `judged` (in a lead-in
    /// it hears only of a dropped paddle).
    fn substeps(&mut self, judged: bool, report: &mut StepReport) {
        for _ in 0..arena::SUBSTEPS {
            let grip: Vec<(Side, GripEvent)> = self
                .robot
                .physics_step()
                .map(|g| (Side::A, g))
                .into_iter()
                .collect();
            let mut events = Vec::new();
            self.world
                .physics_step(&[self.robot.ball_paddle()], &mut events);
            for (_, point, impulse) in self.world.paddle_impulses.clone() {
                self.robot.receive_ball_impulse(&point, &impulse);
            }
            if judged {
                judge(
                    &mut self.referee,
                    &events,
                    self.world.time,
                    self.world.ball.pos.z,
                    &grip,
                    &mut report.calls,
                );
            } else {
                judge(
                    &mut self.referee,
                    &[],
                    self.world.time,
                    f64::INFINITY,
                    &grip,
                    &mut report.calls,
                );
            }
            report.events.extend(events);
            report.grip.extend(grip);
        }
    }

    /// One control step with the controls the caller set on `robot.state.ctrl`.
    pub fn step(&mut self) -> StepReport {
        let mut report = StepReport::default();
        if self.done {
            report.done = true;
            return report;
        }
        if self.lead_in {
            self.lead_in_step(&mut report);
            return report;
        }
        self.substeps(true, &mut report);
        self.steps += 1;
        for call in &report.calls {
            match call {
                Call::Hit { side: Side::A, .. } => self.hit = true,
                Call::LegalReturn {
                    hitter: Side::A, ..
                } => self.success = true,
                _ => {}
            }
        }
        // MyoChallenge's hit rate counts any paddle contact, legal or not.
        if report
            .events
            .iter()
            .any(|e| e.kind == ContactKind::Paddle { owner: Side::A })
        {
            self.hit = true;
        }
        self.done = self.success || self.referee.end().is_some() || self.steps >= self.max_steps;
        report.done = self.done;
        report
    }

    /// The share of the serve's time limit gone: control steps since the serve came into play over
    /// the episode's length (in a lead-in, over the lead-in's and the episode's).
    pub fn elapsed_share(&self) -> f64 {
        (self.steps - self.serve_step) as f64 / (self.max_steps - self.serve_step).max(1) as f64
    }

    /// The policy produced NaN or infinite actions: the episode ends with INVALID_ACTION.
    pub fn invalid_action(&mut self) {
        self.referee
            .report(Side::A, Failure::InvalidAction, self.world.time);
        self.done = true;
    }
}

/// Where an incoming ball met (or would have met) its receiver's hitting plane.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Crossing {
    /// The side receiving the ball.
    pub receiver: Side,
    /// 0 for the serve, then 1, 2, … for each return.
    pub exchange: u32,
    /// Receiver-frame lateral position, m (docs/design.md §3).
    pub y_r: f64,
    /// Height, m.
    pub z: f64,
    /// Inside the serve box.
    pub in_box: bool,
    /// Extrapolated from the flight before the receiver hit the ball early (not measured).
    pub extrapolated: bool,
    /// Time, s.
    pub t: f64,
}

/// The incoming ball being watched for its plane crossing.
#[derive(Debug, Clone, Copy)]
struct Watch {
    receiver: Side,
    exchange: u32,
}

/// A dual-robot rally.
#[derive(Debug, Clone)]
pub struct Rally {
    /// Robots and ball.
    pub arena: DualArena,
    /// Judges the rally.
    pub referee: Referee,
    /// Cap and time limit.
    pub params: RallyParams,
    /// Control steps taken.
    pub steps: usize,
    /// Whether the rally is over.
    pub done: bool,
    /// Every incoming ball's crossing of its receiver's hitting plane, in order.
    pub crossings: Vec<Crossing>,
    watch: Option<Watch>,
    bounce: BounceModel,
}

impl Rally {
    /// A rally environment (call [`Rally::reset`] before stepping).
    pub fn new(model: Arc<Model>, config: &ArenaConfig, preset: Preset) -> Result<Rally, String> {
        let ball = BallState::new(V3::new(0.0, 0.0, 2.0), V3::zeros());
        Ok(Rally {
            arena: DualArena::new(model, config, preset, ball)?,
            referee: Referee::new(Side::A),
            params: config.rally.clone(),
            steps: 0,
            done: false,
            crossings: Vec::new(),
            watch: None,
            bounce: BounceModel::for_table(&preset.table),
        })
    }

    /// A new rally: both robots at `qpos` (default "ready"), `server` serves the paper's rally serve.
    pub fn reset(&mut self, server: Side, rng: &mut Rng, qpos: Option<&[f64]>) -> Serve {
        let ready = ready_pose(self.arena.robots[0].held_model());
        for r in self.arena.robots.iter_mut() {
            r.reset(qpos.or(ready.as_deref()));
        }
        let serve = serve::generate(ServeKind::Rally { server }, rng, &self.bounce);
        self.arena.world = BallWorld::new(self.arena.world.preset, serve.ball);
        self.referee = Referee::new(server);
        self.steps = 0;
        self.done = false;
        self.crossings.clear();
        self.watch = Some(Watch {
            receiver: server.other(),
            exchange: 0,
        });
        serve
    }

    /// One control step with the controls the caller set on both robots.
    pub fn step(&mut self) -> StepReport {
        let mut report = StepReport::default();
        if self.done {
            report.done = true;
            return report;
        }
        for _ in 0..arena::SUBSTEPS {
            let before = self.arena.world.ball;
            let mut events = Vec::new();
            let grip_ab = self.arena.physics_step(&mut events);
            let grip: Vec<(Side, GripEvent)> = [Side::A, Side::B]
                .into_iter()
                .zip(grip_ab)
                .filter_map(|(s, g)| g.map(|g| (s, g)))
                .collect();
            self.watch_crossing(&before, &events);
            let world = &self.arena.world;
            let mut calls = Vec::new();
            judge(
                &mut self.referee,
                &events,
                world.time,
                world.ball.pos.z,
                &grip,
                &mut calls,
            );
            for c in &calls {
                if let Call::Hit { side, .. } = c {
                    // The return is incoming for the other side: watch its crossing.
                    self.watch = Some(Watch {
                        receiver: side.other(),
                        exchange: self.referee.rally_length() + 1,
                    });
                }
            }
            report.calls.extend(calls);
            report.events.extend(events);
            report.grip.extend(grip);
            if self.referee.end().is_some() {
                break;
            }
        }
        self.steps += 1;
        let t = self.arena.world.time;
        if self.referee.end().is_none()
            && (self.referee.rally_length() >= self.params.cap || t >= self.params.max_seconds)
        {
            report.calls.extend(self.referee.cap(t));
        }
        self.done = self.referee.end().is_some();
        report.done = self.done;
        report
    }

    /// A side's policy produced NaN or infinite actions: that side loses the rally (INVALID_ACTION).
    pub fn invalid_action(&mut self, side: Side) {
        self.referee
            .report(side, Failure::InvalidAction, self.arena.world.time);
        self.done = true;
    }

    /// Records the watched ball's crossing of its receiver's plane in this physics step; if the
    /// receiver hit it first, extrapolates the uninterrupted flight from the state before the hit.
    fn watch_crossing(&mut self, before: &BallState, events: &[ContactEvent]) {
        let Some(w) = self.watch else { return };
        let plane = w.receiver.strike_plane_x();
        let after = self.arena.world.ball;
        let hit_early = events
            .iter()
            .any(|e| e.kind == ContactKind::Paddle { owner: w.receiver });
        let crossed =
            (before.pos.x - plane) * (after.pos.x - plane) <= 0.0 && before.pos.x != after.pos.x;
        let crossing = if crossed && !hit_early {
            let f = (plane - before.pos.x) / (after.pos.x - before.pos.x);
            let p = before.pos + (after.pos - before.pos) * f;
            Some((
                p,
                self.arena.world.time - arena::TIMESTEP * (1.0 - f),
                false,
            ))
        } else if hit_early {
            predict::plane_crossing(&before.pos, &before.vel, plane, &self.bounce)
                .map(|c| (c.pos, self.arena.world.time - arena::TIMESTEP + c.t, true))
        } else {
            None
        };
        if crossed || hit_early {
            self.watch = None;
        }
        if let Some((p, t, extrapolated)) = crossing {
            let (y_r, z) = w.receiver.receiver_frame(&p);
            self.crossings.push(Crossing {
                receiver: w.receiver,
                exchange: w.exchange,
                y_r,
                z,
                in_box: arena::in_serve_box(y_r, z),
                extrapolated,
                t,
            });
        }
    }
}
