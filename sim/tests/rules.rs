//! Every rule outcome, from scripted event streams and from real flights in the ball world: the net
//! clip that goes on, the edge ball, the side face, the blade's rim.

use nalgebra::{UnitQuaternion, Vector3};
use sim::arena::{self, Side, MYOCHALLENGE};
use sim::geometry::{Feature, Pose};
use sim::rules::{Call, EndReason, Failure, Referee};
use sim::{BallState, BallWorld, ContactEvent, ContactKind, Paddle};

type V3 = Vector3<f64>;

fn at(kind: ContactKind, t: f64, x: f64) -> ContactEvent {
    ContactEvent {
        kind,
        t,
        pos: V3::new(x, 0.04, 0.815),
    }
}
fn table(t: f64, x: f64) -> ContactEvent {
    at(
        ContactKind::Table {
            feature: Feature::Top,
        },
        t,
        x,
    )
}
fn paddle(t: f64, owner: Side) -> ContactEvent {
    at(ContactKind::Paddle { owner }, t, owner.sign() * 1.8)
}
fn net(t: f64) -> ContactEvent {
    at(ContactKind::Net, t, 0.0)
}
fn floor(t: f64, x: f64) -> ContactEvent {
    at(ContactKind::Floor, t, x)
}

/// Feeds events and returns the end of the rally.
fn judge(server: Side, events: &[ContactEvent]) -> (Referee, Vec<Call>) {
    let mut r = Referee::new(server);
    let calls = events.iter().filter_map(|e| r.on_contact(e)).collect();
    (r, calls)
}

fn ended(r: &Referee) -> (EndReason, Option<Side>) {
    let end = r.end().expect("rally over");
    (end.reason, end.failing_side)
}

fn failed(failure: Failure, side: Side) -> (EndReason, Option<Side>) {
    (EndReason::Failure(failure), Some(side))
}

#[test]
fn a_legal_return_then_a_miss() {
    let (r, calls) = judge(
        Side::B,
        &[
            table(0.3, 0.8),
            paddle(0.5, Side::A),
            table(0.8, -0.7),
            table(1.2, -1.0),
        ],
    );
    assert_eq!(
        calls[..3],
        [
            Call::ServeIn { t: 0.3 },
            Call::Hit {
                side: Side::A,
                t: 0.5
            },
            Call::LegalReturn {
                hitter: Side::A,
                t: 0.8
            }
        ]
    );
    assert_eq!(r.rally_length(), 1);
    assert_eq!(ended(&r), failed(Failure::Miss, Side::B));
}

#[test]
fn no_bounce_when_the_receiver_volleys() {
    let (r, _) = judge(Side::B, &[paddle(0.2, Side::A)]);
    assert_eq!(ended(&r), failed(Failure::NoBounce, Side::A));
}

#[test]
fn miss_by_floor_by_height_and_by_second_bounce() {
    let (r, _) = judge(Side::B, &[table(0.3, 0.8), floor(0.9, 2.5)]);
    assert_eq!(ended(&r), failed(Failure::Miss, Side::A));
    let mut r = Referee::new(Side::B);
    r.on_contact(&table(0.3, 0.8));
    assert!(r.on_ball_height(0.5, 0.31).is_none());
    r.on_ball_height(0.9, 0.29);
    assert_eq!(ended(&r), failed(Failure::Miss, Side::A));
    let (r, _) = judge(Side::B, &[table(0.3, 0.8), table(0.6, 1.2)]);
    assert_eq!(ended(&r), failed(Failure::Miss, Side::A));
}

#[test]
fn double_touch_own_half_net_and_out() {
    let served_in = [table(0.3, 0.8), paddle(0.5, Side::A)];
    let with = |more: &[ContactEvent]| {
        let mut all = served_in.to_vec();
        all.extend_from_slice(more);
        judge(Side::B, &all).0
    };
    assert_eq!(
        ended(&with(&[paddle(0.52, Side::A)])),
        failed(Failure::DoubleTouch, Side::A)
    );
    assert_eq!(
        ended(&with(&[table(0.7, 1.0)])),
        failed(Failure::OwnHalf, Side::A)
    );
    // Net, then the hitter's own half: OWN_HALF comes first in precedence and in time.
    assert_eq!(
        ended(&with(&[net(0.6), table(0.7, 0.3)])),
        failed(Failure::OwnHalf, Side::A)
    );
    assert_eq!(
        ended(&with(&[net(0.6), floor(0.9, 0.2)])),
        failed(Failure::Net, Side::A)
    );
    assert_eq!(
        ended(&with(&[floor(0.9, -2.5)])),
        failed(Failure::Out, Side::A)
    );
    let mut r = with(&[net(0.6)]);
    r.on_ball_height(0.9, 0.2);
    assert_eq!(ended(&r), failed(Failure::Net, Side::A));
    let mut r = with(&[]);
    r.on_ball_height(0.9, 0.2);
    assert_eq!(ended(&r), failed(Failure::Out, Side::A));
}

