//! The ball world: one ball, the table, the net, the floor and up to two paddles driven from outside.
//! Each physics step integrates the ball (semi-implicit Euler, soft table forces as MuJoCo), then
//! sweeps it along its step against every impulsive shape, stopping at each impact (continuous
//! collision detection by conservative advancement), so no contact is ever tunnelled through.
//!
//! Reads the [`Preset`] and the paddles' motion; writes the ball, the clock and contact events.
//! No I/O, no randomness.

use nalgebra::Vector3;

use crate::arena::{self, ImpulseCoeffs, Preset, Side, SoftContact, SurfaceLaw};
use crate::ball::{self, BallState};
use crate::contact::{self, Accel};
use crate::events::{ContactEvent, ContactKind};
use crate::geometry::{plane_proximity, Aabb, PaddleShape, Pose, Proximity};

type V3 = Vector3<f64>;

/// Gap below which the ball counts as touching an impulsive shape, m.
const TOUCH_EPS: f64 = 1e-7;
/// Most impacts resolved inside one physics step (a ball wedged between paddle and table).
const MAX_IMPACTS_PER_STEP: usize = 8;
/// Most conservative-advancement iterations for one shape in one step.
const MAX_ADVANCE_ITERATIONS: usize = 256;

/// A paddle as the ball world sees it: a rigid shape moving with constant linear and angular
/// velocity through each physics step. Whoever drives it (a script, a robot's hand) sets its pose and
/// velocity before the step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Paddle {
    /// Which robot holds it.
    pub owner: Side,
    /// Blade and handle.
    pub shape: PaddleShape,
    /// Pose of the paddle frame at the start of the step.
    pub pose: Pose,
    /// Velocity of the paddle frame's origin, m/s.
    pub lin_vel: V3,
    /// Angular velocity, rad/s, world frame.
    pub ang_vel: V3,
}

impl Paddle {
    /// A paddle at rest.
    pub fn at_rest(owner: Side, pose: Pose) -> Paddle {
        Paddle {
            owner,
            shape: PaddleShape::standard(),
            pose,
            lin_vel: V3::zeros(),
            ang_vel: V3::zeros(),
        }
    }

    /// Pose after moving for `tau` seconds with the current velocities.
    pub fn pose_after(&self, tau: f64) -> Pose {
        Pose {
            pos: self.pose.pos + self.lin_vel * tau,
            rot: crate::math::quat_from_scaled_axis(self.ang_vel * tau) * self.pose.rot,
        }
    }

    /// Moves the pose forward by `dt` with the current velocities.
    pub fn advance(&mut self, dt: f64) {
        self.pose = self.pose_after(dt);
    }
}

/// Which shapes the ball touched in a step, so that a contact that lasts several steps (a soft
/// bounce, a ball carried on the blade) is one event.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Touching {
    table: bool,
    floor: bool,
    net: bool,
    paddle: [bool; 2],
}

/// Something the ball can be swept against.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Target {
    Table,
    Floor,
    Net,
    Paddle(usize),
}

/// The ball world's mutable state plus the preset it runs under.
#[derive(Debug, Clone)]
pub struct BallWorld {
    /// Contact laws and air model.
    pub preset: Preset,
    /// The ball.
    pub ball: BallState,
    /// Simulated time, s.
    pub time: f64,
    table: Aabb,
    net: Aabb,
    touching: Touching,
    /// Impulses the ball received from paddles in the last physics step: (paddle owner, contact
    /// point, impulse on the ball in N·s). The paddle received the opposite.
    pub paddle_impulses: Vec<(Side, V3, V3)>,
}

fn side_index(side: Side) -> usize {
    match side {
        Side::A => 0,
        Side::B => 1,
    }
}

impl BallWorld {
    /// A world at t = 0 with the ball in `ball`.
    pub fn new(preset: Preset, ball: BallState) -> BallWorld {
        BallWorld {
            preset,
            ball,
            time: 0.0,
            table: Aabb::table(),
            net: Aabb::net(),
            touching: Touching::default(),
            paddle_impulses: Vec::new(),
        }
    }

    /// One control step (`SUBSTEPS` physics steps). Paddles move with their velocities and are
    /// left at their poses after the step. Contacts that began are appended to `events`.
    pub fn control_step(&mut self, paddles: &mut [Paddle], events: &mut Vec<ContactEvent>) {
        for _ in 0..arena::SUBSTEPS {
            self.physics_step(paddles, events);
            for p in paddles.iter_mut() {
                p.advance(arena::TIMESTEP);
            }
        }
    }

