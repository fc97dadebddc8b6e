//! The paper's physics-based planner (§IV-B, docs/design.md §6): from the ball's state, where and when it will
//! cross the receiver's hitting plane (drag-free flight and the table bounce of `sim::predict`), an
//! outgoing velocity from the return sampler (or one given), and the racket command — velocity
//! `v̂_r = ((v_o·u + C_r·v_i·u)/(1 + C_r))·u` and orientation taking the blade normal to
//! `u = (v_o − v_i)/|v_o − v_i|`.

use nalgebra::{UnitQuaternion, Vector3};
use serde::Serialize;
use sim::arena::Side;
use sim::predict::{self, BounceModel};
use sim::rng::Rng;

type V3 = Vector3<f64>;

/// Racket restitution the planner assumes (official code: C_r = 1).
pub const RACKET_RESTITUTION: f64 = 1.0;

/// The planner's command for one incoming ball.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plan {
    /// Who strikes.
    pub receiver: Side,
    /// Time until the ball reaches the receiver's hitting plane, s.
    pub t_strike: f64,
    /// Ball centre there (the racket's target position), m.
    pub strike_pos: V3,
    /// Incoming ball velocity there, m/s.
    pub strike_vel: V3,
    /// Outgoing ball velocity wanted, m/s.
    pub v_out: V3,
    /// Racket velocity at contact, m/s.
    pub racket_vel: V3,
    /// Racket orientation (w, x, y, z): the shortest rotation taking the paddle frame's +z (the blade
    /// normal) to the contact normal `u`.
    pub racket_quat: UnitQuaternion<f64>,
    /// Whether the outgoing velocity passed the sampler's test (bounce on the other half, cross the
    /// other hitting plane inside the serve box); always true for a given `v_out`.
    pub accepted: bool,
}

/// Why no plan could be made.
#[derive(Debug, Clone, PartialEq)]
pub enum PlanError {
    /// The ball moves along neither direction of the table.
    NoDirection,
    /// The ball never reaches that side's hitting plane (it flies away or falls first).
    Unreachable(Side),
}

impl std::fmt::Display for PlanError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PlanError::NoDirection => write!(
                f,
                "the ball has no velocity along the table (vx = 0): give --receiver"
            ),
            PlanError::Unreachable(s) => write!(
                f,
                "the ball never reaches side {}'s hitting plane",
                s.name()
            ),
        }
    }
}

impl std::error::Error for PlanError {}

/// The contact normal and racket velocity that turn `v_in` into `v_out` (paper §IV-B).
pub fn racket_command(v_in: &V3, v_out: &V3) -> (V3, V3) {
    let d = v_out - v_in;
    let u = if d.norm() > 1e-12 {
        d / d.norm()
    } else {
        V3::z()
    };
    let c = RACKET_RESTITUTION;
    let speed = (v_out.dot(&u) + c * v_in.dot(&u)) / (1.0 + c);
    (u, u * speed)
}

/// Shortest rotation taking the paddle frame's +z to `u` (180° about x when `u` = −z).
pub fn racket_orientation(u: &V3) -> UnitQuaternion<f64> {
    sim::math::quat_rotation_between(&V3::z(), u)
        .unwrap_or_else(|| sim::math::quat_from_axis_angle(&V3::x_axis(), std::f64::consts::PI))
}

/// Plans the strike of the ball at `pos`, `vel`. The receiver defaults to the side the ball flies
/// towards; `v_out` defaults to a draw of the return sampler from `rng`.
pub fn plan(
    pos: &V3,
    vel: &V3,
    receiver: Option<Side>,
    v_out: Option<V3>,
    rng: &mut Rng,
    model: &BounceModel,
) -> Result<Plan, PlanError> {
    let receiver = match receiver {
        Some(s) => s,
        None if vel.x > 0.0 => Side::A,
        None if vel.x < 0.0 => Side::B,
        None => return Err(PlanError::NoDirection),
    };
    let crossing = predict::plane_crossing(pos, vel, receiver.strike_plane_x(), model)
        .ok_or(PlanError::Unreachable(receiver))?;
    let (v_out, accepted) = match v_out {
        Some(v) => (v, true),
        None => {
            let r = predict::sample_return(rng, &crossing.pos, receiver, model);
            (r.v_out, r.accepted)
        }
    };
    let (u, racket_vel) = racket_command(&crossing.vel, &v_out);
    Ok(Plan {
        receiver,
        t_strike: crossing.t,
        strike_pos: crossing.pos,
        strike_vel: crossing.vel,
        v_out,
        racket_vel,
        racket_quat: racket_orientation(&u),
        accepted,
    })
}

