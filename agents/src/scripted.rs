//! The scripted house agent (issue 4): no learning — the planner says where, when and how to meet the
//! ball, inverse kinematics turns the blade's pose before, at and after the strike into joint targets,
//! and K-MAC turns the joint targets into muscle controls.
//!
//! Timeline for each incoming ball: as soon as it flies towards the robot, plan (and re-plan once
//! after its bounce); move to the backswing pose; swing through the strike pose during `swing_time`
//! centred on the predicted strike (shifted earlier by `lead` for the muscles' lag); hold the
//! follow-through briefly; go back to the ready posture. The fingers hold the ready posture's grasp
//! (the built-in body's single grip joint is driven past its stop so the hand squeezes the handle).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use sim::arena::{self, Side};
use sim::ball::BallState;
use sim::model::Model;
use sim::predict::BounceModel;
use sim::rng::Rng;
use sim::robot::Robot;

use crate::controller::{gravity_offset, Kmac, PdGains};
use crate::ik::{BladeTarget, PaddleIk};
use crate::planner::{self, Plan};

type V3 = Vector3<f64>;

/// How a scripted agent plays.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ScriptedParams {
    /// K-MAC's length PD gains.
    pub gains: PdGains,
    /// Duration of the swing through the strike, s.
    pub swing_time: f64,
    /// Distance of the backswing and follow-through from the strike point along the racket's
    /// velocity, m.
    pub backswing: f64,
    /// How much earlier than planned the swing starts, s (the muscles lag their targets).
    pub lead: f64,
    /// Outgoing velocities drawn from the return sampler per plan; the agent keeps the one that needs
    /// the slowest racket (a block) or the fastest (a drive), see `drive`.
    pub candidates: usize,
    /// Prefer fast returns (true) or blocks that need little racket speed (false).
    pub drive: bool,
    /// Grip joint target, rad (past the handle stop at 1.0, so the fingers squeeze).
    pub grip_target: f64,
    /// Least control of the grip muscles: K-MAC squeezes towards `grip_target`, but never less than
    /// this, so the grip holds however the wrist and elbow change the muscles' lengths.
    pub grip_activation: Option<f64>,
    /// Outer joint-space loop on K-MAC's targets: proportional gain on the tracking error.
    pub outer_kp: f64,
    /// Outer loop: integral gain, 1/s (removes what sag the gravity feed-forward leaves).
    pub outer_ki: f64,
    /// Lead K-MAC's targets by the offset that holds them against gravity (see
    /// `controller::gravity_offset`).
    pub gravity_feedforward: bool,
}

impl Default for ScriptedParams {
    fn default() -> Self {
        ScriptedParams {
            gains: PdGains { kp: 40.0, kd: 3.0 },
            swing_time: 0.24,
            backswing: 0.12,
            lead: 0.15,
            candidates: 12,
            drive: false,
            grip_target: 1.05,
            grip_activation: Some(0.03),
            outer_kp: 0.25,
            outer_ki: 0.0,
            gravity_feedforward: true,
        }
    }
}

/// The current plan and the joint targets it implies.
#[derive(Debug, Clone)]
struct Stroke {
    t_hit: f64,
    bounced: bool,
    z_pre: Vec<f64>,
    z_post: Vec<f64>,
    /// Gravity feed-forward at the strike posture.
    offset: Vec<f64>,
}

/// A scripted agent for one robot.
#[derive(Debug, Clone)]
pub struct Scripted {
    /// Its parameters.
    pub params: ScriptedParams,
    kmac: Kmac,
    ik: PaddleIk,
    ready: Vec<f64>,
    stroke: Option<Stroke>,
    rng: Rng,
    bounce: BounceModel,
    grip_joint: Option<usize>,
    /// The finger joints (and the grip joint): held, never placed by the IK.
    hand: Vec<usize>,
    targets: Vec<f64>,
    integral: Vec<f64>,
    follow_until: f64,
    data: sim::dynamics::Data,
    ready_offset: Vec<f64>,
}