    /// One physics step of `TIMESTEP`, with the paddles at their poses at the step's start.
    pub fn physics_step(&mut self, paddles: &[Paddle], events: &mut Vec<ContactEvent>) {
        let h = arena::TIMESTEP;
        let free =
            ball::flight_acceleration(self.preset.air.as_ref(), &self.ball.vel, &self.ball.spin);
        let soft = self.soft_law();
        let start = self.ball.pos;
        let mut accel = Accel {
            lin: free,
            ang: V3::zeros(),
        };
        let mut start_gaps = [f64::INFINITY; 2];
        if let Some(law) = &soft {
            for (i, prox) in [
                self.table.proximity(&start),
                plane_proximity(arena::FLOOR_Z, &start),
            ]
            .iter()
            .enumerate()
            {
                let gap = prox.distance - arena::BALL_RADIUS;
                start_gaps[i] = gap;
                if gap < 0.0 {
                    let a = law.acceleration(&self.ball, &prox.normal, gap, &free, h);
                    accel.lin += a.lin;
                    accel.ang += a.ang;
                }
            }
        }
        self.ball.vel += h * accel.lin;
        self.ball.spin += h * accel.ang;

        let mut touched = Touching::default();
        self.paddle_impulses.clear();
        self.sweep(paddles, h, &mut touched, events);

        if soft.is_some() {
            let end = self.ball.pos;
            let end_table = self.table.proximity(&end).distance - arena::BALL_RADIUS;
            let end_floor = end.z - arena::FLOOR_Z - arena::BALL_RADIUS;
            touched.table = end_table <= 0.0;
            touched.floor = end_floor <= 0.0;
            if touched.table && !self.touching.table {
                let frac = crossing_fraction(start_gaps[0], end_table);
                let pos = start + (end - start) * frac;
                let feature = self.table.proximity(&pos).feature;
                events.push(ContactEvent {
                    kind: ContactKind::Table { feature },
                    t: self.time + frac * h,
                    pos,
                });
            }
            if touched.floor && !self.touching.floor {
                let frac = crossing_fraction(start_gaps[1], end_floor);
                events.push(ContactEvent {
                    kind: ContactKind::Floor,
                    t: self.time + frac * h,
                    pos: start + (end - start) * frac,
                });
            }
        }
        self.touching = touched;
        self.time += h;
    }

    fn soft_law(&self) -> Option<SoftContact> {
        match self.preset.table {
            SurfaceLaw::Soft(law) => Some(law),
            SurfaceLaw::Impulse(_) => None,
        }
    }

    /// Moves the ball through the step at its new velocity, resolving every impact on the way.
    fn sweep(
        &mut self,
        paddles: &[Paddle],
        h: f64,
        touched: &mut Touching,
        events: &mut Vec<ContactEvent>,
    ) {
        let mut tau = 0.0;
        let mut hit_already: Vec<Target> = Vec::new();
        for _ in 0..MAX_IMPACTS_PER_STEP {
            let mut first: Option<(f64, Target)> = None;
            for target in self.impulse_targets(paddles) {
                if hit_already.contains(&target) {
                    continue;
                }
                if let Some(t_hit) = self.time_of_impact(target, paddles, tau, h) {
                    if first.is_none_or(|(t, _)| t_hit < t) {
                        first = Some((t_hit, target));
                    }
                }
            }
            let Some((t_hit, target)) = first else { break };
            self.ball.pos += self.ball.vel * (t_hit - tau);
            tau = t_hit;
            let (prox, surface_vel) = self.proximity(target, paddles, tau, &self.ball.pos);
            let gap = prox.distance - arena::BALL_RADIUS;
            if gap < 0.0 {
                // Started inside (a paddle moved into the ball): put the ball back on the surface.
                self.ball.pos += prox.normal * (-gap + TOUCH_EPS);
            }
            let coeffs = self.coeffs(target);
            let vel_before = self.ball.vel;
            if contact::apply_impulse(&mut self.ball, &prox.normal, &surface_vel, &coeffs).is_some()
            {
                if let Target::Paddle(i) = target {
                    let impulse = (self.ball.vel - vel_before) * arena::BALL_MASS;
                    self.paddle_impulses
                        .push((paddles[i].owner, prox.point, impulse));
                }
                let kind = match target {
                    Target::Table => ContactKind::Table {
                        feature: prox.feature,
                    },
                    Target::Floor => ContactKind::Floor,
                    Target::Net => ContactKind::Net,
                    Target::Paddle(i) => ContactKind::Paddle {
                        owner: paddles[i].owner,
                    },
                };
                let (was, now) = self.touch_flags(target, paddles, touched);
                if !was && !*now {
                    events.push(ContactEvent {
                        kind,
                        t: self.time + tau,
                        pos: self.ball.pos,
                    });
                }
                *now = true;
            }
            hit_already.push(target);
        }
        self.ball.pos += self.ball.vel * (h - tau);
    }

