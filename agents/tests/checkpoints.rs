//! Checkpoints: a template round-trips and plays; every kind of bad checkpoint is refused with the
//! field named; the RL environment is deterministic per seed and survives a NaN action.

use std::sync::Arc;

use agents::checkpoint::{
    Activation, Checkpoint, MAX_CURVE_POINTS, MAX_PARAMETERS, MAX_TRAINING_BYTES,
};
use agents::controller::{ControllerSpec, PdGains, Synergies};
use agents::env::{Env, RewardWeights};
use agents::eval::{evaluate, Evaluation};
use agents::factory::PlayerSpec;
use agents::observation::ObsBlock;
use sim::model::Model;
use sim::serve::ServeKind;

fn model() -> Arc<Model> {
    Arc::new(sim::config::default_model())
}

fn kmac() -> ControllerSpec {
    ControllerSpec::Kmac {
        gains: PdGains { kp: 40.0, kd: 3.0 },
        activation_clamp: None,
        activation_noise: None,
        clamp_coupled: false,
    }
}

#[test]
fn templates_of_every_controller_validate_round_trip_and_play() {
    let m = model();
    let controllers = [
        kmac(),
        ControllerSpec::MusclePd {
            gains: PdGains::MUSCLE_PD,
        },
        ControllerSpec::Direct,
        ControllerSpec::Dynsyn {
            synergies: Synergies::derive(&m, 8, 1),
        },
    ];
    for c in controllers {
        let ck = Checkpoint::template(&m, "zero", c, &[32, 32], Activation::Elu);
        let text = serde_json::to_string(&ck).unwrap();
        let back = Checkpoint::from_json(&text, &m).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(back, ck);
        let e = Evaluation {
            lead_in: false,
            model: m.clone(),
            config: sim::config::ArenaConfig::default(),
            preset: sim::arena::MYOCHALLENGE,
            kind: ServeKind::P2,
            episodes: 3,
            seed: 2,
        };
        let r = evaluate(&e, &PlayerSpec::Checkpoint(Arc::new(back)), &|| {}).unwrap();
        assert_eq!(r.episodes, 3);
    }
}

/// The controls a player for `spec` writes over one P2 episode of the default robot from `seed`.
fn controls_of(m: &Arc<Model>, spec: &PlayerSpec, seed: u64) -> Vec<Vec<f64>> {
    let preset = sim::arena::MYOCHALLENGE;
    let mut env =
        sim::episode::SingleServe::new(m.clone(), &sim::config::ArenaConfig::default(), preset)
            .unwrap();
    env.reset(ServeKind::P2, &mut sim::rng::Rng::seeded(seed), None);
    let mut player = spec.build(m, &preset, seed).unwrap();
    let mut trace = Vec::new();
    agents::eval::play_traced(&mut env, player.as_mut(), Some(&mut trace));
    trace.into_iter().map(|t| t.controls).collect()
}

#[test]
fn a_checkpoint_plays_the_action_noise_it_was_trained_with_and_mean_action_drops_it() {
    // Muscle-PPO's template acts 0 everywhere (control σ(−2.5) on every muscle). With `action_noise`
    // the player adds that Gaussian to every action after the clip, as the training environment
    // did: the controls move off that value, the same way for the same seed; the mean action
    // (`rally eval --mean-action`) drops the noise again.
    let m = model();
    let plain = Checkpoint::template(&m, "t", ControllerSpec::Direct, &[8], Activation::Tanh);
    let mut noisy = plain.clone();
    noisy.action_noise = Some(0.05);
    let text = serde_json::to_string(&noisy).unwrap();
    assert!(
        text.contains("\"action_noise\":0.05"),
        "the field is written"
    );
    let noisy = Checkpoint::from_json(&text, &m).unwrap();
    let (p, n) = (
        PlayerSpec::Checkpoint(Arc::new(plain)),
        PlayerSpec::Checkpoint(Arc::new(noisy)),
    );
    let (quiet, loud) = (controls_of(&m, &p, 3), controls_of(&m, &n, 3));
    let muscles: Vec<usize> = m.muscles().map(|(i, _)| i).collect();
    let spread = |c: &[Vec<f64>]| {
        let xs = c.iter().flat_map(|s| muscles.iter().map(|&i| s[i]));
        xs.clone().fold(f64::MIN, f64::max) - xs.fold(f64::MAX, f64::min)
    };
    assert_eq!(
        spread(&quiet),
        0.0,
        "without noise every muscle gets the same control"
    );
    assert!(spread(&loud) > 1e-3, "{}", spread(&loud));
    assert_eq!(loud, controls_of(&m, &n, 3), "deterministic per seed");
    assert_ne!(loud, controls_of(&m, &n, 4));
    assert_eq!(controls_of(&m, &n.clone().mean_action(), 3), quiet);
}

