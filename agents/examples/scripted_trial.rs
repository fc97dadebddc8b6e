//! Plays P2 serves with the scripted agent and prints hit and success rates (development aid;
//! `rally eval scripted` is the real evaluation).
use agents::scripted::{Scripted, ScriptedParams};
use sim::arena::MYOCHALLENGE;
use sim::config::{ArenaConfig, DEFAULT_MODEL_XML};
use sim::episode::SingleServe;
use sim::predict::BounceModel;
use sim::rng::Rng;
use sim::serve::ServeKind;
use std::sync::Arc;

fn main() {
    let n: usize = std::env::args()
        .nth(1)
        .map(|s| s.parse().unwrap())
        .unwrap_or(40);
    let model = Arc::new(sim::mjcf::parse_str(DEFAULT_MODEL_XML, "u.xml").unwrap());
    let cfg = ArenaConfig::default();
    let mut env = SingleServe::new(model.clone(), &cfg, MYOCHALLENGE).unwrap();
    let paddle = model.body("paddle").unwrap();
    let mut params = ScriptedParams::default();
    if let Some(v) = std::env::args().nth(2) {
        params.gains.kp = v.parse().unwrap();
    }
    if let Some(v) = std::env::args().nth(3) {
        params.gains.kd = v.parse().unwrap();
    }
    if let Some(v) = std::env::args().nth(4) {
        params.lead = v.parse().unwrap();
    }
    if let Some(v) = std::env::args().nth(5) {
        params.swing_time = v.parse().unwrap();
    }
    if let Some(v) = std::env::args().nth(6) {
        params.grip_target = v.parse().unwrap();
    }
    if let Some(v) = std::env::args().nth(7) {
        params.outer_ki = v.parse().unwrap();
    }
    if let Some(v) = std::env::args().nth(8) {
        params.backswing = v.parse().unwrap();
    }
    if let Some(v) = std::env::args().nth(9) {
        params.grip_activation = Some(v.parse().unwrap());
    }
    let mut agent = Scripted::new(
        &model,
        paddle,
        params,
        BounceModel::for_table(&MYOCHALLENGE.table),
        7,
    );
    let mut rng = Rng::seeded(3);
    let (mut hits, mut wins) = (0, 0);
    let mut reasons = std::collections::BTreeMap::new();
    let mut ctrl = vec![0.0; model.actuators.len()];
    let verbose = std::env::var_os("TRIAL_VERBOSE").is_some();
    for _ in 0..n {
        env.reset(ServeKind::P2, &mut rng, None);
        agent.reset();
        let mut best = (f64::INFINITY, 0.0, [0.0; 3]);
        loop {
            ctrl.copy_from_slice(&env.robot.state.ctrl);
            agent.act(&env.robot, &env.world.ball, env.world.time, &mut ctrl);
            env.robot.state.ctrl.copy_from_slice(&ctrl);
            let done = env.step().done;
            let p = env.robot.ball_paddle();
            let c = p.pose.to_world(&p.shape.blade.center);
            let d = env.world.ball.pos - c;
            // In the blade frame: z along the normal, x/y in its plane.
            let local = p.pose.rot.inverse() * d;
            if d.norm() < best.0 {
                best = (d.norm(), env.world.time, [local.x, local.y, local.z]);
            }
            if done {
                break;
            }
        }
        if verbose {
            let inplane = (best.2[0] * best.2[0] + best.2[1] * best.2[1]).sqrt();
            println!("closest {:.3} m at t {:.2}: in-plane {:.3} normal {:+.3} | hit {} success {} {:?} ball vel after {:.2?}", best.0, best.1, inplane, best.2[2], env.hit, env.success, env.referee.end().map(|e| e.reason.name()), env.world.ball.vel.as_slice());
        }
        hits += env.hit as u32;
        wins += env.success as u32;
        let r = env
            .referee
            .end()
            .map(|e| e.reason.name())
            .unwrap_or(if env.success { "SUCCESS" } else { "TIME" });
        *reasons.entry(r).or_insert(0) += 1;
    }
    println!(
        "hit {:.2} success {:.2} {:?}",
        hits as f64 / n as f64,
        wins as f64 / n as f64,
        reasons
    );
}
