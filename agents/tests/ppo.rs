//! PPO end to end on the real single-serve environment: a short run shows a learning signal, a run
//! is a function of its seed, a run saved and resumed is the same run bit for bit (in the rally
//! environment too), and the shipped
//! `config/train.toml` is the compiled-in default.

use std::sync::Arc;

use agents::ppo::store::{RunDir, WarmOptimiser};
use agents::ppo::trainer::Trainer;
use agents::ppo::{CriticInput, Method, TrainConfig};

fn model() -> Arc<sim::model::Model> {
    Arc::new(sim::config::default_model())
}

/// A small configuration that still runs the whole algorithm.
fn small(envs: usize, steps: usize, every: usize) -> TrainConfig {
    let mut c = TrainConfig::default();
    c.ppo.envs = envs;
    c.ppo.steps_per_env = steps;
    c.ppo.hidden = vec![32, 32];
    c.ppo.checkpoint_every = every;
    c
}

fn weights(t: &Trainer) -> Vec<Vec<u32>> {
    t.net
        .named()
        .iter()
        .map(|(_, x)| {
            x.flatten_all()
                .unwrap()
                .to_vec1::<f32>()
                .unwrap()
                .iter()
                .map(|v| v.to_bits())
                .collect()
        })
        .collect()
}

#[test]
fn the_shipped_train_toml_is_the_default_configuration() {
    let text =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../config/train.toml"))
            .expect("config/train.toml");
    let c: TrainConfig = toml::from_str(&text).expect("parses");
    assert_eq!(c, TrainConfig::default());
}

#[test]
fn the_rally_configuration_is_the_default_but_for_its_environment_and_entropy() {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../config/train-rally.toml"
    ))
    .expect("config/train-rally.toml");
    let mut c: TrainConfig = toml::from_str(&text).expect("parses");
    assert_eq!(c.env, agents::ppo::TrainEnv::Rally);
    assert_eq!(c.ppo.entropy_coef, 0.0);
    c.env = agents::ppo::TrainEnv::Single;
    c.ppo.entropy_coef = TrainConfig::default().ppo.entropy_coef;
    assert_eq!(c, TrainConfig::default());
}

#[test]
fn the_rally_finetune_configuration_is_the_rally_one_but_for_the_ball_out_term() {
    let read = |f: &str| -> TrainConfig {
        let path = format!("{}/../config/{f}", env!("CARGO_MANIFEST_DIR"));
        toml::from_str(&std::fs::read_to_string(&path).expect(f)).expect("parses")
    };
    let mut c = read("train-rally-finetune.toml");
    assert_eq!(c.reward.ball_out, 100.0);
    c.reward.0.ball_out = 0.0;
    assert_eq!(c, read("train-rally.toml"));
}

#[test]
fn the_myochallenge_configuration_is_the_default_but_for_kmac_noise_schedule_and_entropy() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../config/train-myochallenge.toml"
    );
    let mut c: TrainConfig =
        toml::from_str(&std::fs::read_to_string(path).expect("read")).expect("parses");
    c.validate().unwrap();
    let clamp = c.controller.kmac_activation_clamp.take().expect("a clamp");
    assert_eq!(clamp, agents::controller::official_activation_clamp());
    assert_eq!(
        (c.controller.action_noise, c.controller.activation_noise),
        (0.05, 0.1)
    );
    // Its K-MAC checkpoints record the activation noise (they draw it in play); the other
    // methods have no activation of their own and record none.
    let m = model();
    let spec = |c: &TrainConfig, method| c.controller(method, &m);
    match (
        spec(&c, Method::Kmac),
        spec(&TrainConfig::default(), Method::Kmac),
    ) {
        (
            agents::controller::ControllerSpec::Kmac {
                activation_noise: Some(sigma),
                ..
            },
            agents::controller::ControllerSpec::Kmac {
                activation_noise: None,
                ..
            },
        ) => assert_eq!(sigma, 0.1),
        other => panic!("{other:?}"),
    }
    // The rally environment draws no training noise: a configuration asking for it there is refused.
    let mut rally = c.clone();
    rally.env = agents::ppo::TrainEnv::Rally;
    let e = rally.validate().unwrap_err();
    assert!(e.contains("controller.activation_noise"), "{e}");
    c.controller.action_noise = 0.0;
    c.controller.activation_noise = 0.0;
    assert_eq!(c.ppo.schedule, agents::ppo::Schedule::LinearDecay);
    c.ppo.schedule = agents::ppo::Schedule::Adaptive;
    assert_eq!(c.ppo.entropy_coef, 0.0);
    c.ppo.entropy_coef = TrainConfig::default().ppo.entropy_coef;
    assert_eq!(c, TrainConfig::default());
}

