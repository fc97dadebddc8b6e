//! The controllers and the IK on the default robot: K-MAC holds a posture against gravity, no
//! controller ever asks a muscle to push or an activation to leave [0, 1], Muscle-PD relaxes at its
//! target, DynSyn's grouping is deterministic, and the IK reaches the hitting plane.

use std::sync::Arc;

use agents::controller::{
    direct_controls, muscle_pd_control, ActionSpace, Kmac, MuscleNow, MusclePd, PdGains, Synergies,
};
use agents::ik::{BladeTarget, PaddleIk};
use nalgebra::Vector3;
use sim::config::ArenaConfig;
use sim::model::Model;
use sim::rng::Rng;
use sim::robot::{GripPhase, Robot};

fn model() -> Arc<Model> {
    Arc::new(sim::config::default_model())
}

fn ready(model: &Model) -> Vec<f64> {
    let mut q = sim::episode::ready_pose(model).unwrap();
    model.apply_couplings(&mut q);
    q
}

/// A robot at the ready posture and joint targets drawn uniformly within each joint's range.
fn random_targets_at_ready(m: &Arc<Model>, seed: u64) -> (Robot, Vec<f64>) {
    let mut robot = Robot::new(m.clone(), &ArenaConfig::default().grip, sim::Side::A).unwrap();
    robot.reset(Some(&ready(m)));
    let targets = random_targets(m, &ActionSpace::new(m), &mut Rng::seeded(seed));
    (robot, targets)
}

/// A target for each of `space`'s joints, uniform within its range.
fn random_targets(m: &Model, space: &ActionSpace, rng: &mut Rng) -> Vec<f64> {
    space
        .joints
        .iter()
        .map(|&j| {
            let r = m.joints[j].range.unwrap_or([-1.0, 1.0]);
            rng.uniform(r[0], r[1])
        })
        .collect()
}

/// K-MAC's controls for `targets` from the robot's state, one 10 ms control step.
fn kmac_controls(m: &Model, robot: &Robot, targets: &[f64], kmac: &mut Kmac) -> Vec<f64> {
    let mut ctrl = vec![0.0; m.actuators.len()];
    kmac.controls(m, &robot.state, targets, 0.01, &mut ctrl);
    ctrl
}

#[test]
fn kmac_holds_the_ready_posture_against_gravity() {
    let m = model();
    let mut robot = Robot::new(m.clone(), &ArenaConfig::default().grip, sim::Side::A).unwrap();
    let q0 = ready(&m);
    robot.reset(Some(&q0));
    let mut kmac = Kmac::new(&m, PdGains { kp: 40.0, kd: 3.0 });
    let targets: Vec<f64> = kmac
        .space
        .joints
        .iter()
        .map(|&j| q0[m.joints[j].qpos_adr])
        .collect();
    let mut ctrl = vec![0.0; m.actuators.len()];
    for _ in 0..100 {
        kmac.controls(&m, &robot.state, &targets, 0.01, &mut ctrl);
        robot.state.ctrl.copy_from_slice(&ctrl);
        for _ in 0..5 {
            robot.physics_step();
        }
    }
    // Without K-MAC the arm falls ~1 rad in that second; with it every joint stays near its target.
    for (&j, &z) in kmac.space.joints.iter().zip(&targets) {
        let err = (robot.state.qpos[m.joints[j].qpos_adr] - z).abs();
        assert!(
            err < 0.12,
            "{} drifted {err:.3} rad from its target",
            m.joints[j].name
        );
    }
    assert_eq!(robot.phase, GripPhase::Held);
}

