//! The single-serve environment's lead-in (`lead_in` of the training configuration): in that share
//! of episodes the robot's own return flies away first, unjudged, with the `ready` term paid and no
//! stroke term, then the episode's serve comes; the draw comes after the serve's, so the other
//! episodes are served exactly as without it; the configuration refuses a share outside [0, 1] and a
//! lead-in in the rally environment, naming the field; the checkpoint records it.

use std::sync::Arc;

use agents::env::single::{Env, LeadInLength};
use agents::ppo::trainer::envs::{make_env, TrainingEnv};
use agents::ppo::trainer::Trainer;
use agents::ppo::{Method, TrainConfig, TrainEnv};
use sim::config::ArenaConfig;

fn model() -> Arc<sim::model::Model> {
    Arc::new(sim::config::default_model())
}

fn env(lead_in: f64) -> Box<Env> {
    env_with(lead_in, LeadInLength::Full)
}

fn env_with(lead_in: f64, lead_in_length: LeadInLength) -> Box<Env> {
    let m = model();
    let config = TrainConfig {
        lead_in,
        lead_in_length,
        ..TrainConfig::default()
    };
    let controller = config.controller(Method::Kmac, &m);
    match make_env(&m, &ArenaConfig::default(), &controller, &config, None).unwrap() {
        (TrainingEnv::Single(env), ..) => env,
        _ => unreachable!("the default environment is the single serve"),
    }
}

#[test]
fn a_lead_in_pays_the_ready_term_and_no_stroke_until_the_serve_comes() {
    let mut e = env(1.0);
    let zero = vec![0.0; e.action_dim()];
    for seed in 0..3 {
        e.reset(seed);
        assert!(e.episode.in_lead_in());
        assert!(
            e.observer.command().is_none(),
            "no command for a ball flying away"
        );
        let mut lead = 0;
        while e.episode.in_lead_in() {
            let tr = e.step(&zero);
            lead += 1;
            assert!(!tr.done && !tr.hit, "seed {seed}, step {lead}");
            assert!(
                tr.terms.ready > 0.0 && tr.terms.ready <= 1.0,
                "{:?}",
                tr.terms
            );
            assert_eq!(
                (tr.terms.hit, tr.terms.landing, tr.terms.position),
                (0.0, 0.0, 0.0),
                "seed {seed}, step {lead}"
            );
        }
        assert!(lead > 20, "seed {seed}: a lead-in of {lead} steps");
        // The serve is in play: it is planned for, and the ready term is no longer paid.
        let tr = e.step(&zero);
        assert!(e.observer.command().is_some(), "seed {seed}");
        assert_eq!(tr.terms.ready, 0.0);
        let mut done = tr.done;
        while !done {
            done = e.step(&zero).done;
        }
        assert!(e.episode.steps > lead);
    }
}

/// Control steps of the lead-in of the episode `e` was just reset to.
fn lead_in_steps(e: &mut Env) -> usize {
    let zero = vec![0.0; e.action_dim()];
    let mut n = 0;
    while e.episode.in_lead_in() {
        e.step(&zero);
        n += 1;
    }
    n
}

#[test]
fn spread_lead_ins_are_cut_anywhere_in_the_flight_of_the_same_balls() {
    let (mut full, mut spread) = (env(1.0), env_with(1.0, LeadInLength::Spread));
    let mut shares = Vec::new();
    for seed in 0..30 {
        full.reset(seed);
        spread.reset(seed);
        let (f, s) = (lead_in_steps(&mut full), lead_in_steps(&mut spread));
        assert!((1..=f).contains(&s), "seed {seed}: {s} of {f} steps");
        shares.push(s as f64 / f as f64);
    }
    let below = shares.iter().filter(|&&x| x < 0.5).count();
    assert!(
        (8..=22).contains(&below),
        "{below} of 30 below half: {shares:?}"
    );
}

#[test]
fn episodes_without_a_lead_in_are_served_as_without_the_setting() {
    let (mut plain, mut half) = (env(0.0), env(0.5));
    let mut with = 0;
    for seed in 0..40 {
        let a = plain.reset(seed);
        let b = half.reset(seed);
        assert_eq!(plain.episode.serve, half.episode.serve, "seed {seed}");
        if half.episode.in_lead_in() {
            with += 1;
            assert_ne!(a, b, "seed {seed}: the lead-in's ball is observed");
        } else {
            assert_eq!(a, b, "seed {seed}");
        }
        assert!(!plain.episode.in_lead_in());
    }
    assert!(
        (10..=30).contains(&with),
        "{with} of 40 episodes with a lead-in"
    );
}