    fn touch_flags<'a>(
        &self,
        target: Target,
        paddles: &[Paddle],
        touched: &'a mut Touching,
    ) -> (bool, &'a mut bool) {
        match target {
            Target::Table => (self.touching.table, &mut touched.table),
            Target::Floor => (self.touching.floor, &mut touched.floor),
            Target::Net => (self.touching.net, &mut touched.net),
            Target::Paddle(i) => {
                let k = side_index(paddles[i].owner);
                (self.touching.paddle[k], &mut touched.paddle[k])
            }
        }
    }

    fn impulse_targets(&self, paddles: &[Paddle]) -> impl Iterator<Item = Target> {
        let rigid_table = matches!(self.preset.table, SurfaceLaw::Impulse(_));
        let surfaces: &[Target] = if rigid_table {
            &[Target::Net, Target::Table, Target::Floor]
        } else {
            &[Target::Net]
        };
        surfaces
            .iter()
            .copied()
            .chain((0..paddles.len()).map(Target::Paddle))
    }

    fn coeffs(&self, target: Target) -> ImpulseCoeffs {
        match (target, self.preset.table) {
            (Target::Net, _) => self.preset.net,
            (Target::Paddle(_), _) => self.preset.paddle,
            (Target::Table | Target::Floor, SurfaceLaw::Impulse(c)) => c,
            // Soft surfaces are never swept against; a rigid fallback keeps this total.
            (Target::Table | Target::Floor, SurfaceLaw::Soft(_)) => self.preset.net,
        }
    }

    /// Nearest point of `target` (at `tau` into the step) to `p`, and the surface's velocity there.
    fn proximity(&self, target: Target, paddles: &[Paddle], tau: f64, p: &V3) -> (Proximity, V3) {
        match target {
            Target::Table => (self.table.proximity(p), V3::zeros()),
            Target::Net => (self.net.proximity(p), V3::zeros()),
            Target::Floor => (plane_proximity(arena::FLOOR_Z, p), V3::zeros()),
            Target::Paddle(i) => {
                let paddle = &paddles[i];
                let pose = paddle.pose_after(tau);
                let local = paddle.shape.proximity(&pose.to_local(p));
                let point = pose.to_world(&local.point);
                let prox = Proximity {
                    distance: local.distance,
                    normal: pose.rot * local.normal,
                    point,
                    feature: local.feature,
                };
                let vel = paddle.lin_vel + paddle.ang_vel.cross(&(point - pose.pos));
                (prox, vel)
            }
        }
    }

    /// Earliest time in `[tau0, h]` at which the ball, moving from its current position at its
    /// current velocity, touches `target` while approaching it; `None` if it does not.
    ///
    /// Conservative advancement: the gap can shrink no faster than `bound` (relative speed plus the
    /// target's rotation times the lever), so stepping by `gap / bound` never passes through the
    /// surface whatever the speed or the thickness. A touch that is already separating is no impact
    /// (the shapes are convex, so the gap only grows from there within the step).
    fn time_of_impact(&self, target: Target, paddles: &[Paddle], tau0: f64, h: f64) -> Option<f64> {
        let p0 = self.ball.pos;
        let v = self.ball.vel;
        let (rel_speed, ang_speed, lever) = match target {
            Target::Paddle(i) => {
                let paddle = &paddles[i];
                let rel = (v - paddle.lin_vel).norm();
                let origin = paddle.pose_after(tau0).pos;
                let lever = (p0 - origin).norm() + rel * (h - tau0);
                // Broad phase: the ball cannot reach the paddle's bounding sphere this step.
                let reach = paddle.shape.bounding_radius() + arena::BALL_RADIUS;
                let bound = rel + paddle.ang_vel.norm() * lever;
                if (p0 - origin).norm() - reach > bound * (h - tau0) + TOUCH_EPS {
                    return None;
                }
                (rel, paddle.ang_vel.norm(), lever)
            }
            _ => (v.norm(), 0.0, 0.0),
        };
        let bound = rel_speed + ang_speed * lever;
        let mut tau = tau0;
        for _ in 0..MAX_ADVANCE_ITERATIONS {
            let p = p0 + v * (tau - tau0);
            let (prox, surface_vel) = self.proximity(target, paddles, tau, &p);
            let gap = prox.distance - arena::BALL_RADIUS;
            if gap <= TOUCH_EPS {
                let r_c = -arena::BALL_RADIUS * prox.normal;
                let v_rel = v + self.ball.spin.cross(&r_c) - surface_vel;
                return (v_rel.dot(&prox.normal) < 0.0).then_some(tau);
            }
            if bound <= 0.0 {
                return None;
            }
            tau += gap / bound;
            if tau > h {
                return None;
            }
        }
        None
    }
}

/// Fraction of the step at which a gap going from `g0` to `g1 ≤ 0` reached zero (linear).
fn crossing_fraction(g0: f64, g1: f64) -> f64 {
    if g0 <= 0.0 || !g0.is_finite() {
        0.0
    } else {
        (g0 / (g0 - g1)).clamp(0.0, 1.0)
    }
}
