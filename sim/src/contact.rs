//! Contact laws between the ball and the world: MuJoCo's soft contact (a force while the ball
//! penetrates) and the event-accurate impulse (restitution plus Coulomb friction with spin).
//!
//! Pure functions of the ball state and the contact geometry; the ball world decides when to call
//! them. Neither law here can ever add energy in the frame of the surface it acts against, except
//! the soft contact's discretisation (docs/design.md §4: up to ~3%, as MuJoCo's).

use nalgebra::Vector3;

use crate::arena::{self, ImpulseCoeffs, SoftContact};
use crate::ball::BallState;

type V3 = Vector3<f64>;

/// Linear and angular acceleration of the ball, m/s² and rad/s².
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Accel {
    /// Linear acceleration.
    pub lin: V3,
    /// Angular acceleration.
    pub ang: V3,
}

/// MuJoCo's constraint impedance `d(r)` for a penetration `depth ≥ 0` (`mj_solimp`): it rises from
/// `d0` at first touch to `dwidth` at `width`, along two quadratic halves meeting at mid-width.
pub fn impedance(solimp: &[f64; 3], depth: f64) -> f64 {
    let [d0, dwidth, width] = *solimp;
    let x = (depth / width).clamp(0.0, 1.0);
    // midpoint 0.5, power 2 (MuJoCo defaults)
    let y = if x < 0.5 {
        2.0 * x * x
    } else {
        1.0 - 2.0 * (1.0 - x) * (1.0 - x)
    };
    d0 + y * (dwidth - d0)
}

impl SoftContact {
    /// The acceleration the contact adds to a ball whose surface is `gap < 0` from a surface with
    /// outward normal `normal`, given the acceleration `free` the ball would have without it.
    ///
    /// Normal direction, as MuJoCo solves one soft unilateral constraint for a free sphere whose
    /// contact normal passes through its centre: reference acceleration
    /// `a_ref = −B·v_n − K·d·r` with `K = k/dwidth²`, `B = b/dwidth` (direct `solref`), and the
    /// constrained acceleration `a_n = (1 − d)·a0_n + d·a_ref` when that pushes (`a_ref > a0_n`),
    /// else no force. Tangential: the contact point's sliding velocity is damped at
    /// `tangential_damping`, applied as a friction impulse at the contact point (so it spins the
    /// ball) that never reverses the slip.
    pub fn acceleration(
        &self,
        ball: &BallState,
        normal: &V3,
        gap: f64,
        free: &V3,
        h: f64,
    ) -> Accel {
        let depth = -gap;
        if depth <= 0.0 {
            return Accel::default();
        }
        let d = impedance(&self.solimp, depth);
        let dmax = self.solimp[1];
        let k = self.stiffness / (dmax * dmax);
        let b = self.damping / dmax;
        let v_n = ball.vel.dot(normal);
        let a_ref = -b * v_n - k * d * gap;
        let a0_n = free.dot(normal);
        if a_ref <= a0_n {
            return Accel::default();
        }
        let lin_n = d * (a_ref - a0_n);

        // Tangential friction at the contact point r_c = −R·n.
        let r_c = -arena::BALL_RADIUS * normal;
        let v_c = ball.vel + ball.spin.cross(&r_c);
        let v_t = v_c - v_c.dot(normal) * normal;
        let slip = v_t.norm();
        let mut accel = Accel {
            lin: lin_n * normal,
            ang: V3::zeros(),
        };
        if slip > 1e-12 && self.tangential_damping > 0.0 {
            let dir = v_t / slip;
            // Impulse over the step, capped at the one that stops the slip.
            let j =
                (self.tangential_damping * arena::BALL_MASS * slip * h).min(slip * sliding_mass());
            let impulse = -j * dir;
            accel.lin += impulse / (arena::BALL_MASS * h);
            accel.ang += r_c.cross(&impulse) / (arena::BALL_INERTIA * h);
        }
        accel
    }
}

/// Effective mass of the ball against a tangential impulse at its surface, kg:
/// `1 / (1/m + r²/I)`, 0.4·m for a thin shell.
pub fn sliding_mass() -> f64 {
    1.0 / (1.0 / arena::BALL_MASS + arena::BALL_RADIUS * arena::BALL_RADIUS / arena::BALL_INERTIA)
}

/// The ball's change in velocity and spin from an instantaneous contact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImpulseResult {
    /// Normal impulse, N·s (≥ 0).
    pub normal_impulse: f64,
    /// Tangential (friction) impulse magnitude, N·s.
    pub friction_impulse: f64,
}

