//! Ballistic prediction (paper §IV-B, docs/design.md §6): drag-free flight and an instantaneous table bounce
//! `v⁺ = diag(C_h, C_h, −C_v)·v⁻`, the landing point, the crossing of a hitting plane, and the
//! return sampler that both the planner and the rally server draw outgoing velocities from.
//!
//! Flight uses the discrete closed form of the simulator's semi-implicit Euler, so between bounces a
//! prediction matches the `myochallenge` ball world to rounding. Pure functions; randomness only
//! through the [`Rng`] the caller passes.

use nalgebra::Vector3;

use crate::arena::{self, Side, SurfaceLaw};
use crate::rng::{first_accepted, Rng};

type V3 = Vector3<f64>;

/// The planner's table bounce: restitution matrix `diag(C_h, C_h, −C_v)` applied when the ball
/// centre descends through `contact_z`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BounceModel {
    /// Horizontal restitution C_h.
    pub c_h: f64,
    /// Vertical restitution C_v.
    pub c_v: f64,
    /// Ball-centre height at which the equivalent instantaneous bounce happens, m.
    pub contact_z: f64,
}

/// Fitted to the `myochallenge` soft bounce (which reproduces MuJoCo's) by least squares on where
/// 400 seeded P2 serves cross side A's hitting plane (`cargo run --release -p sim --example
/// fit_bounce`): rms error 1.6 cm, worst 4.8 cm. No rigid bounce does better: the soft contact lasts
/// 10–12 ms, and how much energy its discretisation gains (0–3%) depends on the phase at which it
/// starts, which an instantaneous model cannot see. C_h slightly above 1 and the low bounce height
/// stand in for the horizontal travel during the contact and the 12 mm the ball sinks.
pub const MYOCHALLENGE_BOUNCE: BounceModel = BounceModel {
    c_h: 1.0017,
    c_v: 1.0068,
    contact_z: 0.7958,
};

/// Bounce model for a rigid table with restitution `e`: vertical restitution `e`; the horizontal
/// loss depends on the angle of incidence and on spin, and 0.75 is a typical value for a spinless
/// serve with the realistic preset's friction (an approximation: the planner is drag-free and
/// spin-free by design, paper §IV-B).
pub fn rigid_bounce(e: f64) -> BounceModel {
    BounceModel {
        c_h: 0.75,
        c_v: e,
        contact_z: arena::TABLE_TOP_Z + arena::BALL_RADIUS,
    }
}

impl BounceModel {
    /// The planner's bounce model for a preset's table.
    pub fn for_table(law: &SurfaceLaw) -> BounceModel {
        match law {
            SurfaceLaw::Soft(_) => MYOCHALLENGE_BOUNCE,
            SurfaceLaw::Impulse(c) => rigid_bounce(c.restitution),
        }
    }
}

/// Ball state after `t` seconds of drag-free flight from `(pos, vel)`: the semi-implicit Euler
/// closed form `z = z0 + v0·t − ½·g·t·(t + h)`, exact at multiples of the timestep.
pub fn flight(pos: &V3, vel: &V3, t: f64) -> (V3, V3) {
    crate::ball::vacuum_flight(pos, vel, t, arena::TIMESTEP)
}

/// Time until the ball, flying drag-free from height `z0` at vertical speed `vz`, descends through
/// height `z`; `None` if it never reaches it.
pub fn time_to_descend(z0: f64, vz: f64, z: f64) -> Option<f64> {
    crate::ball::descent_time(z0, vz, z, arena::TIMESTEP)
}

/// Whether a drag-free flight from `pos` with `vel` passes over the net (or beside it) when it crosses
/// `x = 0`: its centre at least a ball radius above the net's top there, or outside the net's width.
/// A flight that never reaches `x = 0` does not meet the net.
pub fn clears_net(pos: &V3, vel: &V3) -> bool {
    if vel.x.abs() < 1e-12 || pos.x * vel.x >= 0.0 {
        return true;
    }
    let t = -pos.x / vel.x;
    let (p, _) = flight(pos, vel, t);
    let beside = (p.y - arena::NET_CENTER[1]).abs() > arena::NET_HALF_SIZE[1] + arena::BALL_RADIUS;
    beside || p.z > arena::NET_TOP_Z + arena::BALL_RADIUS
}

