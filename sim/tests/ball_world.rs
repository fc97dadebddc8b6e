//! The ball world against closed forms: flight, bounce ratios per preset, no tunnelling through the
//! blade (4 cm and 5 mm) or the net at up to 40 m/s, and energy bounds.

use nalgebra::{UnitQuaternion, Vector3};
use sim::arena::{self, Preset, Side, MYOCHALLENGE, REALISTIC};
use sim::ball::vacuum_flight_closed_form;
use sim::geometry::{PaddleShape, Pose};
use sim::rng::Rng;
use sim::serve::{generate, ServeKind};
use sim::{BallState, BallWorld, ContactKind, Paddle};

type V3 = Vector3<f64>;

/// Far from table, net and floor: nothing but gravity acts.
fn open_air() -> BallState {
    BallState::new(V3::new(0.3, 5.0, 6.0), V3::new(2.0, -1.0, 4.0))
}

#[test]
fn vacuum_flight_is_the_discrete_closed_form_of_semi_implicit_euler() {
    let start = open_air();
    let mut world = BallWorld::new(MYOCHALLENGE, start);
    let mut events = Vec::new();
    for n in 1..=400u32 {
        world.physics_step(&[], &mut events);
        let (pos, vel) = vacuum_flight_closed_form(&start, n, arena::TIMESTEP);
        assert!(
            (world.ball.pos - pos).norm() < 1e-11,
            "step {n}: {} vs {}",
            world.ball.pos,
            pos
        );
        assert!((world.ball.vel - vel).norm() < 1e-11);
    }
    assert!(events.is_empty());
}

#[test]
fn energy_never_grows_in_flight_with_or_without_air() {
    for preset in [MYOCHALLENGE, REALISTIC] {
        let mut ball = open_air();
        ball.spin = V3::new(20.0, -150.0, 40.0);
        let mut world = BallWorld::new(preset, ball);
        let mut events = Vec::new();
        let mut e = world.ball.mechanical_energy();
        for _ in 0..400 {
            world.physics_step(&[], &mut events);
            let e1 = world.ball.mechanical_energy();
            assert!(
                e1 <= e + 1e-15,
                "{}: energy grew from {e} to {e1}",
                preset.name
            );
            e = e1;
        }
    }
}

/// Drops a ball onto the table from 0.3 m above the surface, moving sideways at `vx`, in vacuum, and
/// returns (vertical speed out / in, horizontal speed out / in), each interpolated where the ball
/// crosses 1 cm above the touch height on the way down and on the way up.
fn bounce_ratios(preset: Preset, vx: f64) -> (f64, f64) {
    let level = arena::TABLE_TOP_Z + arena::BALL_RADIUS + 0.01;
    let mut world = BallWorld::new(
        preset,
        BallState::new(V3::new(0.4, 0.0, level + 0.29), V3::new(vx, 0.0, 0.0)),
    );
    world.preset.air = None;
    let mut events = Vec::new();
    let mut v_in = None;
    let mut v_out = None;
    for _ in 0..1000 {
        let before = world.ball;
        world.physics_step(&[], &mut events);
        let after = world.ball;
        let crossing = |down: bool| {
            let crossed = if down {
                before.pos.z > level && after.pos.z <= level
            } else {
                before.pos.z < level && after.pos.z >= level
            };
            crossed.then(|| {
                let f = (level - before.pos.z) / (after.pos.z - before.pos.z);
                before.vel + (after.vel - before.vel) * f
            })
        };
        if v_in.is_none() {
            v_in = crossing(true);
        } else if let Some(v) = crossing(false) {
            v_out = Some(v);
            break;
        }
    }
    let (vi, vo) = (
        v_in.expect("reaches the table"),
        v_out.expect("bounces back"),
    );
    (-vo.z / vi.z, if vx != 0.0 { vo.x / vi.x } else { 1.0 })
}