/// Applies an instantaneous contact between the ball and a surface that moves with velocity
/// `surface_vel` at the contact point, outward normal `normal` (pointing from the surface to the
/// ball). The surface is kinematic (a paddle driven by its hand, the table, the net).
///
/// Normal: `v_n⁺ = −e·v_n⁻` for the contact point's relative normal velocity. Tangential: Coulomb
/// friction with the ball's spin; the impulse that stops the slip, capped at `μ·J_n`. Returns `None`
/// when the ball is already separating (no impulse).
pub fn apply_impulse(
    ball: &mut BallState,
    normal: &V3,
    surface_vel: &V3,
    coeffs: &ImpulseCoeffs,
) -> Option<ImpulseResult> {
    let r_c = -arena::BALL_RADIUS * normal;
    let v_rel = ball.vel + ball.spin.cross(&r_c) - surface_vel;
    let v_n = v_rel.dot(normal);
    if v_n >= 0.0 {
        return None;
    }
    let m = arena::BALL_MASS;
    // The lever r_c is parallel to the normal, so the normal impulse does not spin the ball.
    let j_n = -(1.0 + coeffs.restitution) * v_n * m;
    let v_t = v_rel - v_n * normal;
    let slip = v_t.norm();
    let mut j_t = 0.0;
    let mut impulse = j_n * normal;
    if slip > 1e-12 {
        j_t = (slip * sliding_mass()).min(coeffs.friction * j_n);
        impulse -= j_t * (v_t / slip);
    }
    ball.vel += impulse / m;
    ball.spin += r_c.cross(&impulse) / arena::BALL_INERTIA;
    Some(ImpulseResult {
        normal_impulse: j_n,
        friction_impulse: j_t,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn energy_in_frame(ball: &BallState, frame_vel: &V3) -> f64 {
        let rel = BallState {
            vel: ball.vel - frame_vel,
            ..*ball
        };
        rel.kinetic_energy()
    }

    #[test]
    fn impedance_follows_mujoco_curve() {
        let s = [0.9, 0.95, 0.001];
        assert!((impedance(&s, 0.0) - 0.9).abs() < 1e-15);
        assert!((impedance(&s, 0.0005) - 0.925).abs() < 1e-15);
        assert!((impedance(&s, 0.00025) - (0.9 + 0.125 * 0.05)).abs() < 1e-15);
        assert!((impedance(&s, 0.01) - 0.95).abs() < 1e-15);
    }

    #[test]
    fn head_on_impulse_reverses_normal_speed_by_restitution() {
        let mut ball = BallState::new(V3::zeros(), V3::new(0.0, 0.0, -5.0));
        let c = ImpulseCoeffs {
            restitution: 0.8,
            friction: 0.3,
        };
        apply_impulse(&mut ball, &V3::z(), &V3::zeros(), &c).unwrap();
        assert!((ball.vel.z - 4.0).abs() < 1e-12);
        assert_eq!(ball.spin, V3::zeros());
    }

    #[test]
    fn friction_spins_the_ball_like_rolling_and_never_adds_energy() {
        let c = ImpulseCoeffs {
            restitution: 1.0,
            friction: 10.0,
        };
        let mut ball = BallState::new(V3::zeros(), V3::new(3.0, 0.0, -2.0));
        let before = ball.kinetic_energy();
        apply_impulse(&mut ball, &V3::z(), &V3::zeros(), &c).unwrap();
        // With unbounded friction the contact point stops sliding: v_x = r·ω_y (rolling).
        assert!((ball.vel.x - arena::BALL_RADIUS * ball.spin.y).abs() < 1e-12);
        assert!(ball.spin.y > 0.0);
        assert!(ball.kinetic_energy() <= before + 1e-15);
    }

    #[test]
    fn moving_surface_conserves_energy_in_its_own_frame() {
        let c = ImpulseCoeffs {
            restitution: 1.0,
            friction: 0.5,
        };
        let paddle_vel = V3::new(-4.0, 1.0, 0.5);
        let n = V3::new(-1.0, 0.2, 0.1).normalize();
        let mut ball = BallState::new(V3::zeros(), V3::new(6.0, 1.0, -1.0));
        ball.spin = V3::new(10.0, -30.0, 5.0);
        let before = energy_in_frame(&ball, &paddle_vel);
        apply_impulse(&mut ball, &n, &paddle_vel, &c).unwrap();
        assert!(energy_in_frame(&ball, &paddle_vel) <= before * (1.0 + 1e-12));
    }

    #[test]
    fn separating_ball_gets_no_impulse() {
        let c = ImpulseCoeffs {
            restitution: 1.0,
            friction: 0.5,
        };
        let mut ball = BallState::new(V3::zeros(), V3::new(0.0, 0.0, 1.0));
        assert!(apply_impulse(&mut ball, &V3::z(), &V3::zeros(), &c).is_none());
    }
}
