//! Serve generators (docs/design.md §4): MyoChallenge's P0, P1 and P2 launcher serves to side A, and the
//! paper's heuristic rally serve from either hitting plane. Seeded by the caller's [`Rng`]; the order
//! of draws is part of the contract (changing it changes every seeded match: bump `SIM_VERSION`).

use nalgebra::Vector3;

use crate::arena::{self, Side};
use crate::ball::BallState;
use crate::predict::{self, BounceModel, PlaneCrossing};
use crate::rng::{first_accepted, Rng};

type V3 = Vector3<f64>;

/// Which serve to generate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServeKind {
    /// MyoChallenge P0: one fixed serve.
    P0,
    /// MyoChallenge P1: position jittered in a small box, fixed velocity.
    P1,
    /// MyoChallenge P2: position in a large box, velocity aimed at a random point of A's half.
    P2,
    /// The paper's rally serve from `server`'s hitting plane (§IV-C).
    Rally {
        /// Who serves.
        server: Side,
    },
    /// A robot's return as the receiver meets it in a rally: the rally serve with a stroke's
    /// execution error on its outgoing velocity (Gaussian, [`STROKE_ERROR_SIGMA`] per axis) and
    /// struck from a wider band of heights, redrawn until it is a legal ball (one bounce, on the
    /// receiver's half, over the net) — so, like the returns of our trained robots, about half of them cross the
    /// receiver's plane outside the serve box. Ours, for training on the balls a rally brings after
    /// its serve (not in the paper).
    Stroke {
        /// Who struck it.
        server: Side,
    },
}

impl ServeKind {
    /// Parses "p0", "p1", "p2", "rally" or "stroke" (served by B, as the launcher serves are; the rally server
    /// alternates through [`ServeKind::Rally`]).
    pub fn parse(name: &str) -> Option<ServeKind> {
        match name {
            "p0" => Some(ServeKind::P0),
            "p1" => Some(ServeKind::P1),
            "p2" => Some(ServeKind::P2),
            "rally" => Some(ServeKind::Rally { server: Side::B }),
            "stroke" => Some(ServeKind::Stroke { server: Side::B }),
            _ => None,
        }
    }
}

/// A served ball and who plays it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Serve {
    /// The ball at t = 0 (no spin).
    pub ball: BallState,
    /// The side the ball comes from.
    pub server: Side,
    /// The side that must return it.
    pub receiver: Side,
    /// For a rally serve: its predicted crossing of the receiver's hitting plane.
    pub predicted_crossing: Option<PlaneCrossing>,
}

/// MyoChallenge P0 position, m.
pub const P0_POS: [f64; 3] = [-1.25, -0.5, 1.2];
/// MyoChallenge P0 and P1 velocity, m/s.
pub const P0_VEL: [f64; 3] = [5.6, 1.6, 0.1];
/// MyoChallenge P1 position box (x, y, z ranges), m.
pub const P1_POS: [(f64, f64); 3] = [(-1.25, -1.20), (-0.5, -0.45), (1.4, 1.5)];
/// MyoChallenge P2 position box, m.
pub const P2_POS: [(f64, f64); 3] = [(-1.25, -0.8), (-0.5, 0.5), (1.4, 1.5)];
/// MyoChallenge P2 vertical speed range, m/s.
pub const P2_VZ: (f64, f64) = (-0.1, 0.1);
/// MyoChallenge P2 aim box on A's half (x, y), m, reached by the ball centre at [`P2_AIM_Z`].
pub const P2_AIM: [(f64, f64); 2] = [(0.5, 1.35), (-0.60, 0.70)];
/// Height of the P2 aim point, m (MyoSuite's sampling formula; the real bounce happens earlier).
pub const P2_AIM_Z: f64 = 0.785;
/// Most start points a rally serve tries before it settles for the last sampled one.
pub const RALLY_SERVE_MAX_POINTS: usize = 100;
/// A stroke serve's execution error on each axis of the outgoing velocity, m/s: with the start
/// heights of [`STROKE_START_Z`], 47% of the legal balls cross the receiver's plane inside the serve
/// box, their heights spread 0.13 m and their lateral positions 0.38 m (the test below), near our
/// rally-trained robot's returns (46%, 0.20 m, 0.45 m in 200 self-play rallies, seed 4242).
pub const STROKE_ERROR_SIGMA: f64 = 0.3;
/// Heights a stroke serve is struck from, m: where our robots strike (the incoming balls' crossings
/// of their plane, 1.09 ± 0.20 m for the rally-trained robot's returns), wider than the serve box.
pub const STROKE_START_Z: (f64, f64) = (0.85, 1.45);
/// Most error draws a stroke serve tries for a legal ball before it keeps the rally serve itself.
pub const STROKE_MAX_DRAWS: usize = 50;