#[test]
fn bounce_ratios_per_preset() {
    // myochallenge: MuJoCo's soft contact keeps ≈ 0.99–1.03 of the vertical speed (its Euler
    // discretisation can gain a little) and ≈ 0.995 of the horizontal speed (docs/design.md §4).
    let (cv, ch) = bounce_ratios(MYOCHALLENGE, 3.0);
    assert!(
        (0.97..=1.035).contains(&cv),
        "myochallenge vertical ratio {cv}"
    );
    assert!(
        (0.985..=1.0).contains(&ch),
        "myochallenge horizontal ratio {ch}"
    );
    // realistic: rigid impulse with the ITTF restitution, exactly (measured at the touch height).
    let (cv, _) = bounce_ratios(REALISTIC, 0.0);
    let e = match REALISTIC.table {
        arena::SurfaceLaw::Impulse(c) => c.restitution,
        _ => unreachable!(),
    };
    assert!(
        (cv - e).abs() < 0.01,
        "realistic vertical ratio {cv}, restitution {e}"
    );
    // Sliding friction slows the ball and spins it up.
    let (_, ch) = bounce_ratios(REALISTIC, 3.0);
    assert!(ch < 0.95 && ch > 0.5, "realistic horizontal ratio {ch}");
}

#[test]
fn soft_table_gains_at_most_about_three_percent_energy() {
    let mut rng = Rng::seeded(9);
    let mut worst: f64 = 0.0;
    for _ in 0..300 {
        let serve = generate(ServeKind::P2, &mut rng, &sim::predict::MYOCHALLENGE_BOUNCE);
        let mut world = BallWorld::new(MYOCHALLENGE, serve.ball);
        let mut events = Vec::new();
        let e0 = world.ball.mechanical_energy();
        // Fly through the bounce and 60 ms past it.
        let mut after = None;
        for _ in 0..400 {
            world.physics_step(&[], &mut events);
            if !events.is_empty() && after.is_none() {
                after = Some(world.time + 0.06);
            }
            if after.is_some_and(|t| world.time >= t) {
                break;
            }
        }
        let ratio = world.ball.mechanical_energy() / e0;
        worst = worst.max(ratio);
    }
    assert!(
        worst <= 1.03,
        "soft bounce gained {:.2}% energy",
        (worst - 1.0) * 100.0
    );
}

/// A paddle floating in open air, its blade normal (+z of the paddle frame) along `normal`.
fn paddle_facing(normal: V3, shape: PaddleShape, lin_vel: V3) -> Paddle {
    let rot = UnitQuaternion::rotation_between(&V3::z(), &normal)
        .unwrap_or_else(UnitQuaternion::identity);
    Paddle {
        owner: Side::A,
        shape,
        pose: Pose {
            pos: V3::new(0.5, 4.0, 3.0),
            rot,
        },
        lin_vel,
        ang_vel: V3::zeros(),
    }
}