#[test]
fn a_net_clip_that_lands_over_is_legal_and_a_side_face_is_not_the_table() {
    let (r, calls) = judge(
        Side::B,
        &[
            table(0.3, 0.8),
            paddle(0.5, Side::A),
            net(0.6),
            table(0.8, -0.5),
        ],
    );
    assert!(calls.contains(&Call::LegalReturn {
        hitter: Side::A,
        t: 0.8
    }));
    assert!(r.end().is_none());
    let side_face = at(
        ContactKind::Table {
            feature: Feature::Side,
        },
        0.8,
        -1.38,
    );
    let (r, _) = judge(
        Side::B,
        &[
            table(0.3, 0.8),
            paddle(0.5, Side::A),
            side_face,
            floor(1.0, -1.5),
        ],
    );
    assert_eq!(ended(&r), failed(Failure::Out, Side::A));
    let edge = at(
        ContactKind::Table {
            feature: Feature::Edge,
        },
        0.8,
        -1.37,
    );
    let (r, _) = judge(Side::B, &[table(0.3, 0.8), paddle(0.5, Side::A), edge]);
    assert_eq!(r.rally_length(), 1);
}

#[test]
fn reported_failures_caps_and_nothing_after_the_end() {
    let mut r = Referee::new(Side::A);
    r.on_contact(&table(0.3, -0.8));
    r.report(Side::B, Failure::DroppedPaddle, 0.4);
    assert_eq!(ended(&r), failed(Failure::DroppedPaddle, Side::B));
    assert!(
        r.on_contact(&paddle(0.5, Side::B)).is_none(),
        "a finished rally takes no more calls"
    );
    let mut r = Referee::new(Side::A);
    r.report(Side::B, Failure::InvalidAction, 0.1);
    assert_eq!(ended(&r), failed(Failure::InvalidAction, Side::B));
    let mut r = Referee::new(Side::A);
    r.cap(9.0);
    assert_eq!(ended(&r), (EndReason::Capped, None));
    assert_eq!(EndReason::Capped.name(), "CAPPED");
    let names: Vec<_> = Failure::ALL.iter().map(|f| f.name()).collect();
    assert_eq!(
        names,
        [
            "NO_BOUNCE",
            "MISS",
            "DOUBLE_TOUCH",
            "OWN_HALF",
            "NET",
            "OUT",
            "DROPPED_PADDLE",
            "INVALID_ACTION"
        ]
    );
}

#[test]
fn serve_faults_and_long_rallies() {
    let (r, _) = judge(Side::B, &[table(0.2, -0.6)]);
    assert_eq!(ended(&r), failed(Failure::OwnHalf, Side::B));
    let mut events = vec![table(0.3, 0.8)];
    let mut t = 0.3;
    let mut hitter = Side::A;
    for _ in 0..40 {
        events.push(paddle(t + 0.1, hitter));
        events.push(table(t + 0.3, hitter.other().sign() * 0.7));
        hitter = hitter.other();
        t += 0.5;
    }
    let (mut r, _) = judge(Side::B, &events);
    assert_eq!(r.rally_length(), 40);
    assert_eq!(r.receiver(), Some(Side::A));
    r.cap(t);
    assert_eq!(ended(&r), (EndReason::Capped, None));
}

/// Runs the ball world from `ball` with optional paddles, feeding the referee, for at most `secs`.
fn play(
    referee: &mut Referee,
    ball: BallState,
    paddles: &mut [Paddle],
    secs: f64,
) -> Vec<ContactEvent> {
    let mut world = BallWorld::new(MYOCHALLENGE, ball);
    let mut all = Vec::new();
    while world.time < secs && referee.end().is_none() {
        let mut events = Vec::new();
        world.control_step(paddles, &mut events);
        for e in &events {
            referee.on_contact(e);
        }
        referee.on_ball_height(world.time, world.ball.pos.z);
        all.extend(events);
    }
    all
}

/// A referee that has seen the serve land on A's half and A's hit: the ball is A's return.
fn after_a_hit() -> Referee {
    let mut r = Referee::new(Side::B);
    r.on_contact(&table(0.0, 0.8));
    r.on_contact(&paddle(0.0, Side::A));
    r
}