#[test]
fn a_kmac_checkpoint_draws_its_activation_noise_in_play_and_its_mean_action_plays_the_expectation()
{
    // K-MAC trained with σ 0.1 on its activation targets (the official form, clamped): the player
    // draws that noise as training did, seeded; the mean action draws nothing and plays each
    // control's expectation under the clamp, E[clip(u + σZ)], from the noiseless control u.
    let m = model();
    let [lo, hi] = agents::controller::official_activation_clamp();
    let spec = |noise: Option<f64>| {
        let c = ControllerSpec::Kmac {
            gains: PdGains { kp: 10.0, kd: 1.0 },
            activation_clamp: Some([lo, hi]),
            activation_noise: noise,
            clamp_coupled: false,
        };
        let ck = Checkpoint::template(&m, "t", c, &[8], Activation::Tanh);
        let text = serde_json::to_string(&ck).unwrap();
        PlayerSpec::Checkpoint(Arc::new(Checkpoint::from_json(&text, &m).unwrap()))
    };
    let (plain, noisy) = (spec(None), spec(Some(0.1)));
    let quiet = controls_of(&m, &plain, 3);
    let drawn = controls_of(&m, &noisy, 3);
    assert_eq!(drawn, controls_of(&m, &noisy, 3), "deterministic per seed");
    assert_ne!(drawn, controls_of(&m, &noisy, 4));
    let mean = controls_of(&m, &noisy.clone().mean_action(), 3);
    assert_eq!(mean, controls_of(&m, &noisy.mean_action(), 3));
    // The first step starts from the same state in all three: compare muscle by muscle.
    let muscles: Vec<usize> = m.muscles().map(|(i, _)| i).collect();
    let mut moved = 0;
    for &a in &muscles {
        let u = quiet[0][a];
        let expected = agents::controller::clamped_normal_mean(u, 0.1, lo, hi);
        if u > lo && u < hi {
            assert!(
                (mean[0][a] - expected).abs() < 1e-12,
                "muscle {a}: mean action {} against E = {expected} (noiseless {u})",
                mean[0][a]
            );
        } else {
            // Clamped: the control before the clamp lay beyond the bound, so the expectation is
            // between the bound and the one from the bound itself.
            let (m, at) = (mean[0][a], expected);
            assert!(
                (u == lo && m > lo && m <= at + 1e-12) || (u == hi && m < hi && m >= at - 1e-12),
                "muscle {a}: mean action {m}, bound {u}, E from the bound {at}"
            );
        }
        assert!(
            (lo..=hi).contains(&drawn[0][a]),
            "muscle {a}: {}",
            drawn[0][a]
        );
        if (drawn[0][a] - u).abs() > 1e-6 && (drawn[0][a] - expected).abs() > 1e-6 {
            moved += 1;
        }
    }
    assert!(
        moved > muscles.len() / 4,
        "only {moved} of {} muscles drew noise",
        muscles.len()
    );
}

fn refused(m: &Model, ck: &Checkpoint, field: &str) {
    let text = serde_json::to_string(ck).unwrap();
    let e = Checkpoint::from_json(&text, m).expect_err("must be refused");
    assert!(
        e.field.contains(field),
        "expected the field {field}, got {e}"
    );
}