/// A predicted table bounce.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bounce {
    /// Time from the prediction's start, s.
    pub t: f64,
    /// Ball centre at the bounce.
    pub pos: V3,
    /// Velocity just before.
    pub vel_in: V3,
    /// Velocity just after.
    pub vel_out: V3,
}

/// Whether a point's x, y lie on the playing surface (its border included).
pub fn over_table(p: &V3) -> bool {
    p.x.abs() <= arena::TABLE_HALF_LENGTH && p.y >= arena::TABLE_Y_MIN && p.y <= arena::TABLE_Y_MAX
}

/// The next bounce on the table, if the ball comes down over it.
pub fn next_bounce(pos: &V3, vel: &V3, model: &BounceModel) -> Option<Bounce> {
    let t = time_to_descend(pos.z, vel.z, model.contact_z)?;
    let (p, v) = flight(pos, vel, t);
    if !over_table(&p) {
        return None;
    }
    Some(Bounce {
        t,
        pos: p,
        vel_in: v,
        vel_out: V3::new(model.c_h * v.x, model.c_h * v.y, -model.c_v * v.z),
    })
}

/// Where a predicted flight crosses the plane `x = plane_x`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneCrossing {
    /// Time from the prediction's start, s.
    pub t: f64,
    /// Ball centre at the crossing.
    pub pos: V3,
    /// Velocity at the crossing.
    pub vel: V3,
    /// Table bounces on the way.
    pub bounces: u32,
    /// The first bounce on the way, if any.
    pub first_bounce: Option<Bounce>,
}

/// Follows the drag-free flight with table bounces until the ball reaches `x = plane_x`. `None` if
/// it never gets there: it flies away from the plane, or falls below `BALL_LOW_Z` first.
pub fn plane_crossing(
    pos: &V3,
    vel: &V3,
    plane_x: f64,
    model: &BounceModel,
) -> Option<PlaneCrossing> {
    let mut p = *pos;
    let mut v = *vel;
    let mut t0 = 0.0;
    let mut bounces = 0;
    let mut first_bounce = None;
    for _ in 0..8 {
        let t_plane = if v.x.abs() > 1e-12 {
            (plane_x - p.x) / v.x
        } else {
            f64::INFINITY
        };
        if t_plane < 0.0 {
            return None;
        }
        let bounce = next_bounce(&p, &v, model).filter(|b| b.t < t_plane);
        match bounce {
            Some(b) => {
                t0 += b.t;
                p = b.pos;
                v = b.vel_out;
                bounces += 1;
                if first_bounce.is_none() {
                    first_bounce = Some(Bounce { t: t0, ..b });
                }
            }
            None => {
                if !t_plane.is_finite() {
                    return None;
                }
                let (pc, vc) = flight(&p, &v, t_plane);
                // It must not fall below the end-of-shot height first.
                if let Some(t_low) = time_to_descend(p.z, v.z, arena::BALL_LOW_Z) {
                    if t_low < t_plane {
                        return None;
                    }
                }
                return Some(PlaneCrossing {
                    t: t0 + t_plane,
                    pos: pc,
                    vel: vc,
                    bounces,
                    first_bounce,
                });
            }
        }
    }
    None
}

/// Height the ball centre must clear over the net when the sampler aims a return, m: the net's
/// top plus a 0.05 m margin (official code: `net_h = 0.95 + 0.05`).
pub const NET_CLEARANCE_Z: f64 = arena::NET_TOP_Z + 0.05;
/// Range of the sampled outgoing vertical speed, m/s (official code: U(0.6, 0.8)).
pub const RETURN_VZ: (f64, f64) = (0.6, 0.8);
/// Landing area of a return, in the hitter's frame: distance beyond the net, m (official code:
/// opponent's x ∈ [−1.35, −0.5] for a hitter on side A).
pub const RETURN_LAND_DEPTH: (f64, f64) = (0.5, 1.35);
/// Landing area across, as the hitter's `y_r` (official code: world y ∈ [−0.40, 0.50] for a
/// hitter on side A, i.e. `y − 0.04` ∈ [−0.44, 0.46]).
pub const RETURN_LAND_YR: (f64, f64) = (-0.44, 0.46);
/// Most draws before the sampler gives up on a strike point (official code).
pub const RETURN_MAX_ATTEMPTS: usize = 50;

