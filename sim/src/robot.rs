//! One robot in the arena: its musculoskeletal model and state, the paddle in its hand and the grip
//! that holds it (docs/design.md §5), placed on side A or, turned about (0, 0.04), on side B.
//!
//! The grip: each physics step, the force and torque the hand must exert to keep the paddle at its
//! nominal pose in the hand (its weight, its acceleration, the ball's impulse spread over the step) are
//! compared with the capacity `friction · Σ |grip muscle force|` (and that times a lever arm for
//! torque). Within capacity the paddle moves with the hand and the ball's impulse reaches the arm;
//! beyond it the paddle slips and flies as a free rigid body, which the hand regains when it is back
//! within `regain_distance`, slower than `regain_speed` relative to the hand, with at least
//! `regain_force` of capacity. Farther than `drop_distance`,
//! the paddle is dropped. Reads the model and config; writes the robot's own state.

use std::sync::Arc;

use nalgebra::{DVector, Matrix3, UnitQuaternion, Vector3};

use crate::arena::{Side, TABLE_CENTER_Y};
use crate::config::GripParams;
use crate::dynamics::{self, Data, State};
use crate::geometry::{PaddleShape, Pose};
use crate::model::Model;
use crate::world::Paddle;

type V3 = Vector3<f64>;

/// Where the paddle is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GripPhase {
    /// In the hand at its nominal pose.
    Held,
    /// Slipped out of the hand and flying free; it can be regained.
    Slipping,
    /// More than `drop_distance` from the hand: lost for the rest of the rally.
    Dropped,
}

/// A change of grip phase, reported by [`Robot::physics_step`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GripEvent {
    /// The load exceeded the grip's capacity: required force and capacity, N.
    Slipped {
        /// Force the hand would have had to exert, N.
        required: f64,
        /// What the grip could hold, N.
        capacity: f64,
    },
    /// The hand caught the paddle again.
    Regained,
    /// The paddle is gone.
    Dropped,
}

/// The paddle's motion, in the robot's model frame (side A's world frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PaddleMotion {
    /// Pose of the paddle frame.
    pub pose: Pose,
    /// Velocity of the paddle frame's origin, m/s.
    pub lin_vel: V3,
    /// Angular velocity, rad/s.
    pub ang_vel: V3,
}

/// The turn that takes side A's frame to side B's: 180° about the vertical line through (0, 0.04).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SideFrame {
    side: Side,
}

impl SideFrame {
    /// The frame of `side` (identity for A).
    pub fn new(side: Side) -> SideFrame {
        SideFrame { side }
    }

    /// A point of the model frame in the world.
    pub fn point_to_world(&self, p: &V3) -> V3 {
        match self.side {
            Side::A => *p,
            Side::B => V3::new(-p.x, 2.0 * TABLE_CENTER_Y - p.y, p.z),
        }
    }

    /// A vector of the model frame in the world.
    pub fn vector_to_world(&self, v: &V3) -> V3 {
        match self.side {
            Side::A => *v,
            Side::B => V3::new(-v.x, -v.y, v.z),
        }
    }

    /// A world point in the model frame (the turn is its own inverse).
    pub fn point_from_world(&self, p: &V3) -> V3 {
        self.point_to_world(p)
    }

    /// A world vector in the model frame.
    pub fn vector_from_world(&self, v: &V3) -> V3 {
        self.vector_to_world(v)
    }

    /// An orientation of the model frame in the world.
    pub fn rotation_to_world(&self, q: &UnitQuaternion<f64>) -> UnitQuaternion<f64> {
        match self.side {
            Side::A => *q,
            Side::B => crate::math::quat_from_axis_angle(&V3::z_axis(), std::f64::consts::PI) * q,
        }
    }
}

/// Mass properties of the paddle body and where it sits in the hand.
#[derive(Debug, Clone)]
struct PaddleBody {
    hand: usize,
    /// The paddle's body in the model.
    index: usize,
    /// The model's own mass and inertia (what [`Robot::set_paddle_mass`] scales).
    nominal_mass: f64,
    nominal_inertia: Matrix3<f64>,
    nominal: Pose,
    mass: f64,
    com: V3,
    inertia: Matrix3<f64>,
}