#[test]
fn a_checkpoint_names_its_robot_and_another_robot_refuses_it() {
    let m = model();
    let ck = Checkpoint::template(&m, "t", kmac(), &[16], Activation::Tanh);
    assert_eq!(ck.model, "default");
    let text = serde_json::to_string(&ck).unwrap();
    assert!(text.contains(r#""model":"default""#), "{text}");
    // A file from before the field plays the default robot.
    let mut old: serde_json::Value = serde_json::from_str(&text).unwrap();
    old.as_object_mut().unwrap().remove("model");
    let back = Checkpoint::from_json(&old.to_string(), &m).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(back.model, "default");
    // The same shapes on a robot of another name: refused for the robot, both names said.
    let mut other = (*m).clone();
    other.name = "other_body".into();
    let e = Checkpoint::from_json(&text, &other).expect_err("another robot's checkpoint");
    assert_eq!(e.field, "model");
    assert!(
        e.to_string().contains("default") && e.to_string().contains("other_body"),
        "{e}"
    );
    let mut c = ck.clone();
    c.model = "myochallenge".into();
    refused(&m, &c, "model");
}

#[test]
fn bad_checkpoints_are_refused_naming_the_field() {
    let m = model();
    let good = Checkpoint::template(&m, "t", kmac(), &[16], Activation::Tanh);

    let mut c = good.clone();
    c.format = "pytorch".into();
    refused(&m, &c, "format");
    let mut c = good.clone();
    c.version = 99;
    refused(&m, &c, "version");
    let mut c = good.clone();
    c.observation.mean.pop();
    refused(&m, &c, "observation.mean");
    let mut c = good.clone();
    c.observation.std[3] = 0.0;
    refused(&m, &c, "observation.std[3]");
    let mut c = good.clone();
    c.policy.as_mut().unwrap().layers[0].weights[2].push(0.0);
    refused(&m, &c, "policy.layers[0].weights[2]");
    let mut c = good.clone();
    c.policy.as_mut().unwrap().layers[1].bias.pop();
    c.policy.as_mut().unwrap().layers[1].weights.pop();
    refused(&m, &c, "policy.layers[1].bias");
    let mut c = good.clone();
    c.controller = ControllerSpec::Kmac {
        gains: PdGains { kp: -1.0, kd: 0.0 },
        activation_clamp: None,
        activation_noise: None,
        clamp_coupled: false,
    };
    refused(&m, &c, "controller.gains");
    for sigma in [-0.1, 1.5, 1e300] {
        let mut c = good.clone();
        c.action_noise = Some(sigma);
        refused(&m, &c, "action_noise");
    }
    for sigma in [-0.1, 1.5, 1e300] {
        let mut c = good.clone();
        c.controller = ControllerSpec::Kmac {
            gains: PdGains { kp: 10.0, kd: 1.0 },
            activation_clamp: None,
            activation_noise: Some(sigma),
            clamp_coupled: false,
        };
        refused(&m, &c, "controller.activation_noise");
    }
    // NaN cannot be written in JSON; a checkpoint built in memory is validated all the same.
    let mut c = good.clone();
    c.policy.as_mut().unwrap().layers[0].weights[1][5] = f64::NAN;
    assert!(c
        .validate(&m)
        .unwrap_err()
        .field
        .contains("policy.layers[0].weights[1]"));
    // Too large.
    let c = Checkpoint::template(
        &m,
        "huge",
        kmac(),
        &[MAX_PARAMETERS / 200],
        Activation::Relu,
    );
    assert!(c.validate(&m).unwrap_err().message.contains("parameters"));
    // A provenance anyone may read, kept small: the learning curve and the whole section.
    let kmac_text = agents::builtins::checkpoint("kmac").expect("built in");
    let trained: Checkpoint = serde_json::from_str(kmac_text).unwrap();
    let mut c = trained.clone();
    let t = c.training.as_mut().unwrap();
    t.curve = t
        .curve
        .iter()
        .cycle()
        .take(MAX_CURVE_POINTS + 1)
        .copied()
        .collect();
    refused(&m, &c, "training.curve");
    let mut c = trained.clone();
    c.training.as_mut().unwrap().note = Some("x".repeat(MAX_TRAINING_BYTES));
    refused(&m, &c, "training");
    let mut c = trained;
    let t = c.training.as_mut().unwrap();
    t.curve = t
        .curve
        .iter()
        .cycle()
        .take(MAX_CURVE_POINTS)
        .copied()
        .collect();
    c.validate(&m).unwrap();
    // Unknown controller kind and unknown fields: serde's words, with line and column.
    let text = serde_json::to_string(&good)
        .unwrap()
        .replace("\"kmac\"", "\"telepathy\"");
    let e = Checkpoint::from_json(&text, &m).unwrap_err();
    assert!(e.message.contains("telepathy"), "{e}");
    let text = serde_json::to_string(&good)
        .unwrap()
        .replacen("{", "{\"extra\":1,", 1);
    assert!(Checkpoint::from_json(&text, &m)
        .unwrap_err()
        .message
        .contains("extra"));
    assert!(Checkpoint::from_json("{not json", &m).is_err());
}

#[test]
fn the_rl_environment_is_deterministic_and_survives_nan() {
    let m = model();
    let mk = || {
        Env::new(
            m.clone(),
            &sim::config::ArenaConfig::default(),
            sim::arena::MYOCHALLENGE,
            &kmac(),
            ObsBlock::ALL.to_vec(),
            RewardWeights::default(),
            ServeKind::P2,
        )
        .unwrap()
    };
    let (mut e1, mut e2) = (mk(), mk());
    let (o1, o2) = (e1.reset(5), e2.reset(5));
    assert_eq!(o1, o2);
    assert_eq!(o1.len(), e1.obs_dim());
    let action = vec![0.1; e1.action_dim()];
    let mut total = 0.0;
    for _ in 0..50 {
        let (t1, t2) = (e1.step(&action), e2.step(&action));
        assert_eq!(t1, t2);
        assert!(t1.reward.is_finite() && t1.obs.iter().all(|x| x.is_finite()));
        total += t1.reward;
        if t1.done {
            break;
        }
    }
    assert!(
        total > 0.0,
        "the grasp term alone rewards holding the paddle"
    );
    assert_ne!(e1.reset(6), o1);
    let mut nan = action.clone();
    nan[0] = f64::NAN;
    let t = e1.step(&nan);
    assert!(t.done);
    assert_eq!(
        e1.episode.referee.end().unwrap().reason.name(),
        "INVALID_ACTION"
    );
}

#[test]
fn the_rally_environment_steps_both_robots_deterministically() {
    use agents::env::RallyEnv;
    let m = model();
    let mk = || {
        RallyEnv::new(
            m.clone(),
            &sim::config::ArenaConfig::default(),
            sim::arena::MYOCHALLENGE,
            &kmac(),
            ObsBlock::ALL.to_vec(),
            RewardWeights::default(),
        )
        .unwrap()
    };
    let (mut e1, mut e2) = (mk(), mk());
    e1.reset(3);
    e2.reset(3);
    assert_eq!(e1.observation(0), e2.observation(0));
    assert_eq!(e1.observation(1), e2.observation(1));
    // The receiver of the serve has a command; the server has none and is paid for being ready.
    let server = (e1.rally.referee.server() == sim::arena::Side::B) as usize;
    assert!(e1.command(1 - server).is_some() && e1.command(server).is_none());
    let action = vec![0.0; e1.action_dim()];
    let mut steps = 0;
    loop {
        let (t1, t2) = (e1.step([&action, &action]), e2.step([&action, &action]));
        assert_eq!(t1, t2);
        if steps == 0 {
            assert!(
                t1[server].step.terms.ready > 0.9,
                "{:?}",
                t1[server].step.terms
            );
            assert_eq!(t1[1 - server].step.terms.ready, 0.0);
        }
        assert!(t1.iter().all(|t| t.step.reward.is_finite()));
        steps += 1;
        if t1[0].step.done {
            assert!(t1[1].step.done);
            break;
        }
    }
    assert!(steps > 10 && e1.rally.referee.end().is_some());
    // A different seed is a different rally.
    e2.reset(4);
    e1.reset(3);
    assert_ne!(e1.observation(0), e2.observation(0));
}
