//! The vector environment the Python package steps, against a recorded trajectory: K-MAC on the
//! default robot, episode seed 5, 40 steps of fixed actions. The Python package's tests compare
//! their run with the same file (`python/tests/test_envs.py`), so a pass on both sides means the
//! two give the same trajectory bit for bit. `RALLY_REGENERATE=1` rewrites it (after a change that
//! is meant to change the trajectory).

use std::sync::Arc;

use agents::ppo::{Method, TrainConfig};
use agents::vecenv::{StepResult, VecEnv};

const FIXTURE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/tests/fixtures/vecenv_trajectory.json"
);

/// The fixed action of step `k`, entry `j`: exact in any language (a small integer over 5.5).
fn action(k: usize, j: usize) -> f64 {
    ((k * 7 + j * 3) % 11) as f64 / 5.5 - 1.0
}

/// The sum of the bit patterns of `x` (wrapping), a checksum numpy computes the same way.
fn bits_sum(x: &[f64]) -> u64 {
    x.iter().fold(0u64, |s, v| s.wrapping_add(v.to_bits()))
}

#[test]
fn the_vector_environment_replays_its_recorded_trajectory() {
    let m = Arc::new(sim::config::default_model());
    let mut v = VecEnv::new(
        m,
        &sim::config::ArenaConfig::default(),
        Method::Kmac,
        &TrainConfig::default(),
        1,
    )
    .unwrap();
    let (od, ad) = (v.obs_dim(), v.act_dim());
    let mut obs = vec![0.0; od];
    v.reset(0, 5, &mut obs).unwrap();
    let mut sums = vec![bits_sum(&obs)];
    let mut rewards = Vec::new();
    let mut results = [StepResult::default()];
    let mut ended = None;
    for k in 0..40 {
        let a: Vec<f64> = (0..ad).map(|j| action(k, j)).collect();
        v.step(&a, &mut obs, &mut results).unwrap();
        sums.push(bits_sum(&obs));
        rewards.push(results[0].reward);
        if ended.is_none() && (results[0].terminated || results[0].truncated) {
            ended = Some(k);
        }
    }
    let now = serde_json::json!({
        "method": "kmac", "model": "default", "seed": 5, "steps": 40,
        "action": "((k*7 + j*3) % 11) / 5.5 - 1 for step k, entry j",
        "obs_bits_sum": sums, "rewards": rewards, "ended_at": ended,
    });
    if std::env::var_os("RALLY_REGENERATE").is_some() {
        std::fs::write(FIXTURE, serde_json::to_string_pretty(&now).unwrap() + "\n").unwrap();
    }
    let text = std::fs::read_to_string(FIXTURE).expect("the recorded trajectory");
    let recorded: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(recorded["obs_bits_sum"], now["obs_bits_sum"]);
    let bits = |v: &serde_json::Value| -> Vec<u64> {
        v.as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap().to_bits())
            .collect()
    };
    assert_eq!(bits(&recorded["rewards"]), bits(&now["rewards"]));
    assert_eq!(recorded["ended_at"], now["ended_at"]);
}