/// An outgoing velocity drawn by the return sampler and what it leads to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SampledReturn {
    /// Outgoing ball velocity at the strike point, m/s.
    pub v_out: V3,
    /// Where the return crosses the receiver's hitting plane (if it does).
    pub crossing: Option<PlaneCrossing>,
    /// Whether it bounces on the receiver's half and crosses the receiver's plane inside the serve
    /// box: the condition the sampler resamples for.
    pub accepted: bool,
    /// Draws used (1 to `RETURN_MAX_ATTEMPTS`).
    pub attempts: usize,
}

/// Whether a predicted return from `hitter` is what the sampler wants: first bounce on the other
/// half, crossing the other side's hitting plane inside the serve box.
pub fn return_is_in_box(hitter: Side, crossing: &Option<PlaneCrossing>) -> bool {
    let receiver = hitter.other();
    let Some(c) = crossing else { return false };
    let Some(b) = c.first_bounce else {
        return false;
    };
    let (y_r, z) = receiver.receiver_frame(&c.pos);
    c.bounces == 1 && Side::of_x(b.pos.x) == receiver && arena::in_serve_box(y_r, z)
}

/// Draws one outgoing velocity for a ball struck at `strike` by `hitter` (docs/design.md §6): `v_z` uniform in
/// [`RETURN_VZ`], the flight time down to the table, then `v_x`, `v_y` uniform in the bounds that land
/// in the target area and clear the net by the margin.
fn draw_return(rng: &mut Rng, strike: &V3, hitter: Side, model: &BounceModel) -> V3 {
    let vz = rng.uniform(RETURN_VZ.0, RETURN_VZ.1);
    let s = hitter.sign();
    // Time to reach the table (always exists: the strike is above the table and vz is small).
    let t = time_to_descend(strike.z, vz, model.contact_z).unwrap_or(0.5);
    // Along x: towards the other side; |Δx| from the strike to the landing area.
    let x_near = -s * RETURN_LAND_DEPTH.0;
    let x_far = -s * RETURN_LAND_DEPTH.1;
    let mut speed_lo = (strike.x - x_near).abs() / t;
    let speed_hi = (strike.x - x_far).abs() / t;
    // Net clearance: the ball must still be above NET_CLEARANCE_Z when it crosses x = 0.
    if let Some(t_max) = time_to_descend(strike.z, vz, NET_CLEARANCE_Z) {
        speed_lo = speed_lo.max(strike.x.abs() / t_max);
    }
    let speed = rng.uniform(speed_lo, speed_hi.max(speed_lo));
    let vx = -s * speed;
    let y_lo = hitter.world_y(RETURN_LAND_YR.0);
    let y_hi = hitter.world_y(RETURN_LAND_YR.1);
    let (y_lo, y_hi) = (y_lo.min(y_hi), y_lo.max(y_hi));
    let vy = rng.uniform((y_lo - strike.y) / t, (y_hi - strike.y) / t);
    V3::new(vx, vy, vz)
}

