//! Fits the planner's bounce model (`predict::MYOCHALLENGE_BOUNCE`: C_h, C_v and the equivalent
//! bounce height) to the `myochallenge` soft table, by least squares on where 400 seeded P2 serves
//! cross side A's hitting plane. Run: `cargo run --release -p sim --example fit_bounce`.

use nalgebra::Vector3;
use sim::arena::{Side, MYOCHALLENGE};
use sim::predict::{plane_crossing, BounceModel, MYOCHALLENGE_BOUNCE};
use sim::rng::Rng;
use sim::serve::{generate, ServeKind};
use sim::BallWorld;

/// Simulated crossing of x = 1.8 (linear interpolation inside the physics step).
fn simulated_crossing(serve: &sim::BallState) -> Option<Vector3<f64>> {
    let mut world = BallWorld::new(MYOCHALLENGE, *serve);
    let mut events = Vec::new();
    let plane = Side::A.strike_plane_x();
    for _ in 0..2000 {
        let before = world.ball.pos;
        world.physics_step(&[], &mut events);
        let after = world.ball.pos;
        if before.x < plane && after.x >= plane {
            let f = (plane - before.x) / (after.x - before.x);
            return Some(before + (after - before) * f);
        }
    }
    None
}

fn main() {
    let mut rng = Rng::seeded(2024);
    let mut cases = Vec::new();
    while cases.len() < 400 {
        let s = generate(ServeKind::P2, &mut rng, &MYOCHALLENGE_BOUNCE);
        if let Some(c) = simulated_crossing(&s.ball) {
            cases.push((s.ball, c));
        }
    }
    let cost = |m: &BounceModel| -> (f64, f64) {
        let mut sum = 0.0;
        let mut worst: f64 = 0.0;
        for (ball, target) in &cases {
            let e = match plane_crossing(&ball.pos, &ball.vel, Side::A.strike_plane_x(), m) {
                Some(c) => (c.pos - target).norm(),
                None => 1.0,
            };
            sum += e * e;
            worst = worst.max(e);
        }
        ((sum / cases.len() as f64).sqrt(), worst)
    };
    let mut best = MYOCHALLENGE_BOUNCE;
    let mut best_cost = cost(&best).0;
    let mut step = [0.01, 0.02, 0.004];
    for _ in 0..60 {
        let mut improved = false;
        for k in 0..3 {
            for dir in [-1.0, 1.0] {
                let mut m = best;
                match k {
                    0 => m.c_h += dir * step[0],
                    1 => m.c_v += dir * step[1],
                    _ => m.contact_z += dir * step[2],
                }
                let c = cost(&m).0;
                if c < best_cost {
                    best = m;
                    best_cost = c;
                    improved = true;
                }
            }
        }
        if !improved {
            for s in &mut step {
                *s *= 0.5;
            }
        }
    }
    let (rms, worst) = cost(&best);
    println!(
        "c_h = {:.4}, c_v = {:.4}, contact_z = {:.4}: rms {:.4} m, worst {:.4} m over {} serves",
        best.c_h,
        best.c_v,
        best.contact_z,
        rms,
        worst,
        cases.len()
    );
    let (rms0, worst0) = cost(&MYOCHALLENGE_BOUNCE);
    println!("current constants: rms {rms0:.4} m, worst {worst0:.4} m");
}
