//! The self-play rally environment (paper §IV-C).

use nalgebra::Vector3;
use sim::arena::{self, Side};
use sim::model::Model;
use sim::predict::BounceModel;
use sim::rng::Rng;

use crate::controller::apply_grip_floor;
use crate::observation::{ObsBlock, Observer};
use crate::planner::Plan;

use super::*;

type V3 = Vector3<f64>;

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
    /// The rules the task terms judge a return by (training: `task_rules`).
    pub task_rules: TaskRules,
    /// Where the position term aims the blade (training: `position_target`).
    pub position_target: PositionTarget,
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
            task_rules: TaskRules::Ours,
            position_target: PositionTarget::Strike,
            grip_floor: 0.0,
            seats: [seat(Side::A), seat(Side::B)],
            bounce,
            crossings_seen: 0,
        })
    }

    /// Makes both sides' commands as `replan` says (training: `replan`).
    pub fn set_replan(&mut self, replan: crate::observation::Replan) {
        for seat in &mut self.seats {
            seat.observer.set_replan(replan);
        }
    }

    /// How both sides' commands are made.
    pub fn replan(&self) -> crate::observation::Replan {
        self.seats[0].observer.replan()
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
            let (mut terms, _) = seat.stroke.step(
                robot,
                &ball,
                contact,
                plan.as_ref(),
                &self.bounce,
                StrokeRules {
                    task: self.task_rules,
                    aim: self.position_target,
                },
            );
            if plan.is_none() && !seat.stroke.in_progress() {
                let d = (robot.paddle.pose.pos - seat.ready).norm();
                terms.ready = ready_term(d);
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
