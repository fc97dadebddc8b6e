//! The grip and the dual arena: a squeezing hand keeps the paddle, a limp one drops it, a weak one
//! lets a hard ball knock it out and can catch it again; robot B is robot A turned about (0, 0.04).

use std::sync::Arc;

use nalgebra::Vector3;
use sim::arena::{Side, MYOCHALLENGE};
use sim::config::{ArenaConfig, DEFAULT_MODEL_XML};
use sim::dual::DualArena;
use sim::robot::{GripEvent, GripPhase, Robot};
use sim::{BallState, ContactKind};

type V3 = Vector3<f64>;

fn model() -> Arc<sim::model::Model> {
    Arc::new(sim::config::default_model())
}

fn ready(model: &sim::model::Model) -> Vec<f64> {
    model
        .keyframes
        .iter()
        .find(|k| k.name == "ready")
        .expect("ready keyframe")
        .qpos
        .clone()
}

fn robot(grip_ctrl: f64) -> Robot {
    let m = model();
    let cfg = ArenaConfig::default();
    let mut r = Robot::new(m.clone(), &cfg.grip, Side::A).expect("robot");
    r.reset(Some(&ready(&m)));
    // The hand already squeezes at the start (activation = control).
    for name in &cfg.grip.muscles {
        let a = m.actuator(name).unwrap();
        r.state.ctrl[a] = grip_ctrl;
        r.state.act[a] = grip_ctrl;
    }
    // Hold the pelvis where it is.
    r.state.ctrl[m.actuator("pelvis_tx_servo").unwrap()] = 0.0;
    r.state.ctrl[m.actuator("pelvis_ty_servo").unwrap()] = 0.0;
    r
}

fn far_ball() -> BallState {
    BallState::new(V3::new(0.0, 3.0, 3.0), V3::zeros())
}

#[test]
fn a_squeezing_hand_keeps_the_paddle_while_the_arm_falls() {
    let mut r = robot(1.0);
    for _ in 0..250 {
        let e = r.physics_step();
        assert!(e.is_none(), "grip event {e:?} at capacity {}", r.capacity);
    }
    assert_eq!(r.phase, GripPhase::Held);
    assert!(r.capacity > 100.0, "capacity {}", r.capacity);
}

#[test]
fn a_limp_hand_lets_the_paddle_slip_and_drop() {
    let mut r = robot(0.0);
    let mut events = Vec::new();
    for _ in 0..250 {
        if let Some(e) = r.physics_step() {
            events.push(e);
        }
    }
    assert!(
        matches!(events.first(), Some(GripEvent::Slipped { .. })),
        "{events:?}"
    );
    assert_eq!(events.last(), Some(&GripEvent::Dropped));
    assert_eq!(r.phase, GripPhase::Dropped);
}

#[test]
fn a_slipping_paddle_is_regained_by_a_quick_squeeze() {
    let mut r = robot(0.0);
    let slipped = (0..10).any(|_| matches!(r.physics_step(), Some(GripEvent::Slipped { .. })));
    assert!(slipped);
    let m = model();
    for name in ["FDS", "FDP", "FPL"] {
        r.state.ctrl[m.actuator(name).unwrap()] = 1.0;
    }
    let regained = (0..40).any(|_| r.physics_step() == Some(GripEvent::Regained));
    assert!(regained, "phase {:?}, capacity {}", r.phase, r.capacity);
    assert_eq!(r.phase, GripPhase::Held);
}

/// A ball fired at the blade's centre along its normal, at `speed`, with the grip at `grip_ctrl`.
fn hit_paddle(grip_ctrl: f64, speed: f64) -> (Vec<GripEvent>, bool) {
    let m = model();
    let cfg = ArenaConfig::default();
    let mut arena = DualArena::new(m.clone(), &cfg, MYOCHALLENGE, far_ball()).unwrap();
    for r in arena.robots.iter_mut() {
        r.reset(Some(&ready(&m)));
        for name in &cfg.grip.muscles {
            let a = m.actuator(name).unwrap();
            r.state.ctrl[a] = grip_ctrl;
            r.state.act[a] = grip_ctrl;
        }
    }
    // Settle, then fire from 10 cm in front of the blade.
    let mut events = Vec::new();
    for _ in 0..20 {
        let [a, _] = arena.physics_step(&mut events);
        assert!(
            a.is_none(),
            "the grip at {grip_ctrl} must hold the paddle at rest: {a:?}"
        );
    }
    let paddle = arena.robots[0].ball_paddle();
    let centre = paddle.pose.to_world(&paddle.shape.blade.center);
    let normal = paddle.pose.rot * V3::z();
    let start = centre + normal * 0.12;
    arena.world.ball = BallState::new(start, -normal * speed);
    let mut grip = Vec::new();
    let mut hit = false;
    for _ in 0..50 {
        events.clear();
        for (side, e) in arena.control_step(&mut events) {
            if side == Side::A {
                grip.push(e);
            }
        }
        hit |= events
            .iter()
            .any(|e| e.kind == ContactKind::Paddle { owner: Side::A });
    }
    (grip, hit)
}

