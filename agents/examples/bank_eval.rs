//! How a checkpoint returns the balls of a bank (`rally match --returns`) when each comes to a robot
//! at rest in its ready pose, against how it returns them inside rallies: a diagnosis aid for
//! whether rallies fail on the balls or on the robot's state between strokes.
//! `cargo run --release --example bank_eval -- CHECKPOINT BANK [balls]`.
use agents::checkpoint::{Checkpoint, CheckpointPlayer};
use agents::env::BallBank;
use agents::player::Player;
use sim::arena::Side;
use std::sync::Arc;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (path, bank) = (&args[0], &args[1]);
    let model = Arc::new(sim::config::default_model());
    let ck =
        Arc::new(Checkpoint::from_json(&std::fs::read_to_string(path).unwrap(), &model).unwrap());
    let balls = BallBank::parse(&std::fs::read_to_string(bank).unwrap()).unwrap();
    let n = args
        .get(2)
        .map(|s| s.parse().unwrap())
        .unwrap_or(balls.len())
        .min(balls.len());
    let preset = sim::arena::MYOCHALLENGE;
    let bounce = sim::predict::BounceModel::for_table(&preset.table);
    let config = sim::config::ArenaConfig::default();
    let results = agents::seeds::par_indexed(
        n,
        || {
            (
                sim::episode::SingleServe::new(model.clone(), &config, preset).unwrap(),
                CheckpointPlayer::new(ck.clone(), &model, bounce, 0).unwrap(),
            )
        },
        |(env, player), i| {
            env.reset_with(
                sim::serve::Serve {
                    ball: balls[i],
                    server: Side::B,
                    receiver: Side::A,
                    predicted_crossing: None,
                },
                None,
            );
            player.reseed(i as u64);
            agents::eval::play_reset_episode(env, player as &mut dyn Player)
        },
    );
    let hit = results.iter().filter(|r| r.hit).count();
    let ok = results.iter().filter(|r| r.success).count();
    println!(
        "{n} bank balls from the ready pose: hit {:.1}%, legal return {:.1}%",
        100.0 * hit as f64 / n as f64,
        100.0 * ok as f64 / n as f64
    );
    let mut ends: std::collections::BTreeMap<&str, usize> = Default::default();
    for r in &results {
        *ends.entry(r.end).or_default() += 1;
    }
    println!("ends: {ends:?}");
    println!("speed (m/s)  balls  legal return");
    for lo in [3.0, 4.0, 5.0, 5.5, 6.0, 6.5, 7.0, 8.0] {
        let hi = if lo < 5.0 {
            lo + 1.0
        } else if lo < 7.0 {
            lo + 0.5
        } else {
            lo + 1.0
        };
        let bin: Vec<bool> = (0..n)
            .filter(|&i| (lo..hi).contains(&balls[i].vel.norm()))
            .map(|i| results[i].success)
            .collect();
        if !bin.is_empty() {
            let k = bin.iter().filter(|&&s| s).count();
            println!(
                "{lo:.1}-{hi:.1}      {:5}  {:.1}%",
                bin.len(),
                100.0 * k as f64 / bin.len() as f64
            );
        }
    }
}