#[test]
fn the_configuration_checks_the_share_and_the_checkpoint_records_it() {
    for bad in [-0.1, 1.5, f64::NAN] {
        let c = TrainConfig {
            lead_in: bad,
            ..TrainConfig::default()
        };
        assert!(c.validate().unwrap_err().contains("lead_in"), "{bad}");
    }
    let rally = TrainConfig {
        lead_in: 0.5,
        env: TrainEnv::Rally,
        ..TrainConfig::default()
    };
    let mut rally = rally;
    rally.controller.action_noise = 0.0;
    rally.controller.activation_noise = 0.0;
    assert!(rally.validate().unwrap_err().starts_with("lead_in"));
    let idle = TrainConfig {
        lead_in_length: LeadInLength::Spread,
        ..TrainConfig::default()
    };
    assert!(idle.validate().unwrap_err().starts_with("lead_in_length"));
    // Written only when set, so configurations and checkpoints without it read and write as before.
    let text = toml::to_string(&TrainConfig::default()).unwrap();
    assert!(!text.contains("lead_in"), "{text}");
    for (lead_in, length) in [
        (0.0, LeadInLength::Full),
        (0.5, LeadInLength::Full),
        (0.5, LeadInLength::Spread),
    ] {
        let mut c = TrainConfig {
            lead_in,
            lead_in_length: length,
            ..TrainConfig::default()
        };
        c.ppo.envs = 2;
        c.ppo.steps_per_env = 8;
        c.ppo.hidden = vec![16];
        let mut t = Trainer::new(model(), Method::Kmac, c, 3).unwrap();
        t.iterate().unwrap();
        let ck = t.checkpoint("probe", "test", "none").unwrap();
        let training = ck.training.as_ref().unwrap();
        assert_eq!(training.lead_in, (lead_in > 0.0).then_some(lead_in));
        let spread = length == LeadInLength::Spread;
        assert_eq!(training.lead_in_length, spread.then_some(length));
        let json = serde_json::to_string(&ck).unwrap();
        assert_eq!(json.contains("lead_in"), lead_in > 0.0);
    }
}

#[test]
fn an_evaluation_with_a_lead_in_plays_the_same_serves_after_the_robots_own_return() {
    let evaluation = |lead_in, episodes| agents::eval::Evaluation {
        model: model(),
        config: ArenaConfig::default(),
        preset: sim::arena::MYOCHALLENGE,
        kind: sim::serve::ServeKind::Stroke {
            server: sim::arena::Side::B,
        },
        episodes,
        seed: 5,
        lead_in,
    };
    let spec = agents::factory::PlayerSpec::scripted("scripted").unwrap();
    let run = |lead_in, episodes| {
        agents::eval::evaluate_traced(&evaluation(lead_in, episodes), &spec, &|| {}, true).unwrap()
    };
    let ((plain, plain_trace), (led, led_trace)) = (run(false, 3), run(true, 3));
    assert!(led.lead_in && !plain.lead_in);
    let json = serde_json::to_value(&plain).unwrap();
    assert!(json.get("lead_in").is_none(), "left out when off: {json}");
    assert_eq!(serde_json::to_value(&led).unwrap()["lead_in"], true);
    assert!(plain_trace.iter().all(|s| !s.lead_in));
    for episode in 0..3 {
        let of = |t: &[agents::eval::TraceStep]| -> Vec<agents::eval::TraceStep> {
            t.iter().filter(|s| s.episode == episode).cloned().collect()
        };
        let (a, b) = (of(&plain_trace), of(&led_trace));
        // Every step is traced, the lead-in's marked and numbered on with the rest.
        assert!(b.iter().enumerate().all(|(i, s)| s.step == i));
        let lead = b.iter().take_while(|s| s.lead_in).count();
        assert!(lead > 20 && b[lead..].iter().all(|s| !s.lead_in), "{lead}");
        assert!(!a.is_empty() && b.len() > lead);
        // The serve starts where the lead-in's ball left off, the same serve as without.
        let serve_time = b[lead].time;
        assert!((serve_time - lead as f64 * sim::arena::CONTROL_DT).abs() < 1e-9);
    }
    // The figures count from the serve on: an episode's steps are the trace's after its lead-in.
    let kind = sim::serve::ServeKind::Stroke {
        server: sim::arena::Side::B,
    };
    let bounce = sim::predict::BounceModel::for_table(&sim::arena::MYOCHALLENGE.table);
    let mut env =
        sim::episode::SingleServe::new(model(), &ArenaConfig::default(), sim::arena::MYOCHALLENGE)
            .unwrap();
    let mut player = spec.build(&model(), &sim::arena::MYOCHALLENGE, 0).unwrap();
    for seed in 0..3 {
        let mut rng = sim::rng::Rng::seeded(seed);
        env.reset(kind, &mut rng, None);
        let away = sim::serve::generate(
            sim::serve::ServeKind::Stroke {
                server: sim::arena::Side::A,
            },
            &mut rng,
            &bounce,
        );
        env.start_lead_in(away.ball, sim::episode::LEAD_IN_STEPS);
        let mut trace = Vec::new();
        let r = agents::eval::play_traced(&mut env, player.as_mut(), Some(&mut trace));
        let lead = trace.iter().filter(|s| s.lead_in).count();
        assert!(lead > 20, "seed {seed}: {lead}");
        assert_eq!(r.steps, trace.len() - lead, "seed {seed}");
        assert!(r.steps <= sim::arena::EPISODE_STEPS);
    }
}
