//! The reward: its named terms and weights, and the stroke reward of one incoming ball.

use nalgebra::{UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use sim::arena::{self, Side};
use sim::ball::BallState;
use sim::predict::BounceModel;
use sim::robot::Robot;

use crate::planner::Plan;

type V3 = Vector3<f64>;

/// The `ready` term at a paddle `distance` (m) from where it started: `exp(−4·d)`.
pub fn ready_term(distance: f64) -> f64 {
    sim::math::exp(-4.0 * distance)
}

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
    /// Dual rally and single-serve lead-ins only (dense): [`ready_term`] of the paddle's distance
    /// from where it was at the rally's (episode's) start, while no ball is coming and no stroke is
    /// being judged (in a single serve: during its lead-in) — the paper's "maintain stability after
    /// striking", so that the robot is ready for the next ball (ours).
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
    /// Every term's name, in [`RewardTerms::weighted`]'s order (the `[reward]` keys of a training
    /// configuration).
    pub const NAMES: [&'static str; 13] = [
        "grasp",
        "position",
        "orientation",
        "velocity",
        "ball_out",
        "hit",
        "landing",
        "centre",
        "in_box",
        "fault",
        "ready",
        "dual",
        "effort",
    ];

    /// Each term times its weight, in [`RewardTerms::NAMES`]'s order: what each term added to the
    /// step's reward ([`RewardTerms::total`] is their sum, added in this order).
    pub fn weighted(&self, w: &RewardWeights) -> [f64; 13] {
        let w = &w.0;
        [
            w.grasp * self.grasp,
            w.position * self.position,
            w.orientation * self.orientation,
            w.velocity * self.velocity,
            w.ball_out * self.ball_out,
            w.hit * self.hit,
            w.landing * self.landing,
            w.centre * self.centre,
            w.in_box * self.in_box,
            w.fault * self.fault,
            w.ready * self.ready,
            w.dual * self.dual,
            w.effort * self.effort,
        ]
    }

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

/// The paper's ablations of Diff-Muscle (§V-C), as settings of a run (`[ablation]` of a training
/// configuration; recorded in its checkpoints): what of the planner's command the policy observes
/// and is rewarded for tracking, and whether the sparse task reward is paid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Ablation {
    /// `full` (Diff-Muscle), `position` (Position-only: the strike position observed, only the
    /// position term of the command reward paid) or `none` (Without-Planner: no command observed,
    /// no command reward).
    pub command: crate::observation::CommandVariant,
    /// Pay the task terms (hit, landing, centre, in_box, fault; in a rally dual); false:
    /// Without-Task.
    pub task_reward: bool,
}

impl Default for Ablation {
    fn default() -> Self {
        Ablation {
            command: crate::observation::CommandVariant::Full,
            task_reward: true,
        }
    }
}

impl Ablation {
    /// Diff-Muscle itself: nothing removed.
    pub fn is_none(&self) -> bool {
        *self == Ablation::default()
    }

    /// `weights` with the removed terms at zero.
    pub fn weights(&self, weights: RewardWeights) -> RewardWeights {
        use crate::observation::CommandVariant;
        let mut w = weights;
        if self.command != CommandVariant::Full {
            (w.0.orientation, w.0.velocity, w.0.ball_out) = (0.0, 0.0, 0.0);
        }
        if self.command == CommandVariant::None {
            w.0.position = 0.0;
        }
        if !self.task_reward {
            let t = &mut w.0;
            (t.hit, t.landing, t.centre, t.in_box, t.fault, t.dual) =
                (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        }
        w
    }

    /// A short name: `full`, `position`, `none`, with `-notask` without the task reward.
    pub fn name(&self) -> String {
        let task = if self.task_reward { "" } else { "-notask" };
        format!("{}{task}", self.command.name())
    }
}

/// How the task terms judge a return (`task_rules` of a training configuration). Both judge the
/// same prediction of the ball's flight (drag-free, then the table's bounce law); they differ in the
/// thresholds. Evaluation and the training curves' predicted success always use ours.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TaskRules {
    /// Ours, the rules' own: `landing` when the next bounce is on the other half and the ball
    /// clears the net on the way; `fault` for every other return.
    #[default]
    Ours,
    /// The official code's (docs/design.md §11): `landing` when the next bounce lies inside the
    /// other half shrunk by [`OFFICIAL_LANDING_MARGIN`] and the ball crosses the net's plane at least
    /// [`OFFICIAL_NET_CLEARANCE_Z`] high and over the table's width; `fault` only for a return that
    /// crosses that plane lower (the net) or beside the table (wide), so a long ball earns neither.
    Official,
}