impl Scripted {
    /// An agent for `robot`'s model; `seed` drives its return-sampler draws. Fails if the model's
    /// paddle body has no blade.
    pub fn new(
        model: &Model,
        paddle_body: usize,
        params: ScriptedParams,
        bounce: BounceModel,
        seed: u64,
    ) -> Result<Scripted, String> {
        let kmac = Kmac::new(model, params.gains);
        let grip_joint = model.joint("grip");
        let hand = crate::ik::JointRoles::of(model, paddle_body).hand;
        let exclude: Vec<usize> = hand.iter().copied().chain(grip_joint).collect();
        let blade = sim::geometry::PaddleShape::from_model(model, paddle_body)?
            .blade
            .center;
        let ik = PaddleIk::new(model, paddle_body, blade, &exclude);
        let mut ready = sim::episode::ready_pose(model).unwrap_or_else(|| model.qpos0.clone());
        model.apply_couplings(&mut ready);
        let targets: Vec<f64> = kmac
            .space
            .joints
            .iter()
            .map(|&j| ready[model.joints[j].qpos_adr])
            .collect();
        let integral = vec![0.0; targets.len()];
        let mut data = sim::dynamics::Data::new(model);
        let ready_offset = if params.gravity_feedforward {
            gravity_offset(
                model,
                &mut data,
                &kmac.space,
                &params.gains,
                &ready,
                &exclude,
            )
        } else {
            vec![0.0; targets.len()]
        };
        Ok(Scripted {
            params,
            kmac,
            ik,
            ready,
            stroke: None,
            rng: Rng::seeded(seed),
            bounce,
            grip_joint,
            hand: exclude,
            targets,
            integral,
            follow_until: f64::NEG_INFINITY,
            data,
            ready_offset,
        })
    }

    /// Reseeds the return-sampler draws.
    pub fn reseed(&mut self, seed: u64) {
        self.rng = Rng::seeded(seed);
    }

    /// Forgets the current stroke and the outer loop's integral (call at every new episode or rally).
    pub fn reset(&mut self) {
        self.stroke = None;
        self.integral.iter_mut().for_each(|x| *x = 0.0);
        self.follow_until = f64::NEG_INFINITY;
    }

    /// Joint targets (action-space order) from a full qpos.
    fn targets_of(&self, model: &Model, qpos: &[f64]) -> Vec<f64> {
        self.kmac
            .space
            .joints
            .iter()
            .map(|&j| qpos[model.joints[j].qpos_adr])
            .collect()
    }

    /// Plans a stroke for the ball (model frame) at time `t`.
    fn plan_stroke(
        &mut self,
        model: &Model,
        robot: &Robot,
        ball: &BallState,
        t: f64,
        bounced: bool,
    ) -> Option<Stroke> {
        let mut best: Option<Plan> = None;
        for _ in 0..self.params.candidates.max(1) {
            let Ok(p) = planner::plan(
                &ball.pos,
                &ball.vel,
                Some(Side::A),
                None,
                &mut self.rng,
                &self.bounce,
            ) else {
                return None;
            };
            let better = match &best {
                None => true,
                // An accepted return (lands over, reaches the other plane in the box) beats any other.
                Some(b) if p.accepted != b.accepted => p.accepted,
                Some(b) if self.params.drive => p.racket_vel.norm() > b.racket_vel.norm(),
                Some(b) => p.racket_vel.norm() < b.racket_vel.norm(),
            };
            if better {
                best = Some(p);
            }
        }
        let plan = best?;
        let u = plan.racket_quat * V3::z();
        let dir = if plan.racket_vel.norm() > 0.3 {
            plan.racket_vel.normalize()
        } else {
            -V3::x()
        };
        let seed = robot.state.qpos.clone();
        let b = self.params.backswing;
        let rest = self.ready.clone();
        let pre = self.ik.solve_near(
            model,
            &seed,
            Some(&rest),
            &BladeTarget {
                pos: plan.strike_pos - dir * b,
                normal: u,
            },
            100,
        );
        let post = self.ik.solve_near(
            model,
            &pre.qpos,
            Some(&rest),
            &BladeTarget {
                pos: plan.strike_pos + dir * b,
                normal: u,
            },
            100,
        );
        let offset = if self.params.gravity_feedforward {
            gravity_offset(
                model,
                &mut self.data,
                &self.kmac.space,
                &self.params.gains,
                &pre.qpos,
                &self.hand,
            )
        } else {
            vec![0.0; self.targets.len()]
        };
        Some(Stroke {
            t_hit: t + plan.t_strike,
            bounced,
            z_pre: self.targets_of(model, &pre.qpos),
            z_post: self.targets_of(model, &post.qpos),
            offset,
        })
    }

