//! PPO in the dual-rally environment (self-play, both robots on one policy): the serve-box term is
//! paid once the policy can return balls (a warm start from the committed single-serve run earns it,
//! the untrained policy does not). Resuming a rally run is tested with the single-serve one in `ppo.rs`.

use std::sync::Arc;

use agents::ppo::store::{RunDir, WarmOptimiser};
use agents::ppo::trainer::Trainer;
use agents::ppo::{Method, TrainConfig, TrainEnv};

fn model() -> Arc<sim::model::Model> {
    Arc::new(sim::config::default_model())
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
    // policy and from the Diff-Muscle built-in's run (single serves only; its resume state is in
    // tests/fixtures/runs/kmac).
    let cfg = rally_config(16, 96, 100);
    let m = model();
    let mut cold = Trainer::new(m.clone(), Method::Kmac, cfg.clone(), 5).unwrap();
    assert_eq!(cold.progress.curve.len(), 0);
    let (cold_dual, cold_n) = dual_per_episode(&mut cold, 4);
    let mut warm = Trainer::new(m, Method::Kmac, cfg, 5).unwrap();
    let run = RunDir::open(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/runs/kmac"
    )))
    .unwrap();
    run.warm_start(&mut warm, WarmOptimiser::Carry)
        .expect("the Diff-Muscle run warm-starts a rally run");
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

fn weight_bits(t: &Trainer) -> Vec<u32> {
    t.net
        .named()
        .iter()
        .flat_map(|(_, x)| {
            x.flatten_all()
                .unwrap()
                .to_vec1::<f32>()
                .unwrap()
                .into_iter()
                .map(f32::to_bits)
        })
        .collect()
}

#[test]
fn validation_scores_the_policy_and_leaves_the_run_unchanged() {
    // Two runs warm-started from the rally built-in's starting point, one validated after every
    // iteration: the same weights after three iterations. The validation plays the policy as a checkpoint would
    // (self-play rallies on the validation seed): the warm policy returns balls, the untrained one
    // does not, and its score is the mean rally length those rallies give.
    let mut cfg = rally_config(4, 16, 100);
    cfg.validation.every = 1;
    cfg.validation.episodes = 10;
    let m = model();
    let run = RunDir::open(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/runs/kmac-bank2-init"
    )))
    .unwrap();
    let warm = |seed| {
        let mut t = Trainer::new(m.clone(), Method::Kmac, cfg.clone(), seed).unwrap();
        run.warm_start(&mut t, WarmOptimiser::Carry).unwrap();
        t
    };
    let (mut plain, mut validated) = (warm(9), warm(9));
    for _ in 0..3 {
        plain.iterate().unwrap();
        validated.iterate().unwrap();
        let v = validated.validate().unwrap();
        validated.progress.validations.push(v);
    }
    assert_eq!(weight_bits(&plain), weight_bits(&validated));
    let scores: Vec<f64> = validated
        .progress
        .validations
        .iter()
        .map(|v| v.score)
        .collect();
    eprintln!("validation mean rally after iterations 1-3: {scores:?}");
    assert!(scores.iter().all(|&s| s > 0.0), "{scores:?}");
    let best = validated.progress.best_validation().unwrap();
    assert!(scores.iter().all(|&s| s <= best.score));
    assert_eq!(
        best.iteration,
        1 + scores.iter().position(|&s| s == best.score).unwrap() as u64
    );
    // The score is the mean rally of the validation's self-play rallies, checkpoint against itself.
    let ck = validated.checkpoint("v", "", "").unwrap();
    let player = agents::factory::PlayerSpec::Checkpoint(Arc::new(ck));
    let spec = agents::matchrun::MatchSpec {
        model: m.clone(),
        config: sim::config::ArenaConfig::default(),
        preset: sim::arena::MYOCHALLENGE,
        rallies: 10,
        seed: cfg.validation.seed,
        replay: false,
    };
    let lengths: u32 = agents::matchrun::play_rallies(&spec, &player, &player)
        .unwrap()
        .iter()
        .map(|r| r.length)
        .sum();
    assert_eq!(lengths as f64 / 10.0, scores[2]);
    let cold = Trainer::new(m.clone(), Method::Kmac, cfg.clone(), 9).unwrap();
    assert_eq!(cold.validate().unwrap().score, 0.0);
}
