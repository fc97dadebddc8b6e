//! The ball's state and its free flight: gravity, optional quadratic drag and Magnus lift,
//! integrated by semi-implicit Euler exactly as MuJoCo's Euler integrator moves a free body.
//!
//! Reads an [`AirModel`]; writes only the [`BallState`] it is given.

use nalgebra::Vector3;

use crate::arena::{self, AirModel};

type V3 = Vector3<f64>;

/// Everything that moves with the ball.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BallState {
    /// Centre position, m (world frame).
    pub pos: V3,
    /// Linear velocity, m/s.
    pub vel: V3,
    /// Angular velocity, rad/s (world frame).
    pub spin: V3,
}

impl BallState {
    /// A ball at `pos` moving at `vel` without spin.
    pub fn new(pos: V3, vel: V3) -> BallState {
        BallState {
            pos,
            vel,
            spin: V3::zeros(),
        }
    }

    /// Translational plus rotational kinetic energy, J.
    pub fn kinetic_energy(&self) -> f64 {
        0.5 * arena::BALL_MASS * self.vel.norm_squared()
            + 0.5 * arena::BALL_INERTIA * self.spin.norm_squared()
    }

    /// Kinetic plus gravitational potential energy (zero at z = 0), J.
    pub fn mechanical_energy(&self) -> f64 {
        self.kinetic_energy() + arena::BALL_MASS * arena::GRAVITY * self.pos.z
    }

    /// Whether every component is a finite number.
    pub fn is_finite(&self) -> bool {
        self.pos
            .iter()
            .chain(self.vel.iter())
            .chain(self.spin.iter())
            .all(|x| x.is_finite())
    }
}

/// Acceleration of a free ball, m/s²: gravity, plus drag `−k_d·|v|·v` and Magnus `k_m·(ω × v)`.
pub fn flight_acceleration(air: Option<&AirModel>, vel: &V3, spin: &V3) -> V3 {
    let gravity = V3::new(0.0, 0.0, -arena::GRAVITY);
    match air {
        None => gravity,
        Some(air) => gravity - air.drag * vel.norm() * vel + air.magnus * spin.cross(vel),
    }
}

/// The discrete closed form of semi-implicit Euler under gravity alone, after `n` steps of `h`:
/// horizontal motion is exact, and `z_n = z0 + v0·t − ½·g·t·(t + h)` with `t = n·h`.
/// The velocity is `v0 − g·t`. This is the reference our flight is tested against.
pub fn vacuum_flight_closed_form(start: &BallState, n: u32, h: f64) -> (V3, V3) {
    let t = n as f64 * h;
    let g = arena::GRAVITY;
    let pos = V3::new(
        start.pos.x + start.vel.x * t,
        start.pos.y + start.vel.y * t,
        start.pos.z + start.vel.z * t - 0.5 * g * t * (t + h),
    );
    let vel = V3::new(start.vel.x, start.vel.y, start.vel.z - g * t);
    (pos, vel)
}