#[test]
fn a_firm_grip_takes_a_hard_ball_and_a_weak_one_is_knocked_out() {
    let (grip, hit) = hit_paddle(1.0, 30.0);
    assert!(hit);
    assert!(
        !grip.iter().any(|e| matches!(e, GripEvent::Slipped { .. })),
        "{grip:?}"
    );
    let (grip, hit) = hit_paddle(0.03, 30.0);
    assert!(hit);
    assert!(
        matches!(grip.first(), Some(GripEvent::Slipped { required, capacity }) if required > capacity),
        "{grip:?}"
    );
    // Knocked away faster than the hand can catch it, it is gone.
    assert_eq!(grip.last(), Some(&GripEvent::Dropped), "{grip:?}");
}

#[test]
fn robot_b_is_robot_a_turned_about_the_table_centre_line() {
    let m = model();
    let cfg = ArenaConfig::default();
    let mut arena = DualArena::new(m.clone(), &cfg, MYOCHALLENGE, far_ball()).unwrap();
    for r in arena.robots.iter_mut() {
        r.reset(Some(&ready(&m)));
        r.state.ctrl.iter_mut().for_each(|c| *c = 0.3);
    }
    let mut events = Vec::new();
    for _ in 0..30 {
        arena.control_step(&mut events);
        let (a, b) = (arena.robots[0].ball_paddle(), arena.robots[1].ball_paddle());
        let mirrored = V3::new(-a.pose.pos.x, 0.08 - a.pose.pos.y, a.pose.pos.z);
        assert!(
            (b.pose.pos - mirrored).norm() < 1e-12,
            "A {} B {}",
            a.pose.pos,
            b.pose.pos
        );
        assert!((b.lin_vel - V3::new(-a.lin_vel.x, -a.lin_vel.y, a.lin_vel.z)).norm() < 1e-12);
        assert_eq!(arena.robots[0].state, arena.robots[1].state);
    }
    // A stands behind side A's end of the table, B behind side B's.
    assert!(
        arena.robots[0].ball_paddle().pose.pos.x > 1.37
            && arena.robots[1].ball_paddle().pose.pos.x < -1.37
    );
}

#[test]
fn the_paddle_the_ball_meets_is_the_models() {
    // The default model's blade and handle, as the ball world sees them.
    let m = model();
    let r = Robot::new(m.clone(), &ArenaConfig::default().grip, Side::A).unwrap();
    let shape = r.ball_paddle().shape;
    assert_eq!(shape, sim::geometry::PaddleShape::standard());
    assert_eq!((shape.blade.radius, shape.blade.half_length), (0.093, 0.02));
    assert_eq!(shape.blade.center, Vector3::new(-0.07, 0.0, 0.0));
    assert_eq!((shape.handle.radius, shape.handle.axis), (0.016, 0));
    // Edit the model's blade: the ball world's paddle changes with it.
    let bigger = DEFAULT_MODEL_XML.replace(
        r#"<geom name="blade" type="cylinder" size="0.093 0.02""#,
        r#"<geom name="blade" type="cylinder" size="0.12 0.01""#,
    );
    assert_ne!(bigger, DEFAULT_MODEL_XML, "the edit applies");
    let m2 = Arc::new(sim::mjcf::parse_str(&bigger, "bigger.xml").unwrap());
    let r2 = Robot::new(m2, &ArenaConfig::default().grip, Side::B).unwrap();
    let s2 = r2.ball_paddle().shape;
    assert_eq!((s2.blade.radius, s2.blade.half_length), (0.12, 0.01));
    // A model whose paddle has no blade is refused, naming the geom.
    let bladeless = DEFAULT_MODEL_XML.replace(r#"name="blade""#, r#"name="plate""#);
    let m3 = Arc::new(sim::mjcf::parse_str(&bladeless, "bladeless.xml").unwrap());
    let e = Robot::new(m3, &ArenaConfig::default().grip, Side::A).unwrap_err();
    assert!(e.contains("no geom named 'blade'"), "{e}");
}
