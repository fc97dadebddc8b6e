//! Evaluates the scripted agent with parameters overridden on the command line, e.g.
//! `cargo run --release -p agents --example tune -- kp=40 kd=3 lead=0.03` (a tuning aid; the
//! defaults it starts from are `ScriptedParams::default()`).
use agents::eval::{evaluate, Evaluation};
use agents::factory::PlayerSpec;
use agents::scripted::ScriptedParams;
use sim::serve::ServeKind;
use std::sync::Arc;
fn main() {
    let mut p = ScriptedParams::default();
    let mut episodes = 200;
    let mut seed = 1;
    for arg in std::env::args().skip(1) {
        let (k, v) = arg.split_once('=').expect("key=value");
        let x: f64 = v.parse().expect("number");
        match k {
            "kp" => p.gains.kp = x,
            "kd" => p.gains.kd = x,
            "lead" => p.lead = x,
            "swing" => p.swing_time = x,
            "back" => p.backswing = x,
            "grip" => p.grip_target = x,
            "floor" => p.grip_activation = Some(x),
            "okp" => p.outer_kp = x,
            "oki" => p.outer_ki = x,
            "ff" => p.gravity_feedforward = x != 0.0,
            "drive" => p.drive = x != 0.0,
            "cand" => p.candidates = x as usize,
            "episodes" => episodes = x as usize,
            "seed" => seed = x as u64,
            _ => panic!("unknown parameter {k}"),
        }
    }
    // RALLY_MYOCHALLENGE: the imported MyoChallenge robot's file, to tune on it instead.
    let (model, config) = match std::env::var_os("RALLY_MYOCHALLENGE") {
        Some(path) => (
            sim::mjcf::load(std::path::Path::new(&path), &|p| std::fs::read_to_string(p)).unwrap(),
            sim::config::ArenaConfig::myochallenge(),
        ),
        None => (
            sim::config::default_model(),
            sim::config::ArenaConfig::default(),
        ),
    };
    let e = Evaluation {
        lead_in: false,
        model: Arc::new(model),
        config,
        preset: sim::arena::MYOCHALLENGE,
        kind: ServeKind::P2,
        episodes,
        seed,
    };
    let r = evaluate(
        &e,
        &PlayerSpec::Scripted {
            name: "tune".into(),
            params: p,
        },
        &|| {},
    )
    .unwrap();
    let ends: Vec<String> = r.ends.iter().map(|(e, n)| format!("{e} {n}")).collect();
    println!(
        "hit {:.3} success {:.3} activation {:.3} | {}",
        r.hit_rate.value,
        r.success_rate.value,
        r.mean_activation.value,
        ends.join(", ")
    );
}