/// The return sampler (paper §IV-B, §IV-C): draws outgoing velocities for a ball struck at `strike`
/// by `hitter` until the predicted return bounces on the other half and crosses the other hitting
/// plane inside the serve box, at most [`RETURN_MAX_ATTEMPTS`] times. If none qualifies, the last draw
/// is returned with `accepted = false`.
pub fn sample_return(
    rng: &mut Rng,
    strike: &V3,
    hitter: Side,
    model: &BounceModel,
) -> SampledReturn {
    let plane = hitter.other().strike_plane_x();
    let mut attempts = 0;
    first_accepted(RETURN_MAX_ATTEMPTS, || {
        attempts += 1;
        let v_out = draw_return(rng, strike, hitter, model);
        let crossing = plane_crossing(strike, &v_out, plane, model);
        let accepted = return_is_in_box(hitter, &crossing);
        let r = SampledReturn {
            v_out,
            crossing,
            accepted,
            attempts,
        };
        (r, accepted)
    })
    .0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flight_matches_closed_form_parabola_shifted_by_half_a_step() {
        let p = V3::new(-1.0, 0.0, 1.2);
        let v = V3::new(5.0, 1.0, 0.5);
        let (pt, vt) = flight(&p, &v, 0.3);
        let g = arena::GRAVITY;
        let h = arena::TIMESTEP;
        assert!((pt.z - (1.2 + 0.5 * 0.3 - 0.5 * g * 0.3 * (0.3 + h))).abs() < 1e-12);
        assert!((pt.x - 0.5).abs() < 1e-12);
        assert!((vt.z - (0.5 - g * 0.3)).abs() < 1e-12);
    }

    #[test]
    fn a_return_that_clips_the_net_top_does_not_clear_it() {
        // From x = 1.566 at 6.643 m/s towards the net, z = 1.101 rising at 0.454 m/s: it reaches
        // x = 0 after 0.2357 s with its centre at z ≈ 0.935, below the net top plus a radius (0.9675)
        // — a return seen in training that the landing prediction alone called legal.
        let p = V3::new(1.566, -0.092, 1.101);
        assert!(!clears_net(&p, &V3::new(-6.643, -0.549, 0.454)));
        // Faster upwards it passes over; beside the net it passes whatever its height.
        assert!(clears_net(&p, &V3::new(-6.643, -0.549, 1.2)));
        assert!(clears_net(
            &V3::new(1.0, 1.5, 0.9),
            &V3::new(-5.0, 0.0, 0.0)
        ));
        // Flying away from the net, it never meets it.
        assert!(clears_net(&p, &V3::new(6.0, 0.0, 0.0)));
    }

    #[test]
    fn descent_time_solves_the_flight() {
        let t = time_to_descend(1.4, 0.1, 0.8).unwrap();
        let (p, _) = flight(&V3::new(0.0, 0.0, 1.4), &V3::new(0.0, 0.0, 0.1), t);
        assert!((p.z - 0.8).abs() < 1e-12);
        assert!(time_to_descend(0.5, 0.0, 0.8).is_none());
    }

    #[test]
    fn crossing_after_one_bounce_and_none_when_flying_away() {
        let model = MYOCHALLENGE_BOUNCE;
        let c = plane_crossing(
            &V3::new(-1.2, -0.4, 1.4),
            &V3::new(5.6, 1.6, 0.1),
            1.8,
            &model,
        )
        .unwrap();
        assert_eq!(c.bounces, 1);
        assert!((c.pos.x - 1.8).abs() < 1e-9);
        assert!(c.first_bounce.unwrap().pos.x > 0.0);
        assert!(plane_crossing(
            &V3::new(0.5, 0.0, 1.2),
            &V3::new(-3.0, 0.0, 0.0),
            1.8,
            &model
        )
        .is_none());
    }

    #[test]
    fn sampled_returns_land_beyond_the_net_and_reach_the_box() {
        let model = MYOCHALLENGE_BOUNCE;
        let mut rng = Rng::seeded(3);
        let mut accepted = 0;
        for i in 0..200 {
            let hitter = if i % 2 == 0 { Side::A } else { Side::B };
            let strike = V3::new(hitter.strike_plane_x(), hitter.world_y(0.1), 1.2);
            let r = sample_return(&mut rng, &strike, hitter, &model);
            assert!(
                r.v_out.x * hitter.sign() < 0.0,
                "a return flies towards the other side"
            );
            assert!(r.v_out.z >= RETURN_VZ.0 && r.v_out.z < RETURN_VZ.1);
            if r.accepted {
                accepted += 1;
                let c = r.crossing.unwrap();
                let b = c.first_bounce.unwrap();
                assert_eq!(Side::of_x(b.pos.x), hitter.other());
                // It cleared the net by the margin: at x = 0 the centre was above NET_CLEARANCE_Z.
                let t_net = -strike.x / r.v_out.x;
                let (p_net, _) = flight(&strike, &r.v_out, t_net);
                assert!(p_net.z >= NET_CLEARANCE_Z - 1e-9);
            }
        }
        assert!(
            accepted >= 190,
            "only {accepted} of 200 strike points found a return"
        );
    }
}
