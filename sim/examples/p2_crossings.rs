//! Where P2 serves cross side A's hitting plane (predicted), and when: the scripted agent's ready pose
//! sits near the middle of this distribution.
use sim::predict::{plane_crossing, MYOCHALLENGE_BOUNCE};
use sim::rng::Rng;
use sim::serve::{generate, ServeKind};
fn main() {
    let mut rng = Rng::seeded(1);
    let mut v: Vec<(f64, f64, f64)> = Vec::new();
    for _ in 0..2000 {
        let s = generate(ServeKind::P2, &mut rng, &MYOCHALLENGE_BOUNCE);
        if let Some(c) = plane_crossing(&s.ball.pos, &s.ball.vel, 1.8, &MYOCHALLENGE_BOUNCE) {
            v.push((c.pos.y, c.pos.z, c.t));
        }
    }
    let q = |k: usize| {
        let mut x: Vec<f64> = v.iter().map(|p| [p.0, p.1, p.2][k]).collect();
        x.sort_by(|a, b| a.total_cmp(b));
        (x[x.len() / 20], x[x.len() / 2], x[x.len() * 19 / 20])
    };
    println!(
        "{} of 2000 cross x = 1.8; y 5/50/95%: {:.2?}; z: {:.2?}; t: {:.2?}",
        v.len(),
        q(0),
        q(1),
        q(2)
    );
}
