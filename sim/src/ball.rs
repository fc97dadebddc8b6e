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

/// Drag-free flight under gravity alone for `t` seconds, as semi-implicit Euler with step `h` moves
/// it (exact at multiples of `h`; `h = 0` is the continuous parabola): horizontal motion is exact,
/// `z = z0 + v0·t − ½·g·t·(t + h)`, and the velocity is `v0 − g·t`. The one place this closed
/// form is written: the predictor and the serves use it, the flight is tested against it.
pub fn vacuum_flight(pos: &V3, vel: &V3, t: f64, h: f64) -> (V3, V3) {
    let g = arena::GRAVITY;
    (
        V3::new(
            pos.x + vel.x * t,
            pos.y + vel.y * t,
            pos.z + vel.z * t - 0.5 * g * t * (t + h),
        ),
        V3::new(vel.x, vel.y, vel.z - g * t),
    )
}

/// [`vacuum_flight`] after `n` steps of `h` from `start`.
pub fn vacuum_flight_closed_form(start: &BallState, n: u32, h: f64) -> (V3, V3) {
    vacuum_flight(&start.pos, &start.vel, n as f64 * h, h)
}

/// Time until a drag-free ball from height `z0` at vertical speed `vz` descends through height `z`
/// under [`vacuum_flight`] with step `h` (the larger root of `½·g·t² − (vz − ½·g·h)·t − (z0 − z) = 0`);
/// `None` if it never reaches it.
pub fn descent_time(z0: f64, vz: f64, z: f64, h: f64) -> Option<f64> {
    let g = arena::GRAVITY;
    let b = vz - 0.5 * g * h;
    let disc = b * b + 2.0 * g * (z0 - z);
    if disc < 0.0 {
        return None;
    }
    let t = (b + disc.sqrt()) / g;
    (t >= 0.0).then_some(t)
}