#[test]
fn no_controller_asks_a_muscle_to_push_or_leaves_0_1() {
    let m = model();
    let mut robot = Robot::new(m.clone(), &ArenaConfig::default().grip, sim::Side::A).unwrap();
    robot.reset(Some(&ready(&m)));
    let mut kmac = Kmac::new(&m, PdGains { kp: 80.0, kd: 2.0 });
    let mut pd = MusclePd::new(&m, PdGains::MUSCLE_PD);
    let space = ActionSpace::new(&m);
    let mut rng = Rng::seeded(5);
    let mut ctrl = vec![0.0; m.actuators.len()];
    for step in 0..200 {
        // Random targets inside the joint ranges (and random lengths inside the length ranges).
        let targets = random_targets(&m, &space, &mut rng);
        match step % 3 {
            0 => kmac.controls(&m, &robot.state, &targets, 0.01, &mut ctrl),
            1 => {
                let lengths: Vec<f64> = space
                    .muscles
                    .iter()
                    .map(|&a| {
                        let lr = m.actuators[a].lengthrange;
                        rng.uniform(lr[0], lr[1])
                    })
                    .collect();
                pd.controls(&m, &robot.state, &lengths, &[0.0, 0.0], 0.01, &mut ctrl)
            }
            _ => {
                let raw: Vec<f64> = space
                    .muscles
                    .iter()
                    .map(|_| rng.uniform(-0.5, 1.5))
                    .collect();
                direct_controls(&space, &raw, &[0.1, -0.1], &mut ctrl)
            }
        }
        for &a in &space.muscles {
            assert!(
                (0.0..=1.0).contains(&ctrl[a]),
                "control {} of {}",
                ctrl[a],
                m.actuators[a].name
            );
        }
        robot.state.ctrl.copy_from_slice(&ctrl);
        for _ in 0..5 {
            robot.physics_step();
            for &a in &space.muscles {
                assert!(
                    robot.data.actuator_force[a] <= 1e-12,
                    "{} pushes",
                    m.actuators[a].name
                );
                assert!((-1e-12..=1.0 + 1e-12).contains(&robot.state.act[a]));
            }
        }
    }
}

#[test]
fn at_its_target_length_and_at_rest_a_muscle_is_told_to_relax() {
    let m = model();
    let a = m.actuator("BRA").unwrap();
    let lr = m.actuators[a].lengthrange;
    // A length where the passive force is zero (short of the optimum).
    let l = lr[0] + 0.2 * (lr[1] - lr[0]);
    let u = muscle_pd_control(
        &m,
        a,
        l,
        &MuscleNow {
            length: l,
            velocity: 0.0,
            act: 0.5,
        },
        &PdGains { kp: 10.0, kd: 1.0 },
        0.01,
    );
    // act* = 0, so the control drops below the activation to deactivate within one step (τ_deact).
    assert!(u < 0.5, "{u}");
    // Too long by 2 cm: it pulls, with the control that reaches act* in one 10 ms step from rest
    // (τ = τ_act·0.5 = 5 ms, so u = act*/2).
    let too_long = MuscleNow {
        length: l + 0.02,
        velocity: 0.0,
        act: 0.0,
    };
    let u = muscle_pd_control(&m, a, l, &too_long, &PdGains { kp: 10.0, kd: 1.0 }, 0.01);
    assert!(u > 0.2 && u <= 0.5, "{u}");
}

#[test]
fn dynsyn_groups_are_deterministic_and_cover_every_muscle() {
    let m = model();
    let a = Synergies::derive(&m, 12, 3);
    let b = Synergies::derive(&m, 12, 3);
    assert_eq!(a, b);
    assert_eq!(a.group_of.len(), m.muscles().count());
    for g in 0..12 {
        assert!(a.group_of.contains(&g), "group {g} is empty");
    }
    // Left and right rectus abdominis move together in every motion: same group.
    let space = ActionSpace::new(&m);
    let idx = |name: &str| {
        space
            .muscles
            .iter()
            .position(|&x| m.actuators[x].name == name)
            .unwrap()
    };
    assert_eq!(a.group_of[idx("TRIlat")], a.group_of[idx("TRImed")]);
}

#[test]
fn ik_reaches_the_hitting_plane_with_the_blade_facing_the_net() {
    let m = model();
    let mut ik = PaddleIk::new(
        &m,
        m.body("paddle").unwrap(),
        sim::geometry::PaddleShape::from_model(&m, m.body("paddle").unwrap())
            .unwrap()
            .blade
            .center,
        &[m.joint("grip").unwrap()],
    );
    let q0 = ready(&m);
    let mut worst: f64 = 0.0;
    for y in [-0.6, -0.2, 0.2, 0.6, 1.0] {
        for z in [0.95, 1.15, 1.35] {
            let t = BladeTarget {
                pos: Vector3::new(1.8, y, z),
                normal: Vector3::new(-1.0, 0.1, 0.1).normalize(),
            };
            let s = ik.solve_near(&m, &q0, Some(&q0), &t, 200);
            worst = worst.max(s.position_error);
            assert!(
                s.normal_error < 0.05,
                "y {y} z {z}: normal off by {}",
                s.normal_error
            );
            for j in &m.joints {
                if let Some([lo, hi]) = j.range {
                    assert!(
                        s.qpos[j.qpos_adr] >= lo - 1e-9 && s.qpos[j.qpos_adr] <= hi + 1e-9,
                        "{} out of range",
                        j.name
                    );
                }
            }
        }
    }
    assert!(worst < 0.01, "worst position error {worst}");
}