/// The JSON form `rally plan` prints.
#[derive(Debug, Serialize)]
pub struct PlanJson {
    receiver: &'static str,
    t_strike: f64,
    strike_pos: [f64; 3],
    strike_vel: [f64; 3],
    v_out: [f64; 3],
    racket_vel: [f64; 3],
    racket_quat: [f64; 4],
}

impl From<&Plan> for PlanJson {
    fn from(p: &Plan) -> Self {
        let v = |x: &V3| [x.x, x.y, x.z];
        let q = p.racket_quat.quaternion();
        PlanJson {
            receiver: p.receiver.name(),
            t_strike: p.t_strike,
            strike_pos: v(&p.strike_pos),
            strike_vel: v(&p.strike_vel),
            v_out: v(&p.v_out),
            racket_vel: v(&p.racket_vel),
            racket_quat: [q.w, q.i, q.j, q.k],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sim::predict::MYOCHALLENGE_BOUNCE;

    #[test]
    fn an_elastic_racket_at_the_planned_velocity_returns_v_out() {
        // Closed form: with C_r = 1 and the racket moving at v̂_r along u, the reflected ball leaves
        // at v_in − 2·((v_in − v̂_r)·u)·u, which must equal v_out.
        let v_in = V3::new(5.5, 1.2, 2.0);
        let v_out = V3::new(-6.0, -0.5, 0.7);
        let (u, vr) = racket_command(&v_in, &v_out);
        let reflected = v_in - 2.0 * (v_in - vr).dot(&u) * u;
        assert!((reflected - v_out).norm() < 1e-12, "{reflected}");
        assert!((racket_orientation(&u) * V3::z() - u).norm() < 1e-12);
        assert!((racket_orientation(&-V3::z()) * V3::z() + V3::z()).norm() < 1e-12);
    }

    #[test]
    fn plan_defaults_and_errors() {
        let mut rng = Rng::seeded(1);
        let p = plan(
            &V3::new(-1.2, -0.45, 1.45),
            &V3::new(5.6, 1.6, 0.1),
            None,
            None,
            &mut rng,
            &MYOCHALLENGE_BOUNCE,
        )
        .unwrap();
        assert_eq!(p.receiver, Side::A);
        assert!((p.strike_pos.x - 1.8).abs() < 1e-9 && p.t_strike > 0.4 && p.t_strike < 0.8);
        assert!(p.v_out.x < 0.0 && p.accepted);
        assert_eq!(
            plan(
                &V3::new(0.0, 0.0, 1.0),
                &V3::new(0.0, 1.0, 0.0),
                None,
                None,
                &mut rng,
                &MYOCHALLENGE_BOUNCE
            ),
            Err(PlanError::NoDirection)
        );
        assert_eq!(
            plan(
                &V3::new(1.0, 0.0, 1.0),
                &V3::new(-3.0, 0.0, 0.0),
                Some(Side::A),
                None,
                &mut rng,
                &MYOCHALLENGE_BOUNCE
            ),
            Err(PlanError::Unreachable(Side::A))
        );
        // A given v_out is taken as is.
        let v = V3::new(-5.0, 0.0, 0.7);
        let p = plan(
            &V3::new(-1.2, -0.45, 1.45),
            &V3::new(5.6, 1.6, 0.1),
            None,
            Some(v),
            &mut rng,
            &MYOCHALLENGE_BOUNCE,
        )
        .unwrap();
        assert_eq!(p.v_out, v);
    }
}