/// A robot, its paddle and its grip.
#[derive(Debug, Clone)]
pub struct Robot {
    /// The side it plays on.
    pub side: Side,
    /// Its frame in the world.
    pub frame: SideFrame,
    held_model: Arc<Model>,
    free_model: Arc<Model>,
    /// Dynamics workspace.
    pub data: Data,
    /// Joint state, activations and controls.
    pub state: State,
    /// Grip phase.
    pub phase: GripPhase,
    /// Paddle motion at the start of the current physics step (model frame).
    pub paddle: PaddleMotion,
    params: GripParams,
    grip_muscles: Vec<usize>,
    body: PaddleBody,
    /// Paddle centre-of-mass velocity and angular velocity at the previous step (for accelerations).
    prev_velocity: Option<(V3, V3)>,
    /// The held paddle's last centre-of-mass and angular accelerations.
    acceleration: (V3, V3),
    /// Ball impulse on the paddle from the last ball step: (contact point, impulse), model frame.
    pending_impulse: Option<(V3, V3)>,
    /// Grip capacity at the last step, N.
    pub capacity: f64,
    /// The paddle's blade and handle, from the model's geoms.
    pub shape: PaddleShape,
}

impl Robot {
    /// A robot at the model's reference configuration on `side`, its paddle held. Fails if the
    /// grip's bodies or muscles are not in the model.
    pub fn new(model: Arc<Model>, params: &GripParams, side: Side) -> Result<Robot, String> {
        let hand = model
            .body(&params.hand_body)
            .ok_or_else(|| format!("grip.hand_body: no body named '{}'", params.hand_body))?;
        let pb = model
            .body(&params.paddle_body)
            .ok_or_else(|| format!("grip.paddle_body: no body named '{}'", params.paddle_body))?;
        let shape =
            PaddleShape::from_model(&model, pb).map_err(|e| format!("grip.paddle_body: {e}"))?;
        let paddle = &model.bodies[pb];
        if paddle.parent != Some(hand) || paddle.joint_count > 0 {
            return Err(format!(
                "grip.paddle_body: '{}' must be welded to '{}' (its child, without joints)",
                params.paddle_body, params.hand_body
            ));
        }
        let grip_muscles = params
            .muscles
            .iter()
            .map(|n| match model.actuator(n) {
                Some(a) if model.actuators[a].muscle().is_some() => Ok(a),
                _ => Err(format!("grip.muscles: no muscle named '{n}'")),
            })
            .collect::<Result<Vec<_>, _>>()?;
        let body = PaddleBody {
            hand,
            index: pb,
            nominal_mass: paddle.mass,
            nominal_inertia: paddle.inertia,
            nominal: Pose {
                pos: paddle.pos,
                rot: paddle.quat,
            },
            mass: paddle.mass,
            com: paddle.com,
            inertia: paddle.inertia,
        };
        let mut free = (*model).clone();
        free.bodies[pb].mass = 0.0;
        free.bodies[pb].inertia = Matrix3::zeros();
        let data = Data::new(&model);
        let state = State::new(&model);
        let mut robot = Robot {
            side,
            frame: SideFrame::new(side),
            held_model: model,
            free_model: Arc::new(free),
            data,
            state,
            phase: GripPhase::Held,
            paddle: PaddleMotion {
                pose: Pose {
                    pos: V3::zeros(),
                    rot: UnitQuaternion::identity(),
                },
                lin_vel: V3::zeros(),
                ang_vel: V3::zeros(),
            },
            params: params.clone(),
            grip_muscles,
            body,
            prev_velocity: None,
            acceleration: (V3::zeros(), V3::zeros()),
            pending_impulse: None,
            capacity: 0.0,
            shape,
        };
        robot.reset(None);
        Ok(robot)
    }

    /// Gives the paddle `mass` kg, its inertia scaled with it and its centre of mass kept (the
    /// model's own paddle: `None`); MyoChallenge's P2 draws it per episode. Call it between
    /// episodes: it takes effect at the next physics step.
    pub fn set_paddle_mass(&mut self, mass: Option<f64>) {
        let mass = mass.unwrap_or(self.body.nominal_mass);
        if mass == self.body.mass {
            return;
        }
        let inertia = self.body.nominal_inertia * (mass / self.body.nominal_mass.max(1e-12));
        let mut model = (*self.held_model).clone();
        model.bodies[self.body.index].mass = mass;
        model.bodies[self.body.index].inertia = inertia;
        self.held_model = Arc::new(model);
        self.body.mass = mass;
        self.body.inertia = inertia;
    }

    /// The paddle's mass, kg.
    pub fn paddle_mass(&self) -> f64 {
        self.body.mass
    }

    /// The model the robot moves with (the paddle's mass belongs to the hand only while held).
    pub fn model(&self) -> &Model {
        match self.phase {
            GripPhase::Held => &self.held_model,
            _ => &self.free_model,
        }
    }