#[test]
fn every_observation_and_action_entry_has_a_name() {
    use agents::controller::ActionMapper;
    use agents::observation::{observation_names, ObsBlock, Observer};
    use agents::ppo::{Method, TrainConfig};
    let m = model();
    let names = observation_names(&m, &ObsBlock::ALL);
    assert_eq!(
        names.len(),
        Observer::new(&m, ObsBlock::ALL.to_vec(), 0).size()
    );
    assert_eq!(names[0], "qpos.pelvis_tx");
    assert!(names.contains(&"muscle_length.FDS".to_string()));
    assert_eq!(names.last().unwrap(), "command.t_strike");
    let unique: std::collections::HashSet<&String> = names.iter().collect();
    assert_eq!(unique.len(), names.len(), "observation names repeat");
    let config = TrainConfig::default();
    for method in Method::ALL {
        let mapper = ActionMapper::new(&m, &config.controller(method, &m));
        let names = mapper.action_names(&m);
        assert_eq!(names.len(), mapper.action_dim(), "{method:?}");
        let unique: std::collections::HashSet<&String> = names.iter().collect();
        assert_eq!(unique.len(), names.len(), "{method:?}: action names repeat");
    }
}

#[test]
fn kmac_in_the_official_form_sends_its_activation_targets_clamped_and_noise_is_seeded() {
    let m = model();
    let (robot, targets) = random_targets_at_ready(&m, 9);
    let clamp = agents::controller::official_activation_clamp();
    assert!(
        (clamp[0] - 0.000_552_778_636_9).abs() < 1e-12
            && (clamp[1] - 0.924_141_819_98).abs() < 1e-10
    );
    let gains = PdGains { kp: 10.0, kd: 1.0 };
    let space = ActionSpace::new(&m);
    let controls = |kmac: &mut Kmac| kmac_controls(&m, &robot, &targets, kmac);
    let ours = controls(&mut Kmac::new(&m, gains));
    let official = controls(&mut Kmac::new(&m, gains).with_activation_clamp(Some(clamp)));
    // Each muscle's control is its activation target, within the clamp (ours inverts the
    // activation dynamics instead, so the two differ wherever the activation must move).
    let mut differ = 0;
    for &a in &space.muscles {
        assert!(
            (clamp[0]..=clamp[1]).contains(&official[a]),
            "{}",
            official[a]
        );
        differ += ((official[a] - ours[a]).abs() > 1e-6) as usize;
    }
    assert!(
        differ > space.muscles.len() / 2,
        "{differ} of {} differ",
        space.muscles.len()
    );
    // Noise: the same seed, the same controls; another seed, others; all within the clamp.
    let noisy = |seed: u64| {
        let mut k = Kmac::new(&m, gains).with_activation_clamp(Some(clamp));
        k.set_activation_noise(0.1, seed);
        controls(&mut k)
    };
    let (a, b, c) = (noisy(1), noisy(1), noisy(2));
    assert_eq!(a, b);
    assert_ne!(a, c);
    assert_ne!(a, official);
    assert!(space
        .muscles
        .iter()
        .all(|&i| (clamp[0]..=clamp[1]).contains(&a[i])));
}

#[test]
fn the_clamped_normal_mean_matches_its_closed_form_and_sampling() {
    use agents::controller::clamped_normal_mean;
    let [lo, hi] = agents::controller::official_activation_clamp();
    // At the lower bound, far from the upper: half the noise is rectified, lo + σ/√(2π).
    let at_lo = clamped_normal_mean(lo, 0.1, lo, hi);
    assert!((at_lo - (lo + 0.1 / (2.0 * std::f64::consts::PI).sqrt())).abs() < 1e-12);
    // No noise: the clamp.
    assert_eq!(clamped_normal_mean(-0.3, 0.0, lo, hi), lo);
    assert_eq!(clamped_normal_mean(0.5, 0.0, lo, hi), 0.5);
    // Against 200 000 samples of the clamp of noisy controls, below, at, inside and near the top.
    let mut rng = Rng::seeded(5);
    for &(mu, sigma) in &[
        (-0.2, 0.1),
        (lo, 0.1),
        (0.05, 0.1),
        (0.5, 0.2),
        (0.9, 0.1),
        (1.2, 0.3),
    ] {
        let n = 200_000;
        let sampled = (0..n)
            .map(|_| (mu + sigma * rng.normal()).clamp(lo, hi))
            .sum::<f64>()
            / n as f64;
        let exact = clamped_normal_mean(mu, sigma, lo, hi);
        assert!(
            (sampled - exact).abs() < 5.0 * sigma / (n as f64).sqrt(),
            "mu {mu}, sigma {sigma}: sampled {sampled}, closed form {exact}"
        );
        assert!((lo..=hi).contains(&exact));
    }
}