/// The official task rules' margins inside the other half, m: from its end line, from the net, from
/// either side line (`x ∈ (−1.34, −0.05)`, `y ∈ (−0.68, 0.76)` on this table).
pub const OFFICIAL_LANDING_MARGIN: (f64, f64, f64) = (0.03, 0.05, 0.04);
/// The height the official task rules ask of a return at the net's plane, m (its net's top, 0.95,
/// plus 0.05; ours is 0.9475).
pub const OFFICIAL_NET_CLEARANCE_Z: f64 = 1.00;

/// The serve box's centre height, m (official code: the `(0, 1.225)` the `centre` term aims at).
pub const SERVE_BOX_CENTRE_Z: f64 = 0.5 * (arena::SERVE_BOX_Z.0 + arena::SERVE_BOX_Z.1);
/// Control steps after the ball leaves the paddle at which the task terms are judged and a training
/// episode ends (official code: 3).
pub const TASK_DELAY_STEPS: usize = 3;
/// A training episode without contact ends this long after the planned strike time, s (official).
pub const MISS_GRACE: f64 = 0.05;

/// Grasp term: 1 while the paddle is at its place in the hand, `exp(−20·d)` once it slips.
pub fn grasp_term(robot: &Robot) -> f64 {
    sim::math::exp(-20.0 * robot.paddle_offset())
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

/// Where the position term wants the blade's centre at the strike time (`position_target` of a
/// training configuration).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PositionTarget {
    /// Ours: at the strike point, the ball's centre (which the blade cannot reach: it meets the
    /// ball one ball radius and half a blade's thickness before).
    #[default]
    Strike,
    /// The official code's: where the blade's centre is when its face first touches the ball
    /// there: the strike point moved back along the planned racket velocity by
    /// [`contact_offset`] (0.04 m on both robots' paddles, the official code's constant).
    Contact,
}

/// How far before the strike point the blade's centre is when its face touches the ball there: the
/// ball's radius plus half the blade's thickness, m.
pub fn contact_offset(shape: &sim::geometry::PaddleShape) -> f64 {
    sim::arena::BALL_RADIUS + shape.blade.half_length
}

/// The point the position term measures the blade's centre against (see [`PositionTarget`]).
pub fn position_target(plan: &Plan, target: PositionTarget, offset: f64) -> V3 {
    match target {
        PositionTarget::Strike => plan.strike_pos,
        PositionTarget::Contact => {
            let v = plan.racket_vel;
            let n = v.norm();
            if n > 1e-9 {
                plan.strike_pos - v * (offset / n)
            } else {
                plan.strike_pos
            }
        }
    }
}

/// Dense pose terms against the plan: `exp(−8·d)` of the blade centre's distance to `target` (see
/// [`position_target`]), `exp(−2·θ)` of the angle between the blade normal (either face) and the
/// planned normal.
pub fn pose_terms(blade: &V3, normal: &V3, target: &V3, plan: &Plan) -> (f64, f64) {
    let u: V3 = plan.racket_quat * V3::z();
    let d = (blade - target).norm();
    let theta = sim::math::acos(normal.dot(&u).abs().min(1.0));
    (sim::math::exp(-8.0 * d), sim::math::exp(-2.0 * theta))
}

