//! The `myochallenge` ball world against 30 serves recorded in MuJoCo (MyoSuite 3.0 / MuJoCo 4.0,
//! `fixtures/README.md`). Each serve starts from the recorded state at t = 0 and flies, bounces once
//! on side A's half and flies on; we compare every 10 ms row.
//!
//! Acceptance (issue 2, docs/design.md §4): the path through the bounce within 2 cm of MuJoCo's, and the
//! velocity after the bounce within 3%.

use nalgebra::Vector3;
use sim::arena::MYOCHALLENGE;
use sim::{BallState, BallWorld, ContactKind};

struct Row {
    serve: usize,
    t: f64,
    pos: Vector3<f64>,
    vel: Vector3<f64>,
    contact: bool,
}

fn load() -> Vec<Vec<Row>> {
    let text = include_str!("fixtures/myosuite_serves_p1.csv");
    let mut serves: Vec<Vec<Row>> = Vec::new();
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let num = |i: usize| f[i].parse::<f64>().expect("number");
        let row = Row {
            serve: f[0].parse().expect("serve id"),
            t: num(2),
            pos: Vector3::new(num(3), num(4), num(5)),
            vel: Vector3::new(num(6), num(7), num(8)),
            contact: !f[12].is_empty(),
        };
        if serves.len() <= row.serve {
            serves.push(Vec::new());
        }
        serves[row.serve].push(row);
    }
    serves
}

struct Comparison {
    max_path_error: f64,
    max_vel_error_after: f64,
    bounce_time_error: f64,
}

fn compare(rows: &[Row]) -> Comparison {
    let start = &rows[0];
    let mut world = BallWorld::new(MYOCHALLENGE, BallState::new(start.pos, start.vel));
    let mut events = Vec::new();
    let mut max_path_error: f64 = 0.0;
    let mut max_vel_error_after: f64 = 0.0;
    let contact_rows: Vec<usize> = (0..rows.len()).filter(|&i| rows[i].contact).collect();
    let last_contact = *contact_rows.last().expect("every reference serve bounces");
    for (i, row) in rows.iter().enumerate().skip(1) {
        world.control_step(&mut [], &mut events);
        assert!((world.time - row.t).abs() < 1e-9);
        max_path_error = max_path_error.max((world.ball.pos - row.pos).norm());
        if i > last_contact {
            let rel = (world.ball.vel - row.vel).norm() / row.vel.norm();
            max_vel_error_after = max_vel_error_after.max(rel);
        }
    }
    let bounce = events
        .iter()
        .find(|e| matches!(e.kind, ContactKind::Table { .. }))
        .expect("our ball bounces too");
    // MuJoCo's first contact row is the control step whose substeps saw the contact begin.
    let first_contact_t = rows[contact_rows[0]].t;
    Comparison {
        max_path_error,
        max_vel_error_after,
        bounce_time_error: (bounce.t - first_contact_t).abs(),
    }
}

#[test]
fn thirty_reference_serves_bounce_like_mujoco() {
    let serves = load();
    assert_eq!(serves.len(), 30);
    let mut worst_path: f64 = 0.0;
    let mut worst_vel: f64 = 0.0;
    for (id, rows) in serves.iter().enumerate() {
        let c = compare(rows);
        eprintln!(
            "serve {id:2}: path error {:.4} m, velocity error after bounce {:.4}, bounce time Δ {:.4} s",
            c.max_path_error, c.max_vel_error_after, c.bounce_time_error
        );
        worst_path = worst_path.max(c.max_path_error);
        worst_vel = worst_vel.max(c.max_vel_error_after);
        assert!(
            c.bounce_time_error <= 0.0100 + 1e-9,
            "serve {id}: bounce time off by {}",
            c.bounce_time_error
        );
    }
    eprintln!("worst path error {worst_path:.4} m, worst velocity error {worst_vel:.4}");
    assert!(worst_path < 0.02, "path error {worst_path} m exceeds 2 cm");
    assert!(worst_vel < 0.03, "velocity error {worst_vel} exceeds 3%");
}

/// At every 2 ms physics step through the whole serve, bounce included: the path within 2 cm, and
/// our first-contact time inside the physics step in which MuJoCo first reported the contact.
#[test]
fn substeps_follow_mujoco_through_the_bounce() {
    let text = include_str!("fixtures/myosuite_serves_p1_substeps.csv");
    let starts = load();
    let mut by_serve: Vec<Vec<(f64, Vector3<f64>, bool)>> = vec![Vec::new(); 30];
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let num = |i: usize| f[i].parse::<f64>().expect("number");
        let id: usize = f[0].parse().expect("serve id");
        by_serve[id].push((
            num(1),
            Vector3::new(num(2), num(3), num(4)),
            !f[11].is_empty(),
        ));
    }
    let mut worst: f64 = 0.0;
    for (id, rows) in by_serve.iter().enumerate() {
        let s = &starts[id][0];
        let mut world = BallWorld::new(MYOCHALLENGE, BallState::new(s.pos, s.vel));
        let mut events = Vec::new();
        for (t, pos, _) in rows {
            world.physics_step(&[], &mut events);
            assert!((world.time - t).abs() < 1e-9);
            worst = worst.max((world.ball.pos - pos).norm());
        }
        let first = rows.iter().position(|r| r.2).expect("a contact");
        let (t_mj, _, _) = rows[first];
        let ours = events
            .iter()
            .find(|e| matches!(e.kind, ContactKind::Table { .. }))
            .expect("bounce");
        assert!(
            ours.t > t_mj - 2.0 * sim::arena::TIMESTEP - 1e-9 && ours.t <= t_mj + 1e-9,
            "serve {id}: our contact began at {}, MuJoCo saw it first at {t_mj}",
            ours.t
        );
    }
    eprintln!("worst substep path error {worst:.4} m");
    assert!(worst < 0.02, "path error {worst} m exceeds 2 cm");
}

/// The planner's drag-free prediction with the fitted bounce model, started from each serve's state at
/// t = 0, against where MuJoCo's ball crossed side A's hitting plane (interpolated between rows).
#[test]
fn prediction_finds_mujocos_hitting_plane_crossing() {
    use sim::predict::{plane_crossing, MYOCHALLENGE_BOUNCE};
    let plane = sim::Side::A.strike_plane_x();
    let mut sq = 0.0;
    let mut worst: f64 = 0.0;
    let serves = load();
    for (id, rows) in serves.iter().enumerate() {
        let k = rows
            .windows(2)
            .position(|w| w[0].pos.x < plane && w[1].pos.x >= plane)
            .expect("crosses the plane");
        let (a, b) = (&rows[k], &rows[k + 1]);
        let f = (plane - a.pos.x) / (b.pos.x - a.pos.x);
        let mujoco = a.pos + (b.pos - a.pos) * f;
        let t_mujoco = a.t + (b.t - a.t) * f;
        let c = plane_crossing(&rows[0].pos, &rows[0].vel, plane, &MYOCHALLENGE_BOUNCE)
            .expect("predicted");
        let err = (c.pos - mujoco).norm();
        assert!(
            (c.t - t_mujoco).abs() < 0.01,
            "serve {id}: crossing time {} vs {t_mujoco}",
            c.t
        );
        sq += err * err;
        worst = worst.max(err);
    }
    let rms = (sq / serves.len() as f64).sqrt();
    eprintln!("prediction at the hitting plane: rms {rms:.4} m, worst {worst:.4} m");
    assert!(rms < 0.02 && worst < 0.05, "rms {rms}, worst {worst}");
}