#[test]
fn a_sigma_cap_holds_the_policy_noise_under_its_schedule() {
    // The cap's schedule: linear from the first value to the second over max_std_steps, then flat.
    let mut c = small(8, 4, 100);
    c.ppo.max_std = Some([0.4, 0.2]);
    c.ppo.max_std_steps = 1000;
    assert_eq!(c.ppo.std_cap(0), Some(0.4));
    assert!((c.ppo.std_cap(500).unwrap() - 0.3).abs() < 1e-12);
    assert_eq!(c.ppo.std_cap(5000), Some(0.2));
    assert_eq!(TrainConfig::default().ppo.std_cap(0), None);
    // Training under it: σ starts at 0.5 and is at most the cap after every update.
    let mut t = Trainer::new(model(), Method::Kmac, c, 5).unwrap();
    assert!(t.net.std().unwrap().iter().all(|s| (s - 0.5).abs() < 1e-6));
    // (An iteration's updates use the cap at the env steps counted before it.)
    for _ in 0..3 {
        let cap = t.config.ppo.std_cap(t.progress.env_steps).unwrap() as f32;
        t.iterate().unwrap();
        let std = t.net.std().unwrap();
        assert!(std.iter().all(|s| *s <= cap * 1.0001), "{std:?} over {cap}");
    }
}

#[test]
fn a_short_kmac_run_learns_a_signal() {
    // 20 iterations of 64 envs × 16 steps (20 480 control steps), against the untrained policy: the
    // critic's loss falls and the episodes' reward (command tracking and grasp, mostly) rises.
    let mut t = Trainer::new(model(), Method::Kmac, small(64, 16, 100), 3).unwrap();
    let mut rows = Vec::new();
    let mut early = Vec::new();
    for k in 0..20 {
        let before = t.progress.episodes;
        rows.push(t.iterate().unwrap());
        let new = (t.progress.episodes - before) as usize;
        if k < 4 {
            early.extend(t.progress.recent.iter().rev().take(new).map(|e| e.reward));
        }
    }
    let late: Vec<f64> = t
        .progress
        .recent
        .iter()
        .rev()
        .take(early.len())
        .map(|e| e.reward)
        .collect();
    let mean = |x: &[f64]| x.iter().sum::<f64>() / x.len() as f64;
    let (r0, r1) = (mean(&early), mean(&late));
    let v0 = rows[..3].iter().map(|r| r.value_loss).sum::<f64>() / 3.0;
    let v1 = rows[17..].iter().map(|r| r.value_loss).sum::<f64>() / 3.0;
    eprintln!(
        "episode reward {r0:.1} → {r1:.1} ({} episodes each); value loss {v0:.3} → {v1:.3}",
        early.len()
    );
    assert!(v1 < 0.5 * v0, "value loss {v0} → {v1}");
    assert!(r1 > r0 * 1.05, "episode reward {r0} → {r1}");
    assert!(rows
        .iter()
        .all(|r| r.kl.is_finite() && r.learning_rate > 0.0));
}