/// Velocity from `start` that carries the ball centre through `target`, with horizontal velocity
/// `vh` (its z is ignored).
fn aim(start: V3, target: V3, vh: V3) -> V3 {
    let along = (target - start).xy();
    let t = along.norm() / vh.xy().norm();
    let g = arena::GRAVITY;
    V3::new(
        vh.x,
        vh.y,
        (target.z - start.z + 0.5 * g * t * (t + arena::TIMESTEP)) / t,
    )
}

#[test]
fn a_real_net_clip_goes_over_and_is_legal() {
    // The ball's bottom passes 0.5 mm below the top of the net: it clips the net's top edge.
    let z_at_net = arena::NET_TOP_Z + arena::BALL_RADIUS - 0.0005;
    let start = V3::new(0.3, 0.1, 1.0);
    let vel = aim(start, V3::new(0.0, 0.1, z_at_net), V3::new(-2.5, 0.0, 0.0));
    let mut r = after_a_hit();
    let events = play(&mut r, BallState::new(start, vel), &mut [], 1.5);
    let kinds: Vec<&str> = events.iter().map(|e| e.kind.name()).collect();
    assert!(
        kinds.len() >= 2 && kinds[..2] == ["net", "table"],
        "events {events:?}"
    );
    assert_eq!(events[1].side(), Some(Side::B));
    assert!(
        r.rally_length() == 1,
        "the clipped return counts: {:?}",
        r.end()
    );
}

#[test]
fn a_real_edge_ball_counts_and_a_real_side_face_hit_does_not() {
    // Coming down steeply just past B's end line: the first touch is the table's edge.
    let x_end = -arena::TABLE_HALF_LENGTH;
    let ball = BallState::new(V3::new(x_end - 0.012, 0.1, 1.1), V3::new(0.0, 0.0, -3.0));
    let mut r = after_a_hit();
    let events = play(&mut r, ball, &mut [], 1.0);
    assert_eq!(
        events[0].kind,
        ContactKind::Table {
            feature: Feature::Edge
        },
        "{events:?}"
    );
    assert_eq!(r.rally_length(), 1);

    // A wide, low return: it comes in from beyond the table's long side on B's half and meets that
    // side face 3 cm below the playing surface.
    let start = V3::new(-0.6, 1.2, 0.85);
    let target = V3::new(
        -0.8,
        arena::TABLE_Y_MAX + arena::BALL_RADIUS,
        arena::TABLE_TOP_Z - 0.03,
    );
    let vel = aim(start, target, V3::new(-1.0, -2.0, 0.0));
    let mut r = after_a_hit();
    let events = play(&mut r, BallState::new(start, vel), &mut [], 2.0);
    let first_table = events
        .iter()
        .find(|e| e.kind.name() == "table")
        .expect("hits the table");
    assert_eq!(
        first_table.kind,
        ContactKind::Table {
            feature: Feature::Side
        },
        "{events:?}"
    );
    assert_eq!(
        r.end().map(|e| (e.reason, e.failing_side)),
        Some(failed(Failure::Out, Side::A))
    );
}

#[test]
fn a_hit_on_the_blades_rim_is_a_hit() {
    // Blade facing +x (towards the incoming ball); the ball flies along x at the height of the rim's
    // top so it meets the rim, not the face.
    let rot = UnitQuaternion::rotation_between(&V3::z(), &V3::x()).unwrap();
    let pose = Pose {
        pos: V3::new(1.8, 0.04, 1.0),
        rot,
    };
    let paddle = Paddle::at_rest(Side::A, pose);
    let blade_centre = pose.to_world(&paddle.shape.blade.center);
    let mut r = Referee::new(Side::B);
    r.on_contact(&table(0.0, 0.8));
    // Aim the ball so its centre passes 1 cm beyond the rim (outside the disc) at the face's plane.
    let rim_top = blade_centre.z + sim::geometry::PaddleShape::standard().blade.radius + 0.01;
    let start = V3::new(1.2, 0.04, 1.2);
    let vel = aim(
        start,
        V3::new(blade_centre.x, 0.04, rim_top),
        V3::new(5.0, 0.0, 0.0),
    );
    let events = play(&mut r, BallState::new(start, vel), &mut [paddle], 0.5);
    let hit = events
        .iter()
        .find(|e| e.kind.name() == "paddle")
        .expect("the rim is hit");
    let local = pose.to_local(&hit.pos) - paddle.shape.blade.center;
    assert!(
        local.xy().norm() > sim::geometry::PaddleShape::standard().blade.radius,
        "the centre was beyond the rim: {local:?}"
    );
    assert!(matches!(hit.kind, ContactKind::Paddle { owner: Side::A }));
}