/// Sparse velocity term at contact.
pub fn velocity_term(paddle_vel: &V3, plan: &Plan) -> f64 {
    sim::math::exp(-(paddle_vel - plan.racket_vel).norm())
}

/// The task terms of a ball (robot frame) that this robot (side A of its frame) has just returned:
/// predicted landing on the other half, closeness of the crossing of the other plane to the serve
/// box's centre, that crossing in the box, or a predicted fault.
pub fn task_terms(
    ball: &BallState,
    bounce: &BounceModel,
    rules: TaskRules,
    terms: &mut RewardTerms,
) {
    let (lands, fault) = match rules {
        TaskRules::Ours => {
            let legal = predicted_legal(ball, bounce);
            (legal, !legal)
        }
        TaskRules::Official => official_judgement(ball, bounce),
    };
    if fault {
        terms.fault = 1.0;
    }
    if !lands {
        return;
    }
    terms.landing = 1.0;
    let crossing =
        sim::predict::plane_crossing(&ball.pos, &ball.vel, Side::B.strike_plane_x(), bounce);
    if let Some(c) = &crossing {
        let (y_r, z) = Side::B.receiver_frame(&c.pos);
        terms.centre = sim::math::exp(-0.5 * (y_r * y_r + (z - SERVE_BOX_CENTRE_Z).powi(2)).sqrt());
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

/// The official task rules' judgement of a return (robot frame): `(lands, fault)`, see
/// [`TaskRules::Official`]. A ball that never reaches the net's plane is a fault.
pub fn official_judgement(ball: &BallState, bounce: &BounceModel) -> (bool, bool) {
    if ball.vel.x >= -1e-12 || ball.pos.x <= 0.0 {
        return (false, true);
    }
    let t = -ball.pos.x / ball.vel.x;
    let (p, _) = sim::predict::flight(&ball.pos, &ball.vel, t);
    let fault =
        p.z < OFFICIAL_NET_CLEARANCE_Z || p.y < arena::TABLE_Y_MIN || p.y > arena::TABLE_Y_MAX;
    let (end, net, side) = OFFICIAL_LANDING_MARGIN;
    let inside = |b: &V3| {
        b.x > -(arena::TABLE_HALF_LENGTH - end)
            && b.x < -net
            && b.y > arena::TABLE_Y_MIN + side
            && b.y < arena::TABLE_Y_MAX - side
    };
    let lands = !fault
        && sim::predict::next_bounce(&ball.pos, &ball.vel, bounce).is_some_and(|b| inside(&b.pos));
    (lands, fault)
}

/// Blade centre and normal of a robot's paddle (robot frame).
pub fn blade(robot: &Robot) -> (V3, V3) {
    let p = &robot.paddle.pose;
    let rot: UnitQuaternion<f64> = p.rot;
    (p.to_world(&robot.shape.blade.center), rot * V3::z())
}

/// What a training configuration sets of how a stroke is rewarded: the task terms' rules and where
/// the position term aims.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StrokeRules {
    /// `task_rules`.
    pub task: TaskRules,
    /// `position_target`.
    pub aim: PositionTarget,
}

/// The reward of one incoming ball, step by step: dense pose terms against the plan (in full once
/// the ball was touched), the velocity term at contact, and the task terms once, `TASK_DELAY_STEPS`
/// after the ball left the paddle.
#[derive(Debug, Clone, Default)]
pub(crate) struct StrokeReward {
    /// Steps since the last control step with a paddle contact, once there was one.
    pub(crate) since_contact: Option<usize>,
    /// The task terms were paid for this ball.
    pub(crate) judged: bool,
    /// Once judged: whether the return was predicted to land by our rules (whatever rules the reward
    /// judged it by), the training curves' predicted success.
    pub(crate) legal: bool,
}

impl StrokeReward {
    /// The ball was touched and its task terms are still to be paid.
    pub(crate) fn in_progress(&self) -> bool {
        self.since_contact.is_some() && !self.judged
    }
}

impl StrokeReward {
    /// This step's terms for `robot` (robot frame), `contact` whether the paddle touched the ball in
    /// it, `plan` the command. Returns the terms and whether the task terms were paid now.
    pub(crate) fn step(
        &mut self,
        robot: &Robot,
        ball_world: &BallState,
        contact: bool,
        plan: Option<&Plan>,
        bounce: &BounceModel,
        rules: StrokeRules,
    ) -> (RewardTerms, bool) {
        let StrokeRules { task: rules, aim } = rules;
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
            let target = position_target(plan, aim, contact_offset(&robot.shape));
            (terms.position, terms.orientation) = pose_terms(&c, &n, &target, plan);
        }
        if contact {
            if let Some(plan) = plan {
                terms.velocity = velocity_term(&robot.paddle.lin_vel, plan);
                if terms.hit == 1.0 {
                    let v = robot.frame.vector_from_world(&ball_world.vel);
                    terms.ball_out = sim::math::exp(-(v - plan.v_out).norm());
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
            task_terms(&local, bounce, rules, &mut terms);
            self.legal = match rules {
                TaskRules::Ours => terms.landing > 0.0,
                TaskRules::Official => predicted_legal(&local, bounce),
            };
        }
        (terms, paid)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan_towards(racket_vel: V3) -> Plan {
        Plan {
            receiver: Side::A,
            t_strike: 0.3,
            strike_pos: V3::new(1.8, 0.1, 1.2),
            strike_vel: V3::new(4.0, 0.0, -1.0),
            v_out: V3::new(-4.0, 0.0, 1.0),
            racket_vel,
            racket_quat: UnitQuaternion::rotation_between(&V3::z(), &(-racket_vel)).unwrap(),
            accepted: true,
        }
    }

    #[test]
    fn the_contact_target_lies_where_the_blade_first_touches_the_ball_at_the_strike_point() {
        let plan = plan_towards(V3::new(-3.0, 0.0, 4.0));
        let offset = contact_offset(&sim::geometry::PaddleShape::standard());
        assert_eq!(offset, 0.04);
        assert_eq!(
            position_target(&plan, PositionTarget::Strike, offset),
            plan.strike_pos
        );
        let at = position_target(&plan, PositionTarget::Contact, offset);
        // Moved back against the racket's velocity (−3, 0, 4)/5 by 0.04 m.
        let expected = plan.strike_pos - V3::new(-0.6, 0.0, 0.8) * 0.04;
        assert!((at - expected).norm() < 1e-15, "{at:?}");
        let normal = plan.racket_quat * V3::z();
        let (p, o) = pose_terms(&at, &normal, &at, &plan);
        assert_eq!(p, 1.0);
        assert!(o > 1.0 - 1e-6, "{o}");
        let (p, _) = pose_terms(&at, &normal, &plan.strike_pos, &plan);
        assert!((p - sim::math::exp(-8.0 * 0.04)).abs() < 1e-12);
        // A plan without a racket velocity has no direction to step back along.
        let still = plan_towards(V3::zeros());
        assert_eq!(
            position_target(&still, PositionTarget::Contact, offset),
            still.strike_pos
        );
    }

    #[test]
    fn the_weighted_terms_are_named_as_the_configuration_names_them_and_add_up_to_the_reward() {
        let json = serde_json::to_value(RewardTerms::default()).unwrap();
        let keys: Vec<&str> = json
            .as_object()
            .unwrap()
            .keys()
            .map(|k| k.as_str())
            .collect();
        let mut names = RewardTerms::NAMES.to_vec();
        let mut sorted = keys.clone();
        names.sort_unstable();
        sorted.sort_unstable();
        assert_eq!(names, sorted);
        // Distinct values per term, so a term paired with another's weight would show.
        let mut v = serde_json::Map::new();
        for (k, name) in RewardTerms::NAMES.iter().enumerate() {
            v.insert(name.to_string(), (0.1 + 0.07 * k as f64).into());
        }
        let terms: RewardTerms = serde_json::from_value(v.into()).unwrap();
        let w = RewardWeights::default();
        let parts = terms.weighted(&w);
        let wj = serde_json::to_value(w).unwrap();
        for (k, name) in RewardTerms::NAMES.iter().enumerate() {
            let expected = wj[name].as_f64().unwrap() * (0.1 + 0.07 * k as f64);
            assert_eq!(parts[k], expected, "{name}");
        }
        let sum = parts.iter().fold(0.0, |s, x| s + x);
        assert_eq!(sum.to_bits(), terms.total(&w).to_bits());
    }

    /// A return from (0.6, y, z) on side A's half towards the other with velocity `v`.
    fn ret(y: f64, z: f64, v: [f64; 3]) -> BallState {
        BallState {
            pos: V3::new(0.6, arena::TABLE_CENTER_Y + y, z),
            vel: V3::new(v[0], v[1], v[2]),
            spin: V3::zeros(),
        }
    }

    /// Where the return crosses the net's plane, and where it next bounces (if on the table).
    fn premises(b: &BallState, bounce: &BounceModel) -> (V3, Option<V3>) {
        let (p, _) = sim::predict::flight(&b.pos, &b.vel, -b.pos.x / b.vel.x);
        let land = sim::predict::next_bounce(&b.pos, &b.vel, bounce).map(|x| x.pos);
        (p, land)
    }

    fn judged(b: &BallState, bounce: &BounceModel, rules: TaskRules) -> RewardTerms {
        let mut t = RewardTerms::default();
        task_terms(b, bounce, rules, &mut t);
        t
    }

    #[test]
    fn the_official_rules_ask_for_margins_and_height_and_fault_only_the_net_and_wide() {
        let bounce = BounceModel::for_table(&arena::MYOCHALLENGE.table);
        let (end, _, side) = OFFICIAL_LANDING_MARGIN;
        // Mid-half and high over the net: both rules call it landed.
        let b = ret(0.0, 1.1, [-5.0, 0.0, 1.0]);
        let (at_net, land) = premises(&b, &bounce);
        let land = land.expect("bounces");
        assert!(at_net.z > OFFICIAL_NET_CLEARANCE_Z + 0.1);
        assert!(
            land.x < -0.5 && land.x > -(arena::TABLE_HALF_LENGTH - end),
            "{land}"
        );
        for rules in [TaskRules::Ours, TaskRules::Official] {
            let t = judged(&b, &bounce, rules);
            assert_eq!((t.landing, t.fault), (1.0, 0.0), "{rules:?}");
            assert!(t.centre > 0.0);
        }
        // Bouncing within the end margin: ours lands, the official rules pay neither.
        let b = ret(0.0, 1.1, [-5.3, 0.0, 1.0]);
        let land = premises(&b, &bounce).1.expect("bounces");
        let margin = -(arena::TABLE_HALF_LENGTH - end);
        assert!(
            land.x < margin && land.x > -arena::TABLE_HALF_LENGTH,
            "{land}"
        );
        let t = judged(&b, &bounce, TaskRules::Ours);
        assert_eq!((t.landing, t.fault), (1.0, 0.0));
        let t = judged(&b, &bounce, TaskRules::Official);
        assert_eq!(
            (t.landing, t.fault, t.centre, t.in_box),
            (0.0, 0.0, 0.0, 0.0)
        );
        // Long, high over the net: a fault of ours, nothing by the official rules.
        let b = ret(0.0, 1.1, [-6.0, 0.0, 1.0]);
        let (at_net, land) = premises(&b, &bounce);
        assert!(land.is_none() && at_net.z > OFFICIAL_NET_CLEARANCE_Z);
        assert_eq!(judged(&b, &bounce, TaskRules::Ours).fault, 1.0);
        let t = judged(&b, &bounce, TaskRules::Official);
        assert_eq!((t.landing, t.fault), (0.0, 0.0));
        // Over our net but under 1.00 m at its plane, landing mid-half: a fault of the official rules.
        let b = ret(0.0, 0.99, [-6.0, 0.0, 0.3]);
        let (at_net, land) = premises(&b, &bounce);
        let land = land.expect("bounces");
        assert!(sim::predict::clears_net(&b.pos, &b.vel) && at_net.z < OFFICIAL_NET_CLEARANCE_Z);
        assert!(land.x < -0.5 && land.x > -1.2, "{land}");
        assert_eq!(judged(&b, &bounce, TaskRules::Ours).landing, 1.0);
        let t = judged(&b, &bounce, TaskRules::Official);
        assert_eq!((t.landing, t.fault), (0.0, 1.0));
        // Beside the table at the net's plane: a fault of both.
        let b = ret(0.0, 1.1, [-5.0, 7.0, 1.0]);
        assert!(premises(&b, &bounce).0.y > arena::TABLE_Y_MAX);
        for rules in [TaskRules::Ours, TaskRules::Official] {
            let t = judged(&b, &bounce, rules);
            assert_eq!((t.landing, t.fault), (0.0, 1.0), "{rules:?}");
        }
        // Within a side margin (the other side of the table in side B's frame is the same margin).
        let b = ret(0.0, 1.1, [-5.0, 2.0, 1.0]);
        let land = premises(&b, &bounce).1.expect("bounces");
        assert!(
            land.y > arena::TABLE_Y_MAX - side && land.y < arena::TABLE_Y_MAX,
            "{land}"
        );
        assert_eq!(judged(&b, &bounce, TaskRules::Ours).landing, 1.0);
        assert_eq!(judged(&b, &bounce, TaskRules::Official).landing, 0.0);
        // A ball that does not go towards the net is a fault of both.
        let b = ret(0.0, 1.1, [1.0, 0.0, 1.0]);
        for rules in [TaskRules::Ours, TaskRules::Official] {
            assert_eq!(judged(&b, &bounce, rules).fault, 1.0, "{rules:?}");
        }
    }

    #[test]
    fn each_ablation_removes_its_terms_and_only_those() {
        use crate::observation::CommandVariant;
        let w = RewardWeights::default();
        // The terms whose weight the ablation changed (each to zero).
        let zeroed = |a: Ablation| -> Vec<&str> {
            let b = serde_json::to_value(a.weights(w)).unwrap();
            let f = serde_json::to_value(w).unwrap();
            RewardTerms::NAMES
                .iter()
                .copied()
                .filter(|n| b[n] != f[n])
                .inspect(|n| assert_eq!(b[n], 0.0, "{n}"))
                .collect()
        };
        assert!(zeroed(Ablation::default()).is_empty());
        assert!(Ablation::default().is_none());
        let position = Ablation {
            command: CommandVariant::Position,
            task_reward: true,
        };
        assert_eq!(zeroed(position), ["orientation", "velocity"]);
        let none = Ablation {
            command: CommandVariant::None,
            task_reward: true,
        };
        assert_eq!(zeroed(none), ["position", "orientation", "velocity"]);
        let notask = Ablation {
            command: CommandVariant::Full,
            task_reward: false,
        };
        assert_eq!(
            zeroed(notask),
            ["hit", "landing", "centre", "in_box", "fault", "dual"]
        );
        assert_eq!(notask.name(), "full-notask");
        // ball_out is 0 by default; a configuration that pays it loses it without the full command.
        let mut paid = w;
        paid.0.ball_out = 5.0;
        assert_eq!(position.weights(paid).ball_out, 0.0);
    }
}