fn uniform3(rng: &mut Rng, b: &[(f64, f64); 3]) -> V3 {
    V3::new(
        rng.uniform(b[0].0, b[0].1),
        rng.uniform(b[1].0, b[1].1),
        rng.uniform(b[2].0, b[2].1),
    )
}

/// Continuous-time fall time used by MyoSuite's P2 formula: from `z0` with `vz` down to `z`.
fn p2_flight_time(z0: f64, vz: f64, z: f64) -> f64 {
    crate::ball::descent_time(z0, vz, z, 0.0).unwrap_or(f64::NAN)
}

/// Generates a serve. Draw order: P1 and P2 draw position x, y, z; P2 then v_z, then aim x, y; a rally
/// serve draws (y_r, z) on the server's plane, then the return sampler's draws.
pub fn generate(kind: ServeKind, rng: &mut Rng, model: &BounceModel) -> Serve {
    let launcher = |pos: V3, vel: V3| Serve {
        ball: BallState::new(pos, vel),
        server: Side::B,
        receiver: Side::A,
        predicted_crossing: None,
    };
    match kind {
        ServeKind::P0 => launcher(V3::from(P0_POS), V3::from(P0_VEL)),
        ServeKind::P1 => launcher(uniform3(rng, &P1_POS), V3::from(P0_VEL)),
        ServeKind::P2 => {
            let pos = uniform3(rng, &P2_POS);
            let vz = rng.uniform(P2_VZ.0, P2_VZ.1);
            let aim_x = rng.uniform(P2_AIM[0].0, P2_AIM[0].1);
            let aim_y = rng.uniform(P2_AIM[1].0, P2_AIM[1].1);
            let t = p2_flight_time(pos.z, vz, P2_AIM_Z);
            launcher(pos, V3::new((aim_x - pos.x) / t, (aim_y - pos.y) / t, vz))
        }
        ServeKind::Rally { server } => rally_serve(server, rng, model),
        ServeKind::Stroke { server } => stroke_serve(server, rng, model),
    }
}

/// A robot's return (see [`ServeKind::Stroke`]): struck from a point of the striker's hitting plane
/// ([`STROKE_START_Z`] high, across the serve box's width) at an outgoing velocity from the return
/// sampler, plus the stroke's error; the error is redrawn until the ball is legal. Draws: (y_r, z),
/// the sampler's draws, then three normal draws per error attempt; a new start point after
/// [`STROKE_MAX_DRAWS`] illegal balls.
fn stroke_serve(server: Side, rng: &mut Rng, model: &BounceModel) -> Serve {
    let receiver = server.other();
    let start = |rng: &mut Rng| {
        let y_r = rng.uniform(-arena::SERVE_BOX_HALF_WIDTH, arena::SERVE_BOX_HALF_WIDTH);
        let z = rng.uniform(STROKE_START_Z.0, STROKE_START_Z.1);
        let pos = V3::new(server.strike_plane_x(), server.world_y(y_r), z);
        let aimed = predict::sample_return(rng, &pos, server, model);
        first_accepted(STROKE_MAX_DRAWS, || {
            let error = V3::new(rng.normal(), rng.normal(), rng.normal()) * STROKE_ERROR_SIGMA;
            let vel = aimed.v_out + error;
            let crossing = predict::plane_crossing(&pos, &vel, receiver.strike_plane_x(), model);
            let legal = predict::clears_net(&pos, &vel)
                && crossing.as_ref().is_some_and(|c| {
                    c.bounces == 1
                        && c.first_bounce
                            .is_some_and(|b| Side::of_x(b.pos.x) == receiver)
                });
            let serve = Serve {
                ball: BallState::new(pos, vel),
                server,
                receiver,
                predicted_crossing: crossing,
            };
            (serve, legal)
        })
    };
    first_accepted(RALLY_SERVE_MAX_POINTS, || start(rng)).0
}

