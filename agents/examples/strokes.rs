//! Where a checkpoint's strokes go wrong: for each single-serve episode with a hit, the planned
//! outgoing ball velocity against the one the paddle produced, the predicted landing of each, and
//! the paddle at the contact step against the command: the blade centre's distance from the strike
//! point, the paddle frame origin's velocity (what the reward's velocity term sees) and the blade
//! centre's against the racket's, and the angle between the blade's normal (either face) and the
//! planned one. All in the robot's frame. A diagnosis aid: `cargo run --release --example strokes
//! -- CHECKPOINT [p2|rally] [episodes] [seed]` (`RALLY_MODEL=FILE` for another robot).
mod common;

use agents::player::Player;
use nalgebra::Vector3;
use sim::events::ContactKind;
use sim::predict::{self, BounceModel};
use sim::rng::Rng;
use sim::serve::ServeKind;

fn landing(pos: &Vector3<f64>, vel: &Vector3<f64>, m: &BounceModel) -> Option<Vector3<f64>> {
    predict::next_bounce(pos, vel, m).map(|b| b.pos)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args.first().expect("checkpoint file");
    let kind = match args.get(1).map(String::as_str).unwrap_or("rally") {
        "p2" => ServeKind::P2,
        _ => ServeKind::Rally {
            server: sim::arena::Side::B,
        },
    };
    let episodes: usize = common::arg(&args, 2, 200);
    let seed: u64 = common::arg(&args, 3, 4242);
    let bench = common::Bench::load(path);
    let bounce = bench.bounce;
    let mut env = bench.single();
    let mut player = bench.player();
    let model = bench.model.clone();
    println!("end,plan_vx,plan_vy,plan_vz,act_vx,act_vy,act_vz,plan_land_x,plan_land_y,act_land_x,act_land_y,blade_err_pos,pad_vx,pad_vy,pad_vz,rkt_vx,rkt_vy,rkt_vz,normal_err_deg,blade_vx,blade_vy,blade_vz");
    for i in 0..episodes {
        let (serve_seed, agent_seed) = agents::seeds::episode_seeds(seed, i);
        env.reset(kind, &mut Rng::seeded(serve_seed), None);
        player.reseed(agent_seed);
        let mut ctrl = vec![0.0; model.actuators.len()];
        let mut row: Option<String> = None;
        loop {
            if !common::act(&mut player, &mut env, &mut ctrl) {
                break;
            }
            let plan = player.command().map(|(p, _)| *p);
            let pad_v = env.robot.paddle.lin_vel;
            let (pad_p, pad_n) = agents::env::reward::blade(&env.robot);
            // The blade centre's velocity: the paddle frame origin's plus the rotation's share.
            let m = &env.robot.paddle;
            let blade_v = m.lin_vel + m.ang_vel.cross(&(pad_p - m.pose.pos));
            let rep = env.step();
            let hit = rep
                .events
                .iter()
                .any(|e| matches!(e.kind, ContactKind::Paddle { .. }));
            if hit && row.is_none() {
                if let Some(p) = plan {
                    let f = env.robot.frame;
                    let v = f.vector_from_world(&env.world.ball.vel);
                    let x = f.point_from_world(&env.world.ball.pos);
                    let pl = landing(&p.strike_pos, &p.v_out, &bounce).unwrap_or_default();
                    let al = landing(&x, &v, &bounce).unwrap_or_default();
                    let pv = f.vector_from_world(&pad_v);
                    let bv = f.vector_from_world(&blade_v);
                    let pp = f.point_from_world(&pad_p);
                    let n = f.vector_from_world(&pad_n);
                    let u = p.racket_quat * Vector3::z();
                    let angle = n.dot(&u).abs().min(1.0).acos().to_degrees();
                    row = Some(format!(
                        "{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.1},{:.3},{:.3},{:.3}",
                        p.v_out.x, p.v_out.y, p.v_out.z, v.x, v.y, v.z, pl.x, pl.y, al.x, al.y,
                        (pp - p.strike_pos).norm(), pv.x, pv.y, pv.z, p.racket_vel.x, p.racket_vel.y, p.racket_vel.z, angle, bv.x, bv.y, bv.z
                    ));
                }
            }
            if rep.done {
                break;
            }
        }
        let end = agents::eval::end_name(&env);
        if let Some(r) = row {
            println!("{end},{r}");
        }
    }
}
