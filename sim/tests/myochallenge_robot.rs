//! MyoSuite's MyoChallenge robot in the arena: its grip holds the paddle, the dual arena steps it.
//! Runs when `RALLY_MYOCHALLENGE` names the file `rally model import myosuite` wrote (`.ci/run` sets
//! it); otherwise it says why it did not run.

use std::path::Path;
use std::sync::Arc;

use sim::arena::{Side, MYOCHALLENGE};
use sim::config::ArenaConfig;
use sim::robot::{GripPhase, Robot};

fn imported() -> Option<Arc<sim::model::Model>> {
    let Some(path) = std::env::var_os("RALLY_MYOCHALLENGE") else {
        eprintln!(
            "not run: set RALLY_MYOCHALLENGE to the file `rally model import myosuite` wrote"
        );
        return None;
    };
    let model = sim::mjcf::load(Path::new(&path), &|p| std::fs::read_to_string(p))
        .unwrap_or_else(|e| panic!("{e}"));
    Some(Arc::new(model))
}

fn keyframe(model: &sim::model::Model) -> Vec<f64> {
    model
        .keyframes
        .first()
        .expect("MyoSuite's keyframe")
        .qpos
        .clone()
}

/// Holds the pelvis servos at the keyframe's position.
fn hold_servos(robot: &mut Robot) {
    let model = robot.held_model().clone();
    for (i, a) in model.actuators.iter().enumerate() {
        if let sim::model::Transmission::Joint(j) = a.transmission {
            let q = robot.state.qpos[model.joints[j].qpos_adr];
            robot.state.ctrl[i] = a.ctrlrange.map_or(q, |[lo, hi]| q.clamp(lo, hi));
        }
    }
}

#[test]
fn the_hand_holds_the_paddle_at_rest_and_drops_it_when_relaxed() {
    let Some(model) = imported() else { return };
    let config = ArenaConfig::myochallenge();
    let mut robot = Robot::new(model.clone(), &config.grip, Side::A)
        .expect("the grip's bodies and muscles exist");
    let key = keyframe(&model);
    robot.reset(Some(&key));
    hold_servos(&mut robot);
    // One second from the keyframe, only the grip muscles on (at their starting activation).
    let mut least: f64 = f64::INFINITY;
    for _ in 0..500 {
        assert!(robot.physics_step().is_none(), "the grip let go");
        least = least.min(robot.capacity);
    }
    assert_eq!(robot.phase, GripPhase::Held);
    assert!(robot.state.qpos.iter().all(|q| q.is_finite()));
    // The paddle weighs 0.15 kg: the flexors at half activation hold far more than its weight.
    eprintln!("grip capacity over 1 s at rest: at least {least:.1} N");
    assert!(least > 10.0 * 0.15 * 9.81, "capacity {least} N");
    // A hand that lets go drops the paddle.
    robot.reset(Some(&key));
    hold_servos(&mut robot);
    for &m in robot.grip_muscles().to_vec().iter() {
        robot.state.act[m] = 0.0;
        robot.state.ctrl[m] = 0.0;
    }
    let dropped = (0..500).any(|_| robot.physics_step().is_some());
    assert!(
        dropped && robot.phase != GripPhase::Held,
        "a relaxed hand kept the paddle"
    );
}

#[test]
fn the_dual_arena_steps_two_myochallenge_robots() {
    let Some(model) = imported() else { return };
    let config = ArenaConfig::myochallenge();
    let ball = sim::BallState::new(
        nalgebra::Vector3::new(-1.2, -0.45, 1.45),
        nalgebra::Vector3::new(5.6, 1.6, 0.1),
    );
    let mut arena =
        sim::dual::DualArena::new(model.clone(), &config, MYOCHALLENGE, ball).expect("arena");
    let key = keyframe(&model);
    for r in arena.robots.iter_mut() {
        r.reset(Some(&key));
        hold_servos(r);
    }
    let mut events = Vec::new();
    for _ in 0..50 {
        arena.control_step(&mut events);
    }
    for r in &arena.robots {
        assert!(r.state.qpos.iter().all(|q| q.is_finite()));
        assert_eq!(r.phase, GripPhase::Held);
    }
}