/// The paper's heuristic server (§IV-C): a start point uniform in the serve box on the server's
/// hitting plane and an outgoing velocity from the return sampler, redrawn until the ball bounces on
/// the receiver's half and crosses the receiver's plane inside the serve box.
fn rally_serve(server: Side, rng: &mut Rng, model: &BounceModel) -> Serve {
    first_accepted(RALLY_SERVE_MAX_POINTS, || {
        let y_r = rng.uniform(-arena::SERVE_BOX_HALF_WIDTH, arena::SERVE_BOX_HALF_WIDTH);
        let z = rng.uniform(arena::SERVE_BOX_Z.0, arena::SERVE_BOX_Z.1);
        let pos = V3::new(server.strike_plane_x(), server.world_y(y_r), z);
        let r = predict::sample_return(rng, &pos, server, model);
        let serve = Serve {
            ball: BallState::new(pos, r.v_out),
            server,
            receiver: server.other(),
            predicted_crossing: r.crossing,
        };
        (serve, r.accepted)
    })
    .0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::predict::MYOCHALLENGE_BOUNCE;

    /// P1, P2, rally serve (by A) and stroke serve (by B) for seed 0: position then velocity, as f64 bits.
    const PINNED: [[u64; 6]; 4] = [
        [
            13831520685972801208,
            13825631191048445258,
            4609298724775684458,
            4617991057905706598,
            4609884578576439706,
            4591870180066957722,
        ],
        [
            13829932202869455085,
            13808444055292104320,
            4609298724775684458,
            4618408219223871511,
            4601002856270307995,
            13814375059036522316,
        ],
        [
            4610785298501913805,
            4599665110851126613,
            4608157359986476285,
            13842087512940187656,
            4594764360310771632,
            4604839003596996420,
        ],
        [
            13834157335356689613,
            13821595995825143863,
            4607765873792844218,
            4621570364070648018,
            4601929591068587814,
            4599057217928218583,
        ],
    ];

    #[test]
    fn p0_is_fixed_and_p1_stays_in_its_box() {
        let mut rng = Rng::seeded(0);
        let s = generate(ServeKind::P0, &mut rng, &MYOCHALLENGE_BOUNCE);
        assert_eq!(s.ball.pos, V3::from(P0_POS));
        for _ in 0..1000 {
            let s = generate(ServeKind::P1, &mut rng, &MYOCHALLENGE_BOUNCE);
            for (i, (lo, hi)) in P1_POS.iter().enumerate() {
                assert!(s.ball.pos[i] >= *lo && s.ball.pos[i] < *hi);
            }
            assert_eq!(s.ball.vel, V3::from(P0_VEL));
        }
    }

    #[test]
    fn p2_aims_at_its_box_by_myosuites_formula() {
        let mut rng = Rng::seeded(5);
        for _ in 0..1000 {
            let s = generate(ServeKind::P2, &mut rng, &MYOCHALLENGE_BOUNCE);
            let t = p2_flight_time(s.ball.pos.z, s.ball.vel.z, P2_AIM_Z);
            // Continuous-time aim point, as the formula intends.
            let aim = s.ball.pos + s.ball.vel * t;
            assert!(aim.x >= P2_AIM[0].0 - 1e-9 && aim.x <= P2_AIM[0].1 + 1e-9);
            assert!(aim.y >= P2_AIM[1].0 - 1e-9 && aim.y <= P2_AIM[1].1 + 1e-9);
            assert!(s.ball.vel.z >= P2_VZ.0 && s.ball.vel.z < P2_VZ.1);
        }
    }

    #[test]
    fn rally_serves_start_in_the_box_and_are_predicted_into_the_other_box() {
        let mut rng = Rng::seeded(11);
        for i in 0..200 {
            let server = if i % 2 == 0 { Side::A } else { Side::B };
            let s = generate(ServeKind::Rally { server }, &mut rng, &MYOCHALLENGE_BOUNCE);
            assert_eq!(s.receiver, server.other());
            assert!((s.ball.pos.x - server.strike_plane_x()).abs() < 1e-12);
            let (y_r, z) = server.receiver_frame(&s.ball.pos);
            assert!(arena::in_serve_box(y_r, z) || (y_r.abs() <= 0.7 && (1.1..=1.35).contains(&z)));
            assert!(
                predict::return_is_in_box(server, &s.predicted_crossing),
                "serve {i} not in box"
            );
        }
    }

    #[test]
    fn stroke_serves_are_legal_balls_about_half_of_them_in_the_box() {
        let mut rng = Rng::seeded(12);
        let (n, mut in_box, mut moved) = (2000, 0, 0);
        let (mut zs, mut ys) = (vec![], vec![]);
        for i in 0..n {
            let server = if i % 2 == 0 { Side::A } else { Side::B };
            let s = generate(ServeKind::Stroke { server }, &mut rng, &MYOCHALLENGE_BOUNCE);
            assert_eq!(s.receiver, server.other());
            let c = s
                .predicted_crossing
                .expect("a legal ball reaches the plane");
            assert_eq!(c.bounces, 1, "serve {i}");
            assert_eq!(Side::of_x(c.first_bounce.unwrap().pos.x), server.other());
            assert!(predict::clears_net(&s.ball.pos, &s.ball.vel), "serve {i}");
            let (y_r, z) = server.other().receiver_frame(&c.pos);
            in_box += usize::from(arena::in_serve_box(y_r, z));
            zs.push(z);
            ys.push(y_r);
            moved += usize::from(!predict::return_is_in_box(server, &Some(c)));
        }
        let frac = in_box as f64 / n as f64;
        let sd = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
        };
        // Our rally-trained robot's returns (200 self-play rallies, seed 4242): 46% in the box, the
        // crossing height's sd 0.20 m, the lateral one's 0.45 m; the clean rally serve's: 96%, 0.05.
        assert!((0.35..0.55).contains(&frac), "in the box: {frac}");
        assert!((0.1..0.25).contains(&sd(&zs)), "height sd {}", sd(&zs));
        assert!((0.3..0.55).contains(&sd(&ys)), "lateral sd {}", sd(&ys));
        assert_eq!(
            n - in_box,
            moved,
            "outside the box exactly when the predicted return is not"
        );
    }

    /// The exact bits of seeded serves, so that a change of RNG crate, draw order or formula (which
    /// would silently change every recorded match) fails here: bump `SIM_VERSION` and these together.
    #[test]
    fn seeded_serves_are_pinned_to_the_bit() {
        let bits = |s: &Serve| -> [u64; 6] {
            let v: Vec<f64> = s
                .ball
                .pos
                .iter()
                .chain(s.ball.vel.iter())
                .copied()
                .collect();
            std::array::from_fn(|i| v[i].to_bits())
        };
        let p1 = generate(ServeKind::P1, &mut Rng::seeded(0), &MYOCHALLENGE_BOUNCE);
        let p2 = generate(ServeKind::P2, &mut Rng::seeded(0), &MYOCHALLENGE_BOUNCE);
        let rally = generate(
            ServeKind::Rally { server: Side::A },
            &mut Rng::seeded(0),
            &MYOCHALLENGE_BOUNCE,
        );
        let stroke = generate(
            ServeKind::Stroke { server: Side::B },
            &mut Rng::seeded(0),
            &MYOCHALLENGE_BOUNCE,
        );
        let got = [bits(&p1), bits(&p2), bits(&rally), bits(&stroke)];
        assert_eq!(got, PINNED, "seeded serves changed: {got:?}");
    }

    #[test]
    fn same_seed_same_serves() {
        for kind in [
            ServeKind::P1,
            ServeKind::P2,
            ServeKind::Rally { server: Side::A },
            ServeKind::Stroke { server: Side::B },
        ] {
            let a = generate(kind, &mut Rng::seeded(42), &MYOCHALLENGE_BOUNCE);
            let b = generate(kind, &mut Rng::seeded(42), &MYOCHALLENGE_BOUNCE);
            assert_eq!(a, b);
        }
    }
}