    /// Writes the robot's controls for this control step. `ball` is in the world frame; `t` is the
    /// arena's time.
    pub fn act(&mut self, robot: &Robot, ball: &BallState, t: f64, ctrl: &mut [f64]) {
        let model = robot.held_model().clone();
        let f = robot.frame;
        let ball = BallState {
            pos: f.point_from_world(&ball.pos),
            vel: f.vector_from_world(&ball.vel),
            spin: f.vector_from_world(&ball.spin),
        };
        let incoming = ball.vel.x > 0.0 && ball.pos.x < arena::STRIKE_PLANE_X + 0.3;
        if incoming {
            // Plan when the ball starts coming; re-plan once it has bounced on our half and left the
            // table (during the 10 ms soft contact its state predicts nothing).
            let clear = arena::TABLE_TOP_Z + arena::BALL_RADIUS + 0.02;
            let bounced = ball.pos.x > 0.0 && ball.vel.z > 0.0 && ball.pos.z > clear;
            let replan = match &self.stroke {
                None => true,
                Some(s) => bounced && !s.bounced,
            };
            if replan {
                if let Some(s) = self.plan_stroke(&model, robot, &ball, t, bounced) {
                    self.stroke = Some(s);
                }
            }
        }
        let p = &self.params;
        self.targets = match &self.stroke {
            Some(s) => {
                let start = s.t_hit - p.lead - 0.5 * p.swing_time;
                let end = start + p.swing_time;
                if t < start {
                    s.z_pre.clone()
                } else if t < end {
                    let a = (t - start) / p.swing_time;
                    s.z_pre
                        .iter()
                        .zip(&s.z_post)
                        .map(|(x, y)| x + a * (y - x))
                        .collect()
                } else {
                    self.follow_until = end + 0.15;
                    s.z_post.clone()
                }
            }
            None if t < self.follow_until => self.targets.clone(),
            None => self.targets_of(&model, &self.ready.clone()),
        };
        if let Some(s) = &self.stroke {
            if !incoming && t > s.t_hit {
                self.stroke = None;
            }
        }
        // The fingers keep the ready posture's grasp; a single grip joint is squeezed past its stop.
        for (i, &j) in self.kmac.space.joints.iter().enumerate() {
            if Some(j) == self.grip_joint {
                self.targets[i] = self.params.grip_target;
            } else if self.hand.contains(&j) {
                self.targets[i] = self.ready[model.joints[j].qpos_adr];
            }
        }
        // Feed-forward: lead the targets by what holds them against gravity; outer loop: by the
        // tracking error and its integral.
        let dt = arena::CONTROL_DT;
        let offset = match &self.stroke {
            Some(s) => &s.offset,
            None => &self.ready_offset,
        };
        let mut command: Vec<f64> = self
            .targets
            .iter()
            .zip(offset)
            .map(|(z, o)| z + o)
            .collect();
        for (i, &j) in self.kmac.space.joints.iter().enumerate() {
            if self.kmac.space.servos[i].is_some() || self.hand.contains(&j) {
                continue;
            }
            let err = self.targets[i] - robot.state.qpos[model.joints[j].qpos_adr];
            self.integral[i] = (self.integral[i] + err * dt).clamp(-0.2, 0.2);
            command[i] += self.params.outer_kp * err + self.params.outer_ki * self.integral[i];
        }
        self.kmac.controls(&model, &robot.state, &command, dt, ctrl);
        if let Some(u) = self.params.grip_activation {
            for &a in robot.grip_muscles() {
                ctrl[a] = ctrl[a].max(u);
            }
        }
    }
}

/// The scripted variants the house offers, by name: the default blocker, a driver that asks for fast
/// returns, and a softer, lower-gain player.
pub fn variants() -> Vec<(&'static str, ScriptedParams)> {
    let base = ScriptedParams::default();
    vec![
        ("scripted", base.clone()),
        (
            "scripted-drive",
            ScriptedParams {
                drive: true,
                backswing: 0.15,
                ..base.clone()
            },
        ),
        (
            "scripted-soft",
            ScriptedParams {
                gains: PdGains { kp: 20.0, kd: 2.0 },
                ..base
            },
        ),
    ]
}

impl crate::player::Player for Scripted {
    fn reset(&mut self) {
        Scripted::reset(self);
    }

    fn reseed(&mut self, seed: u64) {
        Scripted::reseed(self, seed);
    }

    fn act(
        &mut self,
        robot: &Robot,
        ball: &BallState,
        t: f64,
        ctrl: &mut [f64],
    ) -> Result<(), crate::player::InvalidAction> {
        Scripted::act(self, robot, ball, t, ctrl);
        Ok(())
    }
}
