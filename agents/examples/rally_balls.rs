//! What the balls of a self-play rally look like to their receiver: for every ball (the serve and
//! each return) its spin, the planner's spin-free prediction of its bounce against the real bounce,
//! and whether the receiver returned it. A diagnosis aid:
//! `cargo run --release --example rally_balls -- CHECKPOINT [rallies] [seed] > balls.csv`.
mod common;

use agents::player::Player;
use nalgebra::Vector3;
use sim::arena::Side;
use sim::episode::Rally;
use sim::events::ContactKind;
use sim::predict;
use sim::rng::Rng;

type V3 = Vector3<f64>;

/// One ball in flight towards its receiver.
struct Ball {
    index: u32,
    /// State a few control steps after it left the hitter (the serve: at the start).
    pos: V3,
    vel: V3,
    spin: V3,
    predicted: Option<predict::Bounce>,
    bounce_pos: Option<V3>,
    vel_after: Option<V3>,
    length_before: u32,
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args.first().expect("checkpoint file");
    let rallies: u32 = common::arg(&args, 1, 100);
    let seed: u64 = common::arg(&args, 2, 4242);
    let bench = common::Bench::load(path);
    let (model, bounce) = (bench.model.clone(), bench.bounce);
    let mut rally = Rally::new(model.clone(), &bench.config, bench.preset).unwrap();
    let mut players = [bench.player(), bench.player()];
    println!("rally,index,spin_x,spin_y,spin_z,speed,cross_y,cross_z,bounce_err,pred_vx,pred_vz,real_vx,real_vz,returned");
    let mut ctrl = vec![0.0; model.actuators.len()];
    for k in 0..rallies {
        let server = if k % 2 == 0 { Side::A } else { Side::B };
        let (serve_seed, agent_seed) = agents::seeds::episode_seeds(seed, k as usize);
        rally.reset(server, &mut Rng::seeded(serve_seed), None);
        for (i, p) in players.iter_mut().enumerate() {
            p.reset();
            p.reseed(agent_seed.wrapping_add(i as u64));
        }
        let balls = play(&mut rally, &mut players, &mut ctrl, &bounce);
        let final_len = rally.referee.rally_length();
        for b in balls {
            print_ball(k, &b, final_len, &bounce);
        }
    }
}

/// The ball in flight now, numbered `index` (0: the serve).
fn snap(r: &Rally, index: u32, bounce: &predict::BounceModel) -> Ball {
    let b = r.arena.world.ball;
    Ball {
        index,
        pos: b.pos,
        vel: b.vel,
        spin: b.spin,
        predicted: predict::next_bounce(&b.pos, &b.vel, bounce),
        bounce_pos: None,
        vel_after: None,
        length_before: r.referee.rally_length(),
    }
}

/// Plays the rally to its end; returns its balls in order, each with its bounce and the velocity
/// just after it.
fn play(
    rally: &mut Rally,
    players: &mut [agents::checkpoint::CheckpointPlayer; 2],
    ctrl: &mut [f64],
    bounce: &predict::BounceModel,
) -> Vec<Ball> {
    let mut ball = Some(snap(rally, 0, bounce));
    let mut since_hit: Option<usize> = None;
    let mut after_bounce = false;
    let mut strokes = 0u32;
    let mut done = Vec::new();
    loop {
        for (i, p) in players.iter_mut().enumerate() {
            let robot = &rally.arena.robots[i];
            ctrl.copy_from_slice(&robot.state.ctrl);
            let b = rally.arena.world.ball;
            if p.act(robot, &b, rally.arena.world.time, ctrl).is_ok() {
                rally.arena.robots[i].state.ctrl.copy_from_slice(ctrl);
            }
        }
        let rep = rally.step();
        if after_bounce {
            if let Some(b) = ball.as_mut() {
                b.vel_after = Some(rally.arena.world.ball.vel);
            }
            after_bounce = false;
        }
        for e in &rep.events {
            match e.kind {
                ContactKind::Paddle { .. } if since_hit.is_none() => {
                    since_hit = Some(0);
                    if let Some(b) = ball.take() {
                        done.push(b);
                    }
                }
                ContactKind::Table { .. } if e.is_bounce() => {
                    if let Some(b) = ball.as_mut() {
                        if b.bounce_pos.is_none() {
                            b.bounce_pos = Some(e.pos);
                            after_bounce = true;
                        }
                    }
                }
                _ => {}
            }
        }
        if let Some(n) = since_hit.as_mut() {
            *n += 1;
            if *n == agents::env::TASK_DELAY_STEPS + 2 {
                strokes += 1;
                ball = Some(snap(rally, strokes, bounce));
                since_hit = None;
            }
        }
        if rep.done {
            break;
        }
    }
    if let Some(b) = ball.take() {
        done.push(b);
    }
    done
}

/// One CSV row: ball `b` of rally `k`, which ended at rally length `final_len`.
fn print_ball(k: u32, b: &Ball, final_len: u32, bounce: &predict::BounceModel) {
    let returned = final_len > b.length_before + u32::from(b.index > 0);
    let err = match (&b.predicted, &b.bounce_pos) {
        (Some(p), Some(a)) => (p.pos - a).norm(),
        _ => f64::NAN,
    };
    let (pvx, pvz) = b
        .predicted
        .as_ref()
        .map(|p| (p.vel_out.x.abs(), p.vel_out.z))
        .unwrap_or((f64::NAN, f64::NAN));
    let (rvx, rvz) = b
        .vel_after
        .map(|v| (v.x.abs(), v.z))
        .unwrap_or((f64::NAN, f64::NAN));
    let plane = if b.vel.x > 0.0 { 1.0 } else { -1.0 } * sim::arena::STRIKE_PLANE_X;
    let (cy, cz) = predict::plane_crossing(&b.pos, &b.vel, plane, bounce)
        .map(|c| (c.pos.y * plane.signum(), c.pos.z))
        .unwrap_or((f64::NAN, f64::NAN));
    println!(
        "{k},{},{:.1},{:.1},{:.1},{:.2},{cy:.3},{cz:.3},{:.4},{:.3},{:.3},{:.3},{:.3},{}",
        b.index,
        b.spin.x,
        b.spin.y,
        b.spin.z,
        b.vel.norm(),
        err,
        pvx,
        pvz,
        rvx,
        rvz,
        u8::from(returned)
    );
}