    /// Back to `qpos` (or the reference configuration) at rest, paddle in the hand: every muscle
    /// relaxed except the grip muscles, which squeeze at `grip.initial_activation` (control and
    /// activation).
    pub fn reset(&mut self, qpos: Option<&[f64]>) {
        let model = self.held_model.clone();
        self.state = State::new(&model);
        if let Some(q) = qpos {
            self.state.set_qpos(&model, q);
        }
        for &a in &self.grip_muscles {
            self.state.act[a] = self.params.initial_activation;
            self.state.ctrl[a] = self.params.initial_activation;
        }
        self.phase = GripPhase::Held;
        self.prev_velocity = None;
        self.acceleration = (V3::zeros(), V3::zeros());
        self.pending_impulse = None;
        self.data.positions(&model, &self.state.qpos);
        self.data.velocities(&model, &self.state.qvel);
        self.paddle = self.held_motion();
    }

    /// Where the paddle would be, held at its nominal pose, at the state of the last dynamics step.
    fn held_motion(&self) -> PaddleMotion {
        let h = self.body.hand;
        let hand = Pose {
            pos: self.data.kin.xpos[h],
            rot: self.data.kin.xquat[h],
        };
        let pose = Pose {
            pos: hand.to_world(&self.body.nominal.pos),
            rot: hand.rot * self.body.nominal.rot,
        };
        PaddleMotion {
            pose,
            lin_vel: self.data.point_velocity(h, &pose.pos),
            ang_vel: self.data.angular_velocity(h),
        }
    }

    /// How far the paddle is from its place in the hand, m (0 while held).
    pub fn paddle_offset(&self) -> f64 {
        match self.phase {
            GripPhase::Held => 0.0,
            _ => (self.paddle.pose.pos - self.held_motion().pose.pos).norm(),
        }
    }

    /// The grip muscles' actuator indices.
    pub fn grip_muscles(&self) -> &[usize] {
        &self.grip_muscles
    }

    /// The shared model with the paddle in the hand.
    pub fn held_model(&self) -> &Arc<Model> {
        &self.held_model
    }

    /// Grip capacity, N: friction times the summed pull of the grip muscles, each muscle's force
    /// given by `force`.
    fn grip_capacity(&self, force: impl Fn(usize) -> f64) -> f64 {
        self.params.friction
            * self
                .grip_muscles
                .iter()
                .map(|&a| force(a).abs())
                .sum::<f64>()
    }

    /// One physics step: first whether the grip holds this step's load (the ball's impulse from the
    /// last ball step, the paddle's acceleration), then muscles and joints (the arm feels the ball only
    /// through a paddle it holds), then the paddle (held, slipping or dropped). Returns a change of grip
    /// phase, if one happened.
    pub fn physics_step(&mut self) -> Option<GripEvent> {
        let h = self.held_model.timestep;
        let mut event = None;
        if self.phase == GripPhase::Held {
            // The grip's capacity now: today's activations on the last step's muscle lengths
            // (the grip muscles' forces alone; the step below computes every force).
            self.capacity = self.grip_capacity(|a| {
                dynamics::actuator_force_now(&self.held_model, &self.data, &self.state, a)
            });
            event = self.check_hold(h);
        }
        let model = match self.phase {
            GripPhase::Held => self.held_model.clone(),
            _ => self.free_model.clone(),
        };
        let external = match (self.phase, self.pending_impulse) {
            (GripPhase::Held, Some((point, impulse))) => {
                let jac = self.data.kin.point_jacobian(&model, self.body.hand, &point);
                Some(jac.transpose() * DVector::from_column_slice((impulse / h).as_slice()))
            }
            _ => None,
        };
        dynamics::step_with_force(&model, &mut self.data, &mut self.state, external.as_ref());
        if self.phase != GripPhase::Held {
            self.capacity = self.grip_capacity(|a| self.data.actuator_force[a]);
        }
        let nominal = self.held_motion();
        match self.phase {
            GripPhase::Held => {
                self.track_acceleration(&nominal, h);
                self.paddle = nominal;
            }
            GripPhase::Slipping | GripPhase::Dropped => {
                let free = self.fly_free(nominal, h, model.gravity);
                event = event.or(free);
            }
        }
        self.pending_impulse = None;
        event
    }

    fn world_inertia(&self, rot: &UnitQuaternion<f64>) -> Matrix3<f64> {
        let r = rot.to_rotation_matrix();
        r.matrix() * self.body.inertia * r.matrix().transpose()
    }

    /// Updates the held paddle's centre-of-mass and angular accelerations from its velocities.
    fn track_acceleration(&mut self, nominal: &PaddleMotion, h: f64) {
        let com = nominal.pose.to_world(&self.body.com);
        let v_com = nominal.lin_vel + nominal.ang_vel.cross(&(com - nominal.pose.pos));
        self.acceleration = match self.prev_velocity {
            Some((v0, w0)) => ((v_com - v0) / h, (nominal.ang_vel - w0) / h),
            None => (V3::zeros(), V3::zeros()),
        };
        self.prev_velocity = Some((v_com, nominal.ang_vel));
    }

