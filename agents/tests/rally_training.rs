//! PPO in the dual-rally environment (self-play, both robots on one policy): the serve-box term is
//! paid once the policy can return balls (a warm start from the committed single-serve run earns it,
//! the untrained policy does not), and a resumed rally run is the same run bit for bit.

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

#[test]
fn a_resumed_rally_run_is_the_same_run_bit_for_bit() {
    let mut cfg = rally_config(3, 24, 2);
    cfg.ppo.hidden = vec![16, 16];
    let m = model();
    let mut straight = Trainer::new(m.clone(), Method::Kmac, cfg.clone(), 12).unwrap();
    for _ in 0..4 {
        straight.iterate().unwrap();
    }
    let dir = std::env::temp_dir().join(format!("rally-ppo-rally-resume-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let run = RunDir::open(&dir).unwrap();
    let mut first = Trainer::new(m.clone(), Method::Kmac, cfg, 12).unwrap();
    for _ in 0..2 {
        first.iterate().unwrap();
    }
    run.save_state(&first).unwrap();
    first.iterate().unwrap();
    drop(first);
    let mut resumed = run.load(m).unwrap();
    assert_eq!(resumed.config.env, TrainEnv::Rally);
    for _ in 0..2 {
        resumed.iterate().unwrap();
    }
    let bits = |t: &Trainer| -> Vec<u32> {
        t.net
            .named()
            .iter()
            .flat_map(|(_, x)| x.flatten_all().unwrap().to_vec1::<f32>().unwrap())
            .map(f32::to_bits)
            .collect()
    };
    assert_eq!(bits(&resumed), bits(&straight));
    assert_eq!(resumed.normalizer, straight.normalizer);
    assert_eq!(
        resumed
            .progress
            .curve
            .iter()
            .map(|r| (r.episodes, r.value_loss.to_bits()))
            .collect::<Vec<_>>(),
        straight
            .progress
            .curve
            .iter()
            .map(|r| (r.episodes, r.value_loss.to_bits()))
            .collect::<Vec<_>>()
    );
    let _ = std::fs::remove_dir_all(&dir);
}
