//! The single-serve environment and its episode ends.

use serde::{Deserialize, Serialize};
use sim::arena::{self, Side};
use sim::model::Model;
use sim::predict::BounceModel;
use sim::rng::Rng;

use crate::controller::apply_grip_floor;
use crate::observation::{ObsBlock, Observer};

use super::*;

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

/// How long a training lead-in lasts (see [`Env::lead_in`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LeadInLength {
    /// Until its ball reaches the other robot's hitting plane (as in a rally; `rally eval
    /// --lead-in`).
    #[default]
    Full,
    /// Cut after a share of that flight drawn uniformly from (0, 1]: short lead-ins, which leave the
    /// robot near its start, beside long ones.
    Spread,
}

/// The official code's training noise: Gaussian, σ on the policy's actions (in [−1, 1], clipped
/// after) and σ on K-MAC's activation targets (before its clamp), from streams seeded per episode.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TrainingNoise {
    /// σ on every action entry.
    pub action: f64,
    /// σ on every muscle's activation target (K-MAC only).
    pub activation: f64,
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

pub(crate) fn paddle_contact(report: &sim::episode::StepReport, side: Side) -> bool {
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
    /// The rules the task terms judge a return by (training: `task_rules`).
    pub task_rules: TaskRules,
    /// Where the position term aims the blade (training: `position_target`).
    pub position_target: PositionTarget,
    /// Serve distribution.
    pub kind: sim::serve::ServeKind,
    /// When an episode ends.
    pub end: EpisodeEnd,
    /// Least control of the grip muscles (see [`apply_grip_floor`]).
    pub grip_floor: f64,
    /// Balls recorded from rallies, served instead of `kind` in a fraction of episodes.
    pub bank: Option<BallBank>,
    /// Training noise (the official code's): σ on the actions, σ on K-MAC's activation targets; 0:
    /// none (evaluation).
    pub noise: TrainingNoise,
    /// Share of episodes, in [0, 1], that begin with a lead-in (ours, for rallies; see
    /// [`sim::episode::SingleServe::start_lead_in`]): the robot's own return, a stroke ball struck by
    /// A, flies away before the serve comes, and the `ready` term pays for the paddle staying where
    /// it started meanwhile. 0: none (evaluation, and the default).
    pub lead_in: f64,
    /// How long a lead-in lasts.
    pub lead_in_length: LeadInLength,
    /// Share of legal returns, in [0, 1], that a next serve follows (ours, for rallies; training's
    /// episode end only): when a stroke is judged ([`EpisodeEnd::Training`]) a legal return and
    /// the ball is still in play, the episode goes on instead of ending — the return flies away
    /// unjudged, the `ready` term paid meanwhile, and a next serve from the same distribution
    /// comes to the robot as its stroke left it (see [`sim::episode::SingleServe::follow_on`]), as
    /// a rally brings the next ball only after a legal return. 0: none (the default).
    pub follow_on: f64,
    /// The episode's serve stream after the reset's draws: the follow-ons' serves.
    serve_rng: Rng,
    /// Returns judged legal in this episode before its current ball.
    returns: u32,
    noise_rng: Rng,
    /// The paddle's position at the episode's start: the `ready` term's target.
    ready: nalgebra::Vector3<f64>,
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
            task_rules: TaskRules::Ours,
            position_target: PositionTarget::Strike,
            kind,
            end: EpisodeEnd::Rules,
            grip_floor: 0.0,
            bank: None,
            noise: TrainingNoise::default(),
            lead_in: 0.0,
            lead_in_length: LeadInLength::Full,
            follow_on: 0.0,
            serve_rng: Rng::seeded(0),
            returns: 0,
            noise_rng: Rng::seeded(0),
            ready: nalgebra::Vector3::zeros(),
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

    /// Entries of [`Env::privileged_into`].
    pub fn privileged_dim(&self) -> usize {
        self.observer.muscles().len() + 3
    }

    /// What the official code's critic sees beyond the observation (`ppo.critic = "privileged"`),
    /// appended to `out`: the episode's elapsed share of its time limit, every observed muscle's
    /// velocity over its length range, the paddle's mass (kg) and the ball's friction.
    pub fn privileged_into(&self, out: &mut Vec<f64>) {
        let ep = &self.episode;
        out.push(ep.elapsed_share());
        let model = ep.robot.held_model();
        out.extend(self.observer.muscles().iter().map(|&a| {
            let lr = model.actuators[a].lengthrange;
            ep.robot.data.actuator_velocity[a] / (lr[1] - lr[0]).max(1e-9)
        }));
        out.push(ep.robot.paddle_mass());
        out.push(ep.ball_friction);
    }

    /// A new episode from `seed`; returns the first observation.
    pub fn reset(&mut self, seed: u64) -> Vec<f64> {
        let (serve_seed, planner_seed) = crate::seeds::episode_seeds(seed, 0);
        let mut rng = Rng::seeded(serve_seed);
        match self.bank.as_ref().and_then(|b| b.draw(&mut rng)) {
            Some(ball) => self.episode.reset_with(banked_serve(ball), None),
            None => self.episode.reset(self.kind, &mut rng, None),
        }
        // Drawn after the serve, so that an episode without a lead-in is served as before.
        if self.lead_in > 0.0 && rng.unit() < self.lead_in {
            let cut = self.lead_in_length == LeadInLength::Spread;
            self.episode.draw_lead_in(&mut rng, cut);
        }
        self.serve_rng = rng;
        self.returns = 0;
        self.ready = self.episode.robot.paddle.pose.pos;
        self.observer.reset(planner_seed);
        if self.noise.action > 0.0 || self.noise.activation > 0.0 {
            // Streams of their own, so that the serve and the planner draw as without noise.
            let noise_seed = crate::seeds::mix64(planner_seed.wrapping_add(1));
            self.noise_rng = Rng::seeded(noise_seed);
            self.mapper
                .set_activation_noise(self.noise.activation, crate::seeds::mix64(noise_seed));
        }
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

    /// Returns judged legal in this episode so far: its ball's (see [`Env::success`]) and, with
    /// follow-ons, the earlier balls'.
    pub fn returns(&self) -> u32 {
        self.returns + self.success() as u32
    }

    /// The next serve of a follow-on, drawn from the episode's serve stream as a reset draws its
    /// first (the bank's share from the bank, else `kind`; a P2 serve's paddle and friction stay
    /// the episode's).
    fn next_serve(&mut self) -> sim::serve::Serve {
        let rng = &mut self.serve_rng;
        match self.bank.as_ref().and_then(|b| b.draw(rng)) {
            Some(ball) => banked_serve(ball),
            None => sim::serve::generate(self.kind, rng, &self.bounce),
        }
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
        let noisy: Vec<f64>;
        let action = if self.noise.action > 0.0 {
            let (sigma, rng) = (self.noise.action, &mut self.noise_rng);
            noisy = action
                .iter()
                .map(|a| (a + sigma * rng.normal()).clamp(-1.0, 1.0))
                .collect();
            &noisy[..]
        } else {
            action
        };
        self.mapper.controls(
            &model,
            &self.episode.robot.state,
            action,
            arena::CONTROL_DT,
            &mut self.ctrl,
        );
        apply_grip_floor(&self.episode.robot, self.grip_floor, &mut self.ctrl);
        self.episode.robot.state.ctrl.copy_from_slice(&self.ctrl);
        let lead_in = self.episode.in_lead_in();
        let report = self.episode.step();
        let robot = &self.episode.robot;
        let ball = self.episode.world.ball;
        let t = self.episode.world.time;
        // A touch of the lead-in's ball is no stroke.
        let contact = !lead_in && paddle_contact(&report, Side::A);
        let plan = self.observer.command().map(|(p, _)| *p);
        let strike_time = self.observer.command().map(|(_, t_hit)| *t_hit);
        let (terms, judged) = self.stroke.step(
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
        if judged {
            self.predicted_success = self.stroke.legal;
        }
        let mut terms = terms;
        if lead_in {
            let d = (robot.paddle.pose.pos - self.ready).norm();
            terms.ready = ready_term(d);
        }
        let mut done = report.done;
        if self.end == EpisodeEnd::Training {
            let missed =
                !self.episode.hit && strike_time.is_some_and(|t_hit| t > t_hit + MISS_GRACE);
            done |= judged || missed;
            // A legal return whose ball is still in play: with the follow-on's share, a next
            // serve instead of the end (drawn only with follow-ons, so that runs without are
            // served as before).
            if judged
                && self.predicted_success
                && !report.done
                && self.follow_on > 0.0
                && self.serve_rng.unit() < self.follow_on
            {
                self.returns += 1;
                let serve = self.next_serve();
                self.episode.follow_on(serve);
                self.observer.clear_command();
                self.stroke = StrokeReward::default();
                self.predicted_success = false;
                done = false;
            }
        }
        let robot = &self.episode.robot;
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

/// A ball from the bank as the serve of robot B to robot A.
fn banked_serve(ball: sim::BallState) -> sim::serve::Serve {
    sim::serve::Serve {
        ball,
        server: Side::B,
        receiver: Side::A,
        predicted_crossing: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ppo::trainer::envs::{make_env, TrainingEnv};
    use crate::ppo::{Method, TrainConfig};

    fn env(follow_on: f64) -> Box<Env> {
        let m = std::sync::Arc::new(sim::config::default_model());
        let config = TrainConfig {
            follow_on,
            ..TrainConfig::default()
        };
        let controller = config.controller(Method::Kmac, &m);
        let arena = sim::config::ArenaConfig::default();
        match make_env(&m, &arena, &controller, &config, None).unwrap() {
            (TrainingEnv::Single(env), ..) => env,
            _ => unreachable!("the default environment is the single serve"),
        }
    }

    fn zero(e: &Env) -> Vec<f64> {
        vec![0.0; e.action_dim()]
    }

    /// Puts `e` one control step before its stroke is judged: the robot touched the ball a moment
    /// ago and it flies back over A's half towards B at `vz` upwards (1 m/s: over the net and onto
    /// B's half by our rules; −1: into A's own half, a fault).
    fn struck(e: &mut Env, vz: f64) {
        let ball = &mut e.episode.world.ball;
        ball.pos = nalgebra::Vector3::new(0.5, arena::TABLE_CENTER_Y, arena::TABLE_TOP_Z + 0.4);
        ball.vel = nalgebra::Vector3::new(-3.5, 0.0, vz);
        ball.spin = nalgebra::Vector3::zeros();
        e.episode.hit = true;
        e.stroke.since_contact = Some(reward::TASK_DELAY_STEPS - 1);
    }

    /// Steps `e` through a follow-on's lead-in, checking what it pays; returns its length.
    fn lead_in(e: &mut Env) -> usize {
        let mut away = 0;
        while e.episode.in_lead_in() {
            let tr = e.step(&zero(e));
            away += 1;
            assert!(!tr.done && !tr.hit, "step {away}");
            assert!(tr.terms.ready > 0.0, "{:?}", tr.terms);
            assert_eq!((tr.terms.hit, tr.terms.landing), (0.0, 0.0));
        }
        away
    }

    #[test]
    fn a_legal_return_goes_on_to_a_next_serve_after_the_return_flew_away() {
        for seed in 0..3 {
            // Without follow-ons the judged stroke ends a training episode.
            let mut plain = env(0.0);
            plain.reset(seed);
            struck(&mut plain, 1.0);
            let tr = plain.step(&zero(&plain));
            assert!(tr.done && tr.hit && tr.success && plain.returns() == 1);

            let mut e = env(1.0);
            e.reset(seed);
            let first = e.episode.serve;
            struck(&mut e, 1.0);
            let tr = e.step(&zero(&e));
            assert!(tr.terms.landing > 0.0, "the stroke is paid: {:?}", tr.terms);
            assert!(!tr.done && !tr.hit && !tr.success, "seed {seed}: {tr:?}");
            assert!(e.episode.in_lead_in() && e.observer.command().is_none());
            assert_eq!(e.returns(), 1, "the legal return is counted");
            assert_ne!(e.episode.serve, first, "a next serve is drawn");
            let next = e.episode.serve;
            let away = lead_in(&mut e);
            assert!(away > 5, "seed {seed}: the return flew {away} steps");
            assert_eq!(e.episode.world.ball.pos, next.ball.pos);
            assert_eq!(
                e.episode.elapsed_share(),
                0.0,
                "the next serve's time starts"
            );
            // The next ball is planned for and its stroke paid as the first's: a second legal
            // return follows on again.
            let tr = e.step(&zero(&e));
            assert!(e.observer.command().is_some() && tr.terms.ready == 0.0);
            struck(&mut e, 1.0);
            let tr = e.step(&zero(&e));
            assert!(tr.terms.landing > 0.0 && !tr.done, "{:?}", tr.terms);
            assert_eq!(e.returns(), 2);
            assert_ne!(e.episode.serve, next);
            lead_in(&mut e);
            // Unreturned, the third ends the episode with the earlier returns still counted.
            let mut tr = e.step(&zero(&e));
            while !tr.done {
                tr = e.step(&zero(&e));
            }
            assert!(!tr.hit && !tr.success && e.returns() == 2);
        }
    }

    #[test]
    fn a_fault_ends_the_episode_as_without_follow_ons() {
        let mut e = env(1.0);
        e.reset(4);
        struck(&mut e, -1.0);
        let tr = e.step(&zero(&e));
        assert!(
            tr.terms.fault > 0.0 && tr.terms.landing == 0.0,
            "{:?}",
            tr.terms
        );
        assert!(tr.done && !tr.success && e.returns() == 0);
        assert!(!e.episode.in_lead_in());
    }

    #[test]
    fn follow_ons_drawn_and_declined_change_nothing_and_the_same_seed_draws_the_same_next_serve() {
        // A share so small that it draws and never follows on: every step as without the setting.
        let (mut plain, mut drawn) = (env(0.0), env(1e-300));
        for seed in 0..3 {
            assert_eq!(plain.reset(seed), drawn.reset(seed));
            struck(&mut plain, 1.0);
            struck(&mut drawn, 1.0);
            loop {
                let (a, b) = (plain.step(&zero(&plain)), drawn.step(&zero(&drawn)));
                assert_eq!(a, b, "seed {seed}");
                if a.done {
                    break;
                }
            }
        }
        let serve = |seed| {
            let mut e = env(1.0);
            e.reset(seed);
            struck(&mut e, 1.0);
            e.step(&zero(&e));
            e.episode.serve
        };
        assert_eq!(serve(7), serve(7));
        assert_ne!(serve(7), serve(8));
    }
}