/// Fires the ball at the blade's centre along `dir` (unit, pointing from the ball towards the blade,
/// at `angle` from the face's inward normal) at relative speed `speed`, optionally with the paddle
/// doing the moving, and follows it for 40 ms after the first impact. The ball starts 5 mm outside the
/// blade's slab and gets the upward speed that cancels gravity's drop on the way, so its path passes
/// through the blade's centre. Returns whether it stayed on the side it came from: its centre never
/// inside the blade (grown by the ball's radius) nor past the blade's plane within the blade's disc.
fn fire_at_blade(shape: PaddleShape, dir: V3, angle: f64, speed: f64, paddle_moves: bool) -> bool {
    let normal = V3::new(0.3, -0.2, 1.0).normalize();
    let travel = (shape.blade.half_length + arena::BALL_RADIUS + 0.005) / angle.cos();
    let t = travel / speed;
    let lift = V3::z() * 0.5 * arena::GRAVITY * (t + arena::TIMESTEP);
    let (ball_vel, paddle_vel) = if paddle_moves {
        (lift, -dir * speed)
    } else {
        (dir * speed + lift, V3::zeros())
    };
    let mut paddle = paddle_facing(normal, shape, paddle_vel);
    let centre = paddle.pose.to_world(&shape.blade.center);
    let start = centre - dir * travel;
    let mut world = BallWorld::new(MYOCHALLENGE, BallState::new(start, ball_vel));
    let side0 = (paddle.pose.to_local(&start) - shape.blade.center)
        .z
        .signum();
    let mut events = Vec::new();
    let mut steps_after_impact = None;
    for _ in 0..400 {
        world.physics_step(std::slice::from_ref(&paddle), &mut events);
        paddle.advance(arena::TIMESTEP);
        let local = paddle.pose.to_local(&world.ball.pos) - shape.blade.center;
        let within_disc = local.xy().norm() < shape.blade.radius;
        let inside =
            within_disc && local.z.abs() < shape.blade.half_length + arena::BALL_RADIUS - 1e-6;
        if inside || (within_disc && local.z.signum() != side0) {
            return false;
        }
        if !events.is_empty() {
            let n = steps_after_impact.get_or_insert(0);
            *n += 1;
            if *n >= 20 {
                break;
            }
        }
    }
    assert!(
        events.iter().any(|e| matches!(e.kind, ContactKind::Paddle { owner: Side::A })),
        "no paddle contact: half-thickness {}, {speed} m/s, dir {dir:?}, paddle moves {paddle_moves}, events {events:?}, ball {:?}",
        shape.blade.half_length,
        world.ball
    );
    true
}

