//! PPO in the dual-rally environment (self-play, both robots on one policy): the serve-box term is
//! paid once the policy can return balls (a warm start from the committed single-serve run earns it,
//! the untrained policy does not). Resuming a rally run is tested with the single-serve one in `ppo.rs`.

use std::sync::Arc;

use agents::ppo::store::RunDir;
use agents::ppo::trainer::Trainer;
use agents::ppo::{Method, TrainConfig, TrainEnv};

fn model() -> Arc<sim::model::Model> {
    Arc::new(sim::mjcf::parse_str(sim::config::DEFAULT_MODEL_XML, "upper_body.xml").expect("model"))
}

fn rally_config(envs: usize, steps: usize, every: usize) -> TrainConfig {
    let mut c = TrainConfig {
        env: TrainEnv::Rally,
        ..TrainConfig::default()
    };
    c.ppo.envs = envs;
    c.ppo.steps_per_env = steps;
    c.ppo.checkpoint_every = every;
    c
}

/// Mean of the `dual` term paid per finished episode, and the episodes, over `iterations`.
fn dual_per_episode(t: &mut Trainer, iterations: usize) -> (f64, usize) {
    for _ in 0..iterations {
        t.iterate().unwrap();
    }
    let recent = &t.progress.recent;
    let n = recent.len();
    (
        recent.iter().map(|e| e.dual).sum::<f64>() / n.max(1) as f64,
        n,
    )
}

#[test]
fn the_serve_box_term_is_paid_once_the_policy_returns_balls() {
    // 16 rallies × 96 control steps × 2 robots per iteration, 4 iterations, from the untrained
    // policy and from the committed Diff-Muscle run (runs/kmac, single serves only).
    let cfg = rally_config(16, 96, 100);
    let m = model();
    let mut cold = Trainer::new(m.clone(), Method::Kmac, cfg.clone(), 5).unwrap();
    assert_eq!(cold.progress.curve.len(), 0);
    let (cold_dual, cold_n) = dual_per_episode(&mut cold, 4);
    let mut warm = Trainer::new(m, Method::Kmac, cfg, 5).unwrap();
    let run = RunDir::open(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../runs/kmac"
    )))
    .unwrap();
    run.warm_start(&mut warm)
        .expect("runs/kmac warm-starts a rally run");
    assert!(warm.progress.warm_start.is_some());
    let (warm_dual, warm_n) = dual_per_episode(&mut warm, 4);
    let row = warm.progress.curve.last().unwrap();
    eprintln!(
        "dual term per episode: untrained {cold_dual:.3} ({cold_n} episodes), warm {warm_dual:.3} \
         ({warm_n} episodes); warm rally length {:.2}, hit {:.2}",
        row.rally_length, row.hit_rate
    );
    assert!(cold_n >= 20 && warm_n >= 20);
    // ~8 payments expected in ~90 episodes; at least 2 (a Poisson tail below 1% if the rate holds).
    let paid = (warm_dual * warm_n as f64).round();
    assert!(
        paid >= 2.0,
        "the warm start earns the serve-box term ({paid} times)"
    );
    assert!(warm_dual > cold_dual, "{warm_dual} vs {cold_dual}");
    assert!(row.rally_length > 0.0 && (row.dual - warm_dual).abs() < 1e-12);
}