    /// Held: can the hand exert the force and torque that keep the paddle at its nominal pose — its
    /// weight, its last acceleration and the ball's impulse spread over the step? If not, it slips,
    /// carrying the hand's motion plus the ball's push.
    fn check_hold(&mut self, h: f64) -> Option<GripEvent> {
        let g = self.held_model.gravity;
        let p = self.paddle;
        let com = p.pose.to_world(&self.body.com);
        let (a_com, alpha) = self.acceleration;
        let inertia = self.world_inertia(&p.pose.rot);
        let (ball_force, ball_torque) = match self.pending_impulse {
            Some((point, impulse)) => (impulse / h, (point - com).cross(&impulse) / h),
            None => (V3::zeros(), V3::zeros()),
        };
        let force = self.body.mass * (a_com - g) - ball_force;
        let w = p.ang_vel;
        let torque = inertia * alpha + w.cross(&(inertia * w)) - ball_torque;
        let capacity = self.capacity;
        let required = force.norm().max(torque.norm() / self.params.lever_arm);
        if required <= capacity {
            return None;
        }
        self.phase = GripPhase::Slipping;
        if let Some((point, impulse)) = self.pending_impulse.take() {
            self.apply_to_free_paddle(&point, &impulse);
        }
        Some(GripEvent::Slipped { required, capacity })
    }

    fn apply_to_free_paddle(&mut self, point: &V3, impulse: &V3) {
        let com = self.paddle.pose.to_world(&self.body.com);
        let inertia = self.world_inertia(&self.paddle.pose.rot);
        let dw =
            inertia.try_inverse().unwrap_or_else(Matrix3::zeros) * (point - com).cross(impulse);
        self.paddle.lin_vel += impulse / self.body.mass + dw.cross(&(self.paddle.pose.pos - com));
        self.paddle.ang_vel += dw;
    }

    /// Slipping or dropped: the paddle flies as a free rigid body under gravity; the hand may regain it.
    fn fly_free(&mut self, nominal: PaddleMotion, h: f64, gravity: V3) -> Option<GripEvent> {
        if let Some((point, impulse)) = self.pending_impulse {
            self.apply_to_free_paddle(&point, &impulse);
        }
        let p = &mut self.paddle;
        let com_local = self.body.com;
        let com = p.pose.to_world(&com_local);
        let mut v_com = p.lin_vel + p.ang_vel.cross(&(com - p.pose.pos));
        v_com += gravity * h;
        let com = com + v_com * h;
        p.pose.rot = crate::math::quat_from_scaled_axis(p.ang_vel * h) * p.pose.rot;
        p.pose.pos = com - p.pose.rot * com_local;
        p.lin_vel = v_com + p.ang_vel.cross(&(p.pose.pos - com));
        let distance = (p.pose.pos - nominal.pose.pos).norm();
        match self.phase {
            GripPhase::Slipping if distance > self.params.drop_distance => {
                self.phase = GripPhase::Dropped;
                Some(GripEvent::Dropped)
            }
            GripPhase::Slipping
                if distance < self.params.regain_distance
                    && (p.lin_vel - nominal.lin_vel).norm() <= self.params.regain_speed
                    && self.capacity >= self.params.regain_force =>
            {
                self.phase = GripPhase::Held;
                self.paddle = nominal;
                self.prev_velocity = None;
                self.acceleration = (V3::zeros(), V3::zeros());
                Some(GripEvent::Regained)
            }
            _ => None,
        }
    }

    /// The paddle as the ball world needs it: world frame, at the start of the coming physics step.
    pub fn ball_paddle(&self) -> Paddle {
        let f = &self.frame;
        Paddle {
            owner: self.side,
            shape: self.shape,
            pose: Pose {
                pos: f.point_to_world(&self.paddle.pose.pos),
                rot: f.rotation_to_world(&self.paddle.pose.rot),
            },
            lin_vel: f.vector_to_world(&self.paddle.lin_vel),
            ang_vel: f.vector_to_world(&self.paddle.ang_vel),
        }
    }

    /// The ball's impulse on this robot's paddle (world frame: contact point and the impulse the ball
    /// received); the paddle feels the opposite, on the next physics step.
    pub fn receive_ball_impulse(&mut self, point_world: &V3, impulse_on_ball: &V3) {
        let point = self.frame.point_from_world(point_world);
        let on_paddle = -self.frame.vector_from_world(impulse_on_ball);
        self.pending_impulse = Some(match self.pending_impulse {
            Some((p, j)) => (p, j + on_paddle),
            None => (point, on_paddle),
        });
    }
}