#[test]
fn no_tunnelling_through_4cm_or_5mm_blade_up_to_40_m_s() {
    let normal = V3::new(0.3, -0.2, 1.0).normalize();
    let tangent = normal.cross(&V3::x()).normalize();
    for shape in [
        PaddleShape::standard(),
        PaddleShape::standard().with_blade_half_thickness(0.0025),
    ] {
        for &speed in &[2.0, 5.0, 10.0, 20.0, 30.0, 40.0] {
            for &angle_deg in &[0.0, 20.0, 45.0, 70.0, 80.0] {
                for &from_front in &[true, false] {
                    for &paddle_moves in &[false, true] {
                        let a = f64::to_radians(angle_deg);
                        let n = if from_front { normal } else { -normal };
                        // Fired towards the face: against its outward normal, tilted by `a`.
                        let dir = (-n * a.cos() + tangent * a.sin()).normalize();
                        let ok = fire_at_blade(shape, dir, a, speed, paddle_moves);
                        assert!(
                            ok,
                            "tunnelled: half-thickness {} m, {speed} m/s, {angle_deg}°, front {from_front}, paddle moves {paddle_moves}",
                            shape.blade.half_length
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn no_tunnelling_through_the_net_up_to_40_m_s() {
    for &speed in &[2.0, 10.0, 25.0, 40.0] {
        for &angle_deg in &[0.0, 30.0, 60.0, 80.0] {
            for &from_a in &[true, false] {
                let s = if from_a { 1.0 } else { -1.0 };
                let a = f64::to_radians(angle_deg);
                let dir = V3::new(-s * a.cos(), a.sin(), 0.0);
                // Aimed at the net's face above the table (z = 0.88), from 0.1 m away.
                let target = V3::new(0.0, 0.04, 0.88);
                let start = target - dir * 0.1;
                let mut world = BallWorld::new(MYOCHALLENGE, BallState::new(start, dir * speed));
                let mut events = Vec::new();
                for _ in 0..200 {
                    world.physics_step(&[], &mut events);
                    assert!(
                        world.ball.pos.x * s > arena::NET_HALF_SIZE[0],
                        "through the net at {speed} m/s, {angle_deg}°: x = {}",
                        world.ball.pos.x
                    );
                    if world.ball.pos.z < arena::TABLE_TOP_Z + 0.03 {
                        break;
                    }
                }
                assert!(matches!(
                    events.first().map(|e| e.kind),
                    Some(ContactKind::Net)
                ));
            }
        }
    }
}

#[test]
fn paddle_and_net_impacts_never_add_energy_in_the_paddle_frame() {
    let mut rng = Rng::seeded(77);
    for preset in [MYOCHALLENGE, REALISTIC] {
        for i in 0..500 {
            let normal = V3::new(
                rng.uniform(-1.0, 1.0),
                rng.uniform(-1.0, 1.0),
                rng.uniform(-1.0, 1.0),
            )
            .normalize();
            let paddle_vel = V3::new(
                rng.uniform(-8.0, 8.0),
                rng.uniform(-8.0, 8.0),
                rng.uniform(-8.0, 8.0),
            );
            let paddle = paddle_facing(normal, PaddleShape::standard(), paddle_vel);
            let centre = paddle.pose.to_world(&paddle.shape.blade.center);
            // Ball just in front of the blade, approaching it.
            let mut ball = BallState::new(
                centre + normal * (paddle.shape.blade.half_length + arena::BALL_RADIUS + 0.005),
                paddle_vel - normal * rng.uniform(0.5, 40.0)
                    + normal.cross(&V3::x()) * rng.uniform(-5.0, 5.0),
            );
            ball.spin = V3::new(
                rng.uniform(-200.0, 200.0),
                rng.uniform(-200.0, 200.0),
                rng.uniform(-200.0, 200.0),
            );
            // Energy in the paddle's (inertial) frame, gravity's potential included: semi-implicit
            // Euler flight only loses it, so any gain would come from the impact.
            let energy = |b: &BallState, t: f64| {
                BallState {
                    pos: b.pos - paddle_vel * t,
                    vel: b.vel - paddle_vel,
                    spin: b.spin,
                }
                .mechanical_energy()
            };
            let mut world = BallWorld::new(preset, ball);
            world.preset.air = None;
            let mut events = Vec::new();
            let mut p = paddle;
            let mut e0 = energy(&world.ball, 0.0);
            for _ in 0..100 {
                world.physics_step(std::slice::from_ref(&p), &mut events);
                p.advance(arena::TIMESTEP);
                let e1 = energy(&world.ball, world.time);
                assert!(
                    e1 <= e0 * (1.0 + 1e-12),
                    "{} case {i}: {e0} -> {e1}",
                    preset.name
                );
                e0 = e1;
                if !events.is_empty() {
                    break;
                }
            }
            assert!(
                events
                    .iter()
                    .any(|e| matches!(e.kind, ContactKind::Paddle { .. })),
                "case {i}: no impact"
            );
        }
    }
}

#[test]
fn net_impacts_never_add_energy() {
    let mut rng = Rng::seeded(78);
    for preset in [MYOCHALLENGE, REALISTIC] {
        for i in 0..300 {
            let from_a = i % 2 == 0;
            let s = if from_a { 1.0 } else { -1.0 };
            let target = V3::new(0.0, rng.uniform(-0.5, 0.6), rng.uniform(0.83, 0.96));
            let dir = V3::new(-s, rng.uniform(-0.5, 0.5), rng.uniform(-0.3, 0.3)).normalize();
            let start = target - dir * 0.08;
            let mut ball = BallState::new(start, dir * rng.uniform(1.0, 40.0));
            ball.spin = V3::new(
                rng.uniform(-300.0, 300.0),
                rng.uniform(-300.0, 300.0),
                rng.uniform(-300.0, 300.0),
            );
            let mut world = BallWorld::new(preset, ball);
            world.preset.air = None;
            let mut events = Vec::new();
            let mut e0 = world.ball.mechanical_energy();
            for _ in 0..60 {
                world.physics_step(&[], &mut events);
                let e1 = world.ball.mechanical_energy();
                // Stop before any table contact: only the net's impulse is under test.
                if events.iter().any(|e| e.kind != ContactKind::Net) {
                    break;
                }
                assert!(
                    e1 <= e0 * (1.0 + 1e-12),
                    "{} case {i}: {e0} -> {e1}",
                    preset.name
                );
                e0 = e1;
            }
            assert!(
                matches!(events.first().map(|e| e.kind), Some(ContactKind::Net)),
                "case {i}: missed the net"
            );
        }
    }
}