#[test]
fn kmac_plays_the_mean_of_the_activation_noise_it_was_trained_with() {
    let m = model();
    let (robot, targets) = random_targets_at_ready(&m, 11);
    let clamp = agents::controller::official_activation_clamp();
    let gains = PdGains { kp: 10.0, kd: 1.0 };
    let space = ActionSpace::new(&m);
    let controls = |kmac: &mut Kmac| kmac_controls(&m, &robot, &targets, kmac);
    let official = || Kmac::new(&m, gains).with_activation_clamp(Some(clamp));
    let plain = controls(&mut official());
    let expected = controls(&mut official().with_expected_activation_noise(Some(0.1)));
    // Relaxed muscles are raised by the rectified noise; none is lowered below its plain control
    // by more than the clamp's top allows.
    let relaxed: Vec<usize> = space
        .muscles
        .iter()
        .copied()
        .filter(|&a| plain[a] <= clamp[0])
        .collect();
    assert!(!relaxed.is_empty());
    for &a in &relaxed {
        assert!((expected[a] - plain[a] - 0.1 / (2.0 * std::f64::consts::PI).sqrt()).abs() < 1e-3);
    }
    // The expectation is what the noisy controls average to: 4 000 draws, each muscle within
    // 5 standard errors.
    let draws = 4_000;
    let mut mean = vec![0.0; m.actuators.len()];
    for seed in 0..draws {
        let mut k = official();
        k.set_activation_noise(0.1, seed);
        for (s, c) in mean.iter_mut().zip(controls(&mut k)) {
            *s += c / draws as f64;
        }
    }
    for &a in &space.muscles {
        assert!(
            (mean[a] - expected[a]).abs() < 5.0 * 0.1 / (draws as f64).sqrt(),
            "muscle {a}: noisy mean {}, expectation {}",
            mean[a],
            expected[a]
        );
    }
    // While training noise is drawn, it is the noise that plays, not the expectation.
    let mut trained = official().with_expected_activation_noise(Some(0.1));
    trained.set_activation_noise(0.1, 7);
    let mut noisy = official();
    noisy.set_activation_noise(0.1, 7);
    assert_eq!(controls(&mut trained), controls(&mut noisy));
}

/// With `clamp_coupled` (the official code's form) K-MAC keeps every coupled joint's target inside
/// its range where the coupling's polynomial leaves it, and changes nothing else; without it the
/// polynomial's value stands (the checkpoints trained before the setting).
#[test]
fn kmac_clamps_coupled_targets_to_their_ranges_when_asked() {
    let mut m = sim::config::default_model();
    // The default robot's spine couplings stay in range; steepened three times they leave it.
    for c in &mut m.couplings {
        for k in &mut c.coef[1..] {
            *k *= 3.0;
        }
    }
    let m = Arc::new(m);
    let mut robot = Robot::new(m.clone(), &ArenaConfig::default().grip, sim::Side::A).unwrap();
    robot.reset(Some(&ready(&m)));
    let space = ActionSpace::new(&m);
    let gains = PdGains { kp: 10.0, kd: 1.0 };
    for end in [0, 1] {
        let targets: Vec<f64> = space
            .joints
            .iter()
            .map(|&j| m.joints[j].range.map_or(0.0, |r| r[end]))
            .collect();
        let open = Kmac::new(&m, gains)
            .target_configuration(&m, &robot.state, &targets)
            .to_vec();
        let clamped = Kmac::new(&m, gains)
            .with_clamp_coupled(true)
            .target_configuration(&m, &robot.state, &targets)
            .to_vec();
        let mut outside = 0;
        for (i, (a, b)) in open.iter().zip(&clamped).enumerate() {
            let coupled = m
                .couplings
                .iter()
                .find(|c| m.joints[c.dependent].qpos_adr == i);
            match coupled.and_then(|c| m.joints[c.dependent].range) {
                Some([lo, hi]) => {
                    assert!(lo <= *b && *b <= hi, "qpos {i}: {b} outside [{lo}, {hi}]");
                    assert_eq!(*b, a.clamp(lo, hi));
                    outside += usize::from(*a < lo || *a > hi);
                }
                None => assert_eq!(a.to_bits(), b.to_bits(), "qpos {i}"),
            }
        }
        assert!(outside > 0, "no coupled target left its range at end {end}");
    }
}