#[test]
fn a_resumed_run_is_the_same_run_bit_for_bit() {
    // In both environments: single serves, and the self-play rally (two robots per environment).
    // And with the privileged critic (its own statistics are saved and resumed too).
    let mut rally = small(3, 24, 2);
    rally.env = agents::ppo::TrainEnv::Rally;
    rally.ppo.hidden = vec![16, 16];
    let mut privileged = small(4, 8, 2);
    privileged.ppo.critic = CriticInput::Privileged;
    // And stopped inside a critic warm-up (the policy's own Adam steps are saved and resumed).
    let mut warm = small(4, 8, 2);
    warm.ppo.critic_warmup = 3;
    for (k, cfg) in [small(4, 8, 2), rally, privileged, warm]
        .into_iter()
        .enumerate()
    {
        let m = model();
        let mut straight = Trainer::new(m.clone(), Method::Kmac, cfg.clone(), 11).unwrap();
        for _ in 0..4 {
            straight.iterate().unwrap();
        }
        let dir = std::env::temp_dir().join(format!(
            "rally-ppo-resume-{}-{k}-{}",
            cfg.env.name(),
            std::process::id()
        ));
        let _ = std::fs::remove_dir_all(&dir);
        let run = RunDir::open(&dir).unwrap();
        let mut first = Trainer::new(m.clone(), Method::Kmac, cfg.clone(), 11).unwrap();
        for _ in 0..2 {
            first.iterate().unwrap();
        }
        run.save_state(&first).unwrap();
        // A third iteration that is lost, as if killed before the next checkpoint.
        first.iterate().unwrap();
        drop(first);
        let mut resumed = run.load(m).unwrap();
        assert_eq!(resumed.progress.iteration, 2);
        assert_eq!(resumed.config, cfg);
        for _ in 0..2 {
            resumed.iterate().unwrap();
        }
        assert_eq!(weights(&resumed), weights(&straight), "{}", cfg.env.name());
        assert_eq!(resumed.adam.lr.to_bits(), straight.adam.lr.to_bits());
        assert_eq!(resumed.adam.var_steps, straight.adam.var_steps);
        assert_eq!(resumed.normalizer, straight.normalizer);
        assert_eq!(resumed.critic_normalizer, straight.critic_normalizer);
        let strip = |rows: &[agents::ppo::trainer::CurveRow]| -> Vec<(u64, u64, u64)> {
            rows.iter()
                .map(|r| (r.iteration, r.episodes, r.value_loss.to_bits()))
                .collect()
        };
        assert_eq!(
            strip(&resumed.progress.curve),
            strip(&straight.progress.curve)
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}

#[test]
fn the_linear_decay_schedule_falls_to_zero_at_the_step_target() {
    let mut cfg = small(4, 8, 2);
    cfg.ppo.schedule = agents::ppo::Schedule::LinearDecay;
    let lr0 = cfg.ppo.learning_rate;
    let mut t = Trainer::new(model(), Method::Kmac, cfg, 3).unwrap();
    let per = 4 * 8;
    t.steps_target = 4 * per;
    let mut rates = Vec::new();
    for _ in 0..4 {
        let row = t.iterate().unwrap();
        rates.push(row.learning_rate);
    }
    // Set before each iteration's update from the steps done before it: 1, 3/4, 1/2, 1/4 of lr0.
    let want: Vec<f64> = [1.0, 0.75, 0.5, 0.25].iter().map(|f| lr0 * f).collect();
    for (got, want) in rates.iter().zip(&want) {
        assert!((got - want).abs() < 1e-15, "{rates:?} against {want:?}");
    }
    assert_eq!(t.linear_decay_lr(), 0.0, "zero once the target is reached");
    // Without a target (a trainer outside `rally train`) the rate stays put.
    t.steps_target = 0;
    assert_eq!(t.linear_decay_lr(), lr0);
}

#[test]
fn each_ablation_is_observed_rewarded_and_recorded_as_configured() {
    use agents::env::Ablation;
    use agents::observation::CommandVariant;
    let m = model();
    for (command, width) in [
        (CommandVariant::Full, 206),
        (CommandVariant::Position, 198),
        (CommandVariant::None, 195),
    ] {
        for task_reward in [true, false] {
            let mut c = small(2, 4, 10);
            c.ablation = Ablation {
                command,
                task_reward,
            };
            // The environment's own observation, and its reward without the removed terms.
            let mut v = agents::vecenv::VecEnv::new(
                m.clone(),
                &sim::config::ArenaConfig::default(),
                Method::Kmac,
                &c,
                1,
            )
            .unwrap();
            assert_eq!(v.obs_dim(), width, "{command:?}");
            let names = v.observation_names().join(" ");
            assert_eq!(
                names.contains("command.racket_vx"),
                command == CommandVariant::Full
            );
            assert_eq!(
                names.contains("command.strike_x"),
                command != CommandVariant::None
            );
            let mut obs = vec![0.0; width];
            let mut r = vec![agents::vecenv::StepResult::default()];
            let removed = |name: &str| {
                agents::env::RewardTerms::NAMES
                    .iter()
                    .position(|n| *n == name)
                    .unwrap()
            };
            let mut paid = [false; 13];
            for _ in 0..120 {
                v.step(&[0.0; 13], &mut obs, &mut r).unwrap();
                for (p, x) in paid.iter_mut().zip(r[0].terms) {
                    *p |= x != 0.0;
                }
                if command != CommandVariant::Full {
                    assert_eq!(r[0].terms[removed("orientation")], 0.0);
                }
                if command == CommandVariant::None {
                    assert_eq!(r[0].terms[removed("position")], 0.0);
                }
                if !task_reward {
                    assert_eq!(r[0].terms[removed("fault")], 0.0);
                    assert_eq!(r[0].terms[removed("hit")], 0.0);
                }
                if r[0].terminated || r[0].truncated {
                    break;
                }
            }
            // What is not removed is paid (so the checks above could fail).
            assert!(paid[removed("grasp")]);
            assert_eq!(paid[removed("position")], command != CommandVariant::None);
            assert_eq!(
                paid[removed("orientation")],
                command == CommandVariant::Full
            );
            // Trained under it: the checkpoint observes as it trained and says how.
            let ablation = c.ablation;
            let mut t = Trainer::new(m.clone(), Method::Kmac, c, 5).unwrap();
            t.iterate().unwrap();
            let ck = t.checkpoint("probe", "test", "none").unwrap();
            assert_eq!(ck.observation.mean.len(), width);
            let recorded = ck.training.as_ref().unwrap().ablation;
            let full = command == CommandVariant::Full && task_reward;
            assert_eq!(recorded, (!full).then_some(ablation));
            round_trip_and_play(&m, &ck);
        }
    }
}

/// The checkpoint read back from its JSON, after it played two P2 serves.
fn round_trip_and_play(
    m: &Arc<sim::model::Model>,
    ck: &agents::checkpoint::Checkpoint,
) -> Arc<agents::checkpoint::Checkpoint> {
    let text = serde_json::to_string(ck).unwrap();
    let back = Arc::new(agents::checkpoint::Checkpoint::from_json(&text, m).unwrap());
    let e = agents::eval::Evaluation {
        lead_in: false,
        model: m.clone(),
        config: sim::config::ArenaConfig::default(),
        preset: sim::arena::MYOCHALLENGE,
        kind: sim::serve::ServeKind::P2,
        episodes: 2,
        seed: 1,
    };
    agents::eval::evaluate(
        &e,
        &agents::factory::PlayerSpec::Checkpoint(back.clone()),
        &|| {},
    )
    .unwrap();
    back
}

#[test]
fn every_method_trains_and_exports_a_checkpoint_that_plays() {
    let m = model();
    for method in Method::ALL {
        let mut t = Trainer::new(m.clone(), method, small(2, 4, 10), 5).unwrap();
        t.iterate().unwrap();
        let ck = t.checkpoint("probe", "test", "none").unwrap();
        ck.validate(&m)
            .unwrap_or_else(|e| panic!("{method:?}: {e}"));
        let back = round_trip_and_play(&m, &ck);
        assert_eq!(back.training.as_ref().unwrap().method, method.name());
    }
}

#[test]
fn the_rally_batch_configuration_is_the_finetune_one_but_for_its_batch_and_validation() {
    let read = |f: &str| -> TrainConfig {
        let path = format!("{}/../config/{f}", env!("CARGO_MANIFEST_DIR"));
        toml::from_str(&std::fs::read_to_string(&path).expect(f)).expect("parses")
    };
    let mut c = read("train-rally-batch.toml");
    assert_eq!((c.ppo.envs, c.validation.every), (256, 10));
    c.ppo.envs = 64;
    c.validation.every = 0;
    assert_eq!(c, read("train-rally-finetune.toml"));
}

#[test]
fn a_refreshed_bank_is_kept_in_the_resumable_state_and_served() {
    // Balls struck by B (rally serves stand in for recorded returns), served in every episode.
    let balls: Vec<sim::ball::BallState> = (0..5)
        .map(|i| {
            sim::serve::generate(
                sim::serve::ServeKind::Rally {
                    server: sim::arena::Side::B,
                },
                &mut sim::rng::Rng::seeded(i),
                &sim::predict::MYOCHALLENGE_BOUNCE,
            )
            .ball
        })
        .collect();
    let mut cfg = small(4, 8, 2);
    cfg.bank.fraction = 1.0;
    let m = model();
    let mut straight = Trainer::new(m.clone(), Method::Kmac, cfg.clone(), 12).unwrap();
    straight.set_bank(balls.clone().into());
    let mut plain = Trainer::new(m.clone(), Method::Kmac, cfg.clone(), 12).unwrap();
    for _ in 0..4 {
        straight.iterate().unwrap();
        plain.iterate().unwrap();
    }
    assert_ne!(
        weights(&straight),
        weights(&plain),
        "the bank's balls were served"
    );
    let dir = std::env::temp_dir().join(format!("rally-ppo-bank-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let run = RunDir::open(&dir).unwrap();
    let mut first = Trainer::new(m.clone(), Method::Kmac, cfg.clone(), 12).unwrap();
    first.set_bank(balls.clone().into());
    for _ in 0..2 {
        first.iterate().unwrap();
    }
    run.save_state(&first).unwrap();
    drop(first);
    let mut resumed = run.load(m).unwrap();
    assert_eq!(resumed.bank.as_deref(), Some(&balls[..]));
    for _ in 0..2 {
        resumed.iterate().unwrap();
    }
    assert_eq!(weights(&resumed), weights(&straight));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_warm_start_carries_the_optimiser_so_its_first_update_stays_near_the_start() {
    // From the committed Diff-Muscle run (its adaptive schedule at the 1e-5 floor): the warm start
    // takes its moments and learning rate, and the first iteration's policy change stays near the
    // schedule's target. With a fresh optimiser at the configured 5e-4 — what warm starts did — the
    // same iteration moves the policy far further.
    let run = RunDir::open(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/runs/kmac"
    )))
    .unwrap();
    let saved = run.read_state().unwrap();
    let mut cfg = TrainConfig::default();
    cfg.ppo.envs = 16;
    cfg.ppo.steps_per_env = 32;
    let first_kl = |fresh: bool| {
        let mut t = Trainer::new(model(), Method::Kmac, cfg.clone(), 3).unwrap();
        let how = if fresh {
            WarmOptimiser::Fresh
        } else {
            WarmOptimiser::Carry
        };
        run.warm_start(&mut t, how).unwrap();
        assert_eq!(t.progress.iteration, 0);
        if fresh {
            assert_eq!(t.adam.lr, cfg.ppo.learning_rate);
        } else {
            assert_eq!(t.adam.lr, saved.learning_rate);
            assert_eq!(t.adam.t, saved.adam_steps);
        }
        t.iterate().unwrap().kl
    };
    let (carried, fresh) = (first_kl(false), first_kl(true));
    eprintln!("first-iteration KL: optimiser carried {carried:.4}, fresh {fresh:.4}");
    assert!(carried < 3.0 * cfg.ppo.desired_kl, "{carried}");
    assert!(fresh > 5.0 * carried, "{fresh} vs {carried}");
}

#[test]
fn validation_plays_and_keeps_the_policy_at_its_noise_scale() {
    let mut cfg = small(2, 4, 10);
    let plain = Trainer::new(model(), Method::Kmac, cfg.clone(), 4).unwrap();
    let same = plain.validation_checkpoint("v", "", "").unwrap();
    assert_eq!(
        same,
        plain.checkpoint("v", "", "").unwrap(),
        "scale 1: as trained"
    );
    assert_eq!(same.action_noise, None, "trained without action noise");
    cfg.validation.noise_scale = 0.5;
    cfg.controller.action_noise = 0.05;
    let t = Trainer::new(model(), Method::Kmac, cfg.clone(), 4).unwrap();
    let (trained, played) = (
        t.checkpoint("v", "", "").unwrap(),
        t.validation_checkpoint("v", "", "").unwrap(),
    );
    let (s0, s1) = (trained.policy_std.unwrap(), played.policy_std.unwrap());
    assert!(s0.iter().zip(&s1).all(|(a, b)| *b == 0.5 * a && *a > 0.0));
    assert_eq!(played.policy, trained.policy);
    assert_eq!(
        trained.action_noise,
        Some(0.05),
        "the training's action noise is recorded"
    );
    assert_eq!(
        played.action_noise,
        Some(0.025),
        "and scaled with the policy's σ"
    );
    assert_eq!(played.training.unwrap().noise_scale, Some(0.5));
    cfg.validation.noise_scale = -0.5;
    assert_eq!(
        cfg.validate().unwrap_err(),
        "validation.noise_scale: out of range"
    );
}

#[test]
fn the_bound_loss_pulls_pinned_means_back_towards_the_bound() {
    // The rally built-in's source (tests/fixtures/runs/kmac-bank2-init) has means far past ±1 on several joints
    // (their samples almost always clip, so the surrogate gives them no gradient). Four iterations
    // with the bound loss (a fresh optimiser, as the rally fine-tunings start) bring them part of the
    // way in; without it, they stay about where they were.
    let run = RunDir::open(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/fixtures/runs/kmac-bank2-init"
    )))
    .unwrap();
    let mut cfg = TrainConfig::default();
    cfg.ppo.envs = 8;
    cfg.ppo.steps_per_env = 32;
    // Past the bound, at the normalised observation's mean (the zero vector).
    let excess = |t: &Trainer| -> f32 {
        let obs = candle_core::Tensor::zeros(
            (1, t.obs_dim()),
            candle_core::DType::F32,
            &candle_core::Device::Cpu,
        )
        .unwrap();
        let mu = t
            .net
            .mean(&obs)
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap();
        mu.iter().map(|m| (m.abs() - 1.0).max(0.0)).sum()
    };
    let after = |coef: f64| {
        let mut c = cfg.clone();
        c.ppo.bound_coef = coef;
        let mut t = Trainer::new(model(), Method::Kmac, c, 5).unwrap();
        run.warm_start(&mut t, WarmOptimiser::Fresh).unwrap();
        let start = excess(&t);
        for _ in 0..4 {
            t.iterate().unwrap();
        }
        (start, excess(&t))
    };
    let ((start, plain), (_, bounded)) = (after(0.0), after(1.0));
    eprintln!("summed excess past ±1: start {start:.3}, plain {plain:.3}, bound loss {bounded:.3}");
    assert!(start > 1.0, "the start has pinned means: {start}");
    assert!(bounded < 0.8 * start, "{bounded} vs {start}");
    assert!(bounded < 0.8 * plain, "{bounded} vs {plain}");
    cfg.ppo.bound_coef = -1.0;
    assert_eq!(cfg.validate().unwrap_err(), "ppo.bound_coef: out of range");
}

#[test]
fn the_task_rules_setting_reaches_both_training_environments() {
    use agents::ppo::trainer::envs::{make_env, TrainingEnv};
    let m = model();
    let arena = sim::config::ArenaConfig::default();
    assert_eq!(
        TrainConfig::default().task_rules,
        agents::env::TaskRules::Ours
    );
    for env in ["single", "rally"] {
        let text = format!("env = \"{env}\"\ntask_rules = \"official\"\n");
        let c: TrainConfig = toml::from_str(&text).expect("parses");
        let controller = c.controller(Method::Kmac, &m);
        let rules = match make_env(&m, &arena, &controller, &c, None)
            .expect("builds")
            .0
        {
            TrainingEnv::Single(e) => e.task_rules,
            TrainingEnv::Rally(e) => e.task_rules,
        };
        assert_eq!(rules, agents::env::TaskRules::Official, "{env}");
    }
    let bad = toml::from_str::<TrainConfig>("task_rules = \"strict\"").unwrap_err();
    assert!(
        bad.to_string().contains("ours") && bad.to_string().contains("official"),
        "{bad}"
    );
}

#[test]
fn the_official_position_target_and_coupled_clamp_reach_the_environments_and_the_checkpoint() {
    use agents::controller::ControllerSpec;
    use agents::env::PositionTarget;
    use agents::ppo::trainer::envs::{make_env, TrainingEnv};
    let m = model();
    let arena = sim::config::ArenaConfig::default();
    let default = TrainConfig::default();
    assert_eq!(default.position_target, PositionTarget::Strike);
    assert!(!default.controller.kmac_clamp_coupled);
    for env in ["single", "rally"] {
        let text = format!(
            "env = \"{env}\"\nposition_target = \"contact\"\n[controller]\nkmac_clamp_coupled = true\n"
        );
        let c: TrainConfig = toml::from_str(&text).expect("parses");
        let controller = c.controller(Method::Kmac, &m);
        let aim = match make_env(&m, &arena, &controller, &c, None)
            .expect("builds")
            .0
        {
            TrainingEnv::Single(e) => e.position_target,
            TrainingEnv::Rally(e) => e.position_target,
        };
        assert_eq!(aim, PositionTarget::Contact, "{env}");
        // The checkpoint records the clamp; one without it (every checkpoint before the setting)
        // serialises without the field and reads back without the clamp.
        let on = serde_json::to_value(&controller).unwrap();
        assert_eq!(on["clamp_coupled"], serde_json::Value::Bool(true));
        let off = serde_json::to_value(default.controller(Method::Kmac, &m)).unwrap();
        assert!(off.get("clamp_coupled").is_none(), "{off}");
        let back: ControllerSpec = serde_json::from_value(off).unwrap();
        assert!(matches!(
            back,
            ControllerSpec::Kmac {
                clamp_coupled: false,
                ..
            }
        ));
    }
    let bad = toml::from_str::<TrainConfig>("position_target = \"centre\"").unwrap_err();
    assert!(
        bad.to_string().contains("strike") && bad.to_string().contains("contact"),
        "{bad}"
    );
}

#[test]
fn a_privileged_critic_sees_what_the_policy_does_not_and_only_the_critic_does() {
    let m = model();
    let mut cfg = small(4, 8, 2);
    cfg.ppo.critic = CriticInput::Privileged;
    let mut t = Trainer::new(m.clone(), Method::Kmac, cfg.clone(), 5).unwrap();
    for _ in 0..2 {
        t.iterate().unwrap();
    }
    // The actor reads the observation; the critic reads it and, after it, the elapsed share of the
    // episode, one velocity per muscle, the paddle's mass and the ball's friction.
    let obs = t.obs_dim();
    let muscles = m.muscles().count();
    assert_eq!(t.net.actor[0].w.as_tensor().dims(), &[32, obs]);
    assert_eq!(
        t.net.critic[0].w.as_tensor().dims(),
        &[32, obs + muscles + 3]
    );
    let stats = t.critic_normalizer.as_ref().expect("privileged statistics");
    let n = stats.mean.len();
    assert_eq!(n, muscles + 3);
    assert!(
        stats.mean[0] > 0.0 && stats.mean[0] < 1.0,
        "elapsed share {}",
        stats.mean[0]
    );
    assert!(stats.mean[1..n - 2].iter().all(|v| v.is_finite()));
    assert!(
        stats.mean[1..n - 2].iter().any(|v| *v != 0.0),
        "muscles moved"
    );
    assert!(stats.mean[n - 2] > 0.0, "the paddle has mass");
    assert_eq!(stats.mean[n - 1], 1.0, "the built-in arena's ball friction");
    // The checkpoint's policy is the actor alone: it plays as any other.
    let ck = t.checkpoint("privileged", "test", "none").unwrap();
    assert_eq!(ck.policy.as_ref().unwrap().layers[0].weights[0].len(), obs);

    // The default critic sees the actor's observation, and its state says nothing of the switch.
    let plain = Trainer::new(m.clone(), Method::Kmac, small(4, 8, 2), 5).unwrap();
    assert_eq!(plain.net.critic[0].w.as_tensor().dims(), &[32, obs]);
    assert!(plain.critic_normalizer.is_none());
    let dir = std::env::temp_dir().join(format!("rally-ppo-critic-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let run = RunDir::open(&dir).unwrap();
    run.save_state(&plain).unwrap();
    let state = std::fs::read_to_string(dir.join("resume/state.json")).unwrap();
    assert!(
        !state.contains("critic"),
        "a default run's state names no critic setting"
    );
    // A warm start keeps its critic: one of the other kind is refused.
    let mut other = Trainer::new(m.clone(), Method::Kmac, cfg.clone(), 6).unwrap();
    let err = run
        .warm_start(&mut other, WarmOptimiser::Carry)
        .unwrap_err();
    assert!(err.contains("ppo.critic"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);

    // Set in a configuration file; refused in the rally environment, which has no such input.
    let parsed: TrainConfig = toml::from_str("[ppo]\ncritic = \"privileged\"\n").unwrap();
    assert_eq!(parsed.ppo.critic, CriticInput::Privileged);
    let mut rally = parsed.clone();
    rally.env = agents::ppo::TrainEnv::Rally;
    let err = rally.validate().unwrap_err();
    assert!(err.contains("ppo.critic"), "{err}");
}

#[test]
fn a_checkpoint_file_warm_start_plays_as_the_checkpoint_and_its_critic_learns_alone_first() {
    // A short run, saved as validation saves best.json (at half its σ).
    let mut cfg = small(4, 8, 10);
    cfg.validation.noise_scale = 0.5;
    let mut a = Trainer::new(model(), Method::Kmac, cfg.clone(), 5).unwrap();
    for _ in 0..2 {
        a.iterate().unwrap();
    }
    let ck = a.validation_checkpoint("a", "", "").unwrap();
    let trained = a.checkpoint("a", "", "").unwrap();
    // Another seed's run, from it: the policy, its trained σ and the observation statistics.
    cfg.ppo.critic_warmup = 2;
    let mut b = Trainer::new(model(), Method::Kmac, cfg.clone(), 6).unwrap();
    b.warm_start_from_checkpoint(&ck, "a.json").unwrap();
    let start = b.checkpoint("b", "", "").unwrap();
    assert_eq!(start.policy, trained.policy);
    assert_eq!(start.observation.mean, trained.observation.mean);
    for (x, y) in start.observation.std.iter().zip(&trained.observation.std) {
        assert!((x - y).abs() < 1e-12, "{x} vs {y}");
    }
    for (x, y) in start
        .policy_std
        .unwrap()
        .iter()
        .zip(trained.policy_std.unwrap())
    {
        assert!((x / y - 1.0).abs() < 1e-6, "σ {x} vs trained {y}");
    }
    assert!(b.progress.warm_start.as_deref().unwrap().contains("a.json"));
    // Its statistics move slowly, as in a long run: counted at least a million observations.
    assert_eq!(b.normalizer.count, 1_000_000);
    // Its first two iterations move the critic only; the third the policy too.
    let actor = |t: &Trainer| {
        let w = weights(t);
        let n = 2 * t.net.actor.len();
        (w[..n].to_vec(), w.last().unwrap().clone())
    };
    let critic = |t: &Trainer| {
        let w = weights(t);
        w[2 * t.net.actor.len()..w.len() - 1].to_vec()
    };
    let (policy0, critic0) = (actor(&b), critic(&b));
    for _ in 0..2 {
        b.iterate().unwrap();
    }
    assert_eq!(
        actor(&b),
        policy0,
        "the policy and σ keep still while the critic warms up"
    );
    assert_ne!(critic(&b), critic0, "the critic learns");
    assert_eq!(
        b.adam.lr, cfg.ppo.learning_rate,
        "the adaptive schedule waits"
    );
    let n = b.net.actor.len() * 2;
    let steps = (cfg.ppo.epochs * cfg.ppo.minibatches * 2) as u64;
    let vs = b.adam.var_steps.clone();
    let (policy_steps, critic_steps) = (vs[..n].to_vec(), vs[n..vs.len() - 1].to_vec());
    assert!(
        policy_steps.iter().all(|&s| s == 0) && vs[vs.len() - 1] == 0,
        "{vs:?}"
    );
    assert!(critic_steps.iter().all(|&s| s == steps), "{vs:?}");
    b.iterate().unwrap();
    assert_ne!(
        actor(&b).0,
        policy0.0,
        "after the warm-up the policy learns"
    );
    let vs = &b.adam.var_steps;
    assert!(
        vs[..n]
            .iter()
            .chain(&vs[vs.len() - 1..])
            .all(|&s| s == steps / 2),
        "the policy's Adam counts its own steps: {vs:?}"
    );
    // What does not fit is refused, naming why.
    let mut other = small(4, 8, 10);
    other.ppo.hidden = vec![16, 16];
    let mut c = Trainer::new(model(), Method::Kmac, other, 6).unwrap();
    let err = c.warm_start_from_checkpoint(&ck, "a.json").unwrap_err();
    assert!(err.contains("ppo.hidden"), "{err}");
    let mut d = Trainer::new(model(), Method::Muscle, small(4, 8, 10), 6).unwrap();
    let err = d.warm_start_from_checkpoint(&ck, "a.json").unwrap_err();
    assert!(err.contains("training.method"), "{err}");
    let mut gains = small(4, 8, 10);
    gains.controller.kmac.kp = 20.0;
    let mut f = Trainer::new(model(), Method::Kmac, gains, 6).unwrap();
    let err = f.warm_start_from_checkpoint(&ck, "a.json").unwrap_err();
    assert!(err.contains("controller.gains"), "{err}");
    let mut tanh = ck.clone();
    tanh.policy.as_mut().unwrap().layers[0].activation = agents::checkpoint::Activation::Tanh;
    tanh.policy.as_mut().unwrap().layers[1].weights[0][0] += 1.0;
    let mut g = Trainer::new(model(), Method::Kmac, cfg.clone(), 6).unwrap();
    let before = (weights(&g), g.normalizer.clone());
    let err = g.warm_start_from_checkpoint(&tanh, "a.json").unwrap_err();
    assert!(err.contains("policy.layers[0].activation"), "{err}");
    assert_eq!(
        (weights(&g), g.normalizer.clone()),
        before,
        "a refused checkpoint changes nothing"
    );
}
