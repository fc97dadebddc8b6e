//! Our MJCF loader and kinematics against MuJoCo itself, on models under `fixtures/models/`.
//! The fixtures under `fixtures/mujoco/` were written by `tools/mujoco_crosscheck.py` (MuJoCo 4.0);
//! set `RALLY_MUJOCO_FIXTURES` to a folder of freshly generated ones to compare against a live MuJoCo
//! (`.ci/run` does).
//!
//! Tolerances: what the code reaches, with a margin of about 30× for a MuJoCo release that sums in
//! another order. Measured against the committed fixtures: lengths 3.5e-14 relative, moment arms
//! 3.5e-16 m, site positions ≤ 1e-15 m, mass matrix 3.6e-15 and bias 4.1e-14 relative, motions without
//! couplings 2.8e-16 rad after their whole run, activations exact. Motions with couplings differ
//! physically (ours exact, MuJoCo's soft) and keep their own bound.

use std::path::{Path, PathBuf};

use nalgebra::DMatrix;
use serde_json::Value;
use sim::kinematics::{actuator_length, Kinematics, TendonKinematics};
use sim::mjcf;
use sim::model::{Model, Transmission};

/// Kinematic quantities (lengths relative, moment arms and sites in m, velocities).
const KINEMATICS_TOL: f64 = 1e-12;
/// Mass matrix and bias forces, relative to their largest entry.
const DYNAMICS_TOL: f64 = 1e-12;
/// Joint positions after a whole recorded motion without couplings (rad or m).
const MOTION_TOL: f64 = 1e-12;
/// Activations after a whole recorded motion.
const ACTIVATION_TOL: f64 = 1e-12;

fn fixtures_dir() -> PathBuf {
    match std::env::var_os("RALLY_MUJOCO_FIXTURES") {
        Some(d) => PathBuf::from(d),
        None => Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/mujoco"),
    }
}

pub fn load_model(path: &Path) -> Model {
    mjcf::load(path, &|p| std::fs::read_to_string(p)).unwrap_or_else(|e| panic!("{e}"))
}

fn load_fixture(name: &str) -> Value {
    let path = fixtures_dir().join(format!("{name}.json"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).expect("fixture JSON")
}

fn nums(v: &Value) -> Vec<f64> {
    v.as_array()
        .expect("array")
        .iter()
        .map(|x| x.as_f64().expect("number"))
        .collect()
}

fn matrix(v: &Value) -> DMatrix<f64> {
    let rows: Vec<Vec<f64>> = v.as_array().unwrap().iter().map(nums).collect();
    let (r, c) = (rows.len(), rows.first().map_or(0, |x| x.len()));
    DMatrix::from_fn(r, c, |i, j| rows[i][j])
}

/// Dense actuator moment arms (nu × nv), MuJoCo's `actuator_moment`.
pub fn actuator_moments(model: &Model, ten: &TendonKinematics) -> DMatrix<f64> {
    let mut out = DMatrix::zeros(model.actuators.len(), model.nv);
    for (a, act) in model.actuators.iter().enumerate() {
        match act.transmission {
            Transmission::Tendon(t) => out.set_row(a, &ten.moment.row(t)),
            Transmission::Joint(j) => out[(a, model.joints[j].dof_adr)] = 1.0,
        }
    }
    out
}

/// A model file by name: the test models under `tests/fixtures/models/`, or the shipped ones under
/// `config/models/`.
fn model_path(model_file: &str) -> PathBuf {
    let test = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/models")
        .join(model_file);
    if test.exists() {
        test
    } else {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../config/models")
            .join(model_file)
    }
}

fn compare_positions(model_file: &str, fixture: &str) {
    let model = load_model(&model_path(model_file));
    let fx = load_fixture(fixture);
    assert_eq!(fx["nq"].as_u64().unwrap() as usize, model.nq);
    assert_eq!(fx["nv"].as_u64().unwrap() as usize, model.nv);
    let names: Vec<String> = fx["actuator_names"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_str().unwrap().to_string())
        .collect();
    assert_eq!(
        names,
        model
            .actuators
            .iter()
            .map(|a| a.name.clone())
            .collect::<Vec<_>>()
    );
    for (b, m) in nums(&fx["body_mass"]).iter().enumerate() {
        assert!(
            (model.bodies[b].mass - m).abs() < KINEMATICS_TOL * m.max(1.0),
            "body {b} mass {} vs {m}",
            model.bodies[b].mass
        );
    }
    let mut kin = Kinematics::new(&model);
    let mut ten = TendonKinematics::new(&model);
    let mut lengths_only = TendonKinematics::new(&model);
    let mut worst_len: f64 = 0.0;
    let mut worst_moment: f64 = 0.0;
    for (i, c) in fx["configs"].as_array().unwrap().iter().enumerate() {
        let qpos = nums(&c["qpos"]);
        kin.update(&model, &qpos);
        ten.update(&model, &kin);
        // The lengths-only update (K-MAC's target) sums the same segments: the same bits.
        lengths_only.update_lengths(&kin);
        assert_eq!(
            lengths_only
                .length
                .iter()
                .map(|l| l.to_bits())
                .collect::<Vec<_>>(),
            ten.length.iter().map(|l| l.to_bits()).collect::<Vec<_>>(),
            "config {i}: lengths-only tendon update differs from the full one"
        );
        for (s, p) in c["site_xpos"].as_array().unwrap().iter().enumerate() {
            let p = nums(p);
            let d = (kin.site_pos[s] - nalgebra::Vector3::new(p[0], p[1], p[2])).norm();
            assert!(
                d < KINEMATICS_TOL,
                "config {i}: site {} off by {d}",
                model.sites[s].name
            );
        }
        for (a, l) in nums(&c["actuator_length"]).iter().enumerate() {
            let ours = actuator_length(&model, model.actuators[a].transmission, &ten, &qpos);
            let rel = (ours - l).abs() / l.abs().max(1e-3);
            worst_len = worst_len.max(rel);
            assert!(
                rel < KINEMATICS_TOL,
                "config {i}: {} length {ours} vs MuJoCo {l}",
                names[a]
            );
        }
        let ours = actuator_moments(&model, &ten);
        let theirs = matrix(&c["actuator_moment"]);
        let diff = (&ours - &theirs).abs().max();
        worst_moment = worst_moment.max(diff);
        assert!(
            diff < KINEMATICS_TOL,
            "config {i}: moment arms differ by {diff}\nours {ours}\nMuJoCo {theirs}"
        );
    }
    eprintln!("{model_file}: worst length error {worst_len:.2e} (relative), worst moment-arm error {worst_moment:.2e} m");
}

#[test]
fn two_link_kinematics_match_mujoco() {
    compare_positions("two_link.xml", "two_link");
}

fn compare_dynamics(model_file: &str, fixture: &str) {
    use sim::dynamics::Data;
    let model = load_model(&model_path(model_file));
    let fx = load_fixture(fixture);
    let mut data = Data::new(&model);
    let (mut worst_m, mut worst_c): (f64, f64) = (0.0, 0.0);
    for (i, c) in fx["configs"].as_array().unwrap().iter().enumerate() {
        let (qpos, qvel) = (nums(&c["qpos"]), nums(&c["qvel"]));
        data.positions(&model, &qpos);
        data.velocities(&model, &qvel);
        let m = matrix(&c["mass_matrix"]);
        let dm = (&data.mass - &m).abs().max() / m.abs().max();
        let bias = nalgebra::DVector::from_vec(nums(&c["qfrc_bias"]));
        let dc = (&data.bias - &bias).abs().max() / bias.abs().max().max(1e-9);
        worst_m = worst_m.max(dm);
        worst_c = worst_c.max(dc);
        assert!(
            dm < DYNAMICS_TOL,
            "config {i}: mass matrix off by {dm} (relative)\nours {}\nMuJoCo {m}",
            data.mass
        );
        assert!(
            dc < DYNAMICS_TOL,
            "config {i}: bias off by {dc}\nours {}\nMuJoCo {bias}",
            data.bias
        );
        for (a, v) in nums(&c["actuator_velocity"]).iter().enumerate() {
            assert!(
                (data.actuator_velocity[a] - v).abs() < KINEMATICS_TOL,
                "config {i}: actuator {a} velocity"
            );
        }
    }
    eprintln!("{model_file}: mass matrix worst relative error {worst_m:.2e}, bias {worst_c:.2e}");
}

#[test]
fn two_link_mass_matrix_and_bias_match_mujoco() {
    compare_dynamics("two_link.xml", "two_link");
}

/// Runs one recorded motion; returns the worst difference in independent-joint positions (rad or m),
/// in muscle activations, and MuJoCo's own worst coupling violation `|q_dep − p(q_ind)|` over the run.
fn motion_difference(model: &Model, motion: &Value) -> (f64, f64, f64) {
    use sim::dynamics::{step, Data, State};
    let mut data = Data::new(model);
    let mut state = State::new(model);
    state.set_qpos(model, &nums(&motion["start_qpos"]));
    if let Some(v) = motion.get("start_qvel") {
        state.qvel = nums(v);
    }
    state.ctrl = nums(&motion["ctrl"]);
    let (mut worst_q, mut worst_act, mut violation): (f64, f64, f64) = (0.0, 0.0, 0.0);
    let act_ids: Vec<usize> = (0..model.actuators.len())
        .filter(|&a| !matches!(model.actuators[a].dynamics, sim::model::Dynamics::None))
        .collect();
    for (k, (q, act)) in motion["qpos"]
        .as_array()
        .unwrap()
        .iter()
        .zip(motion["act"].as_array().unwrap())
        .enumerate()
    {
        step(model, &mut data, &mut state);
        let q = nums(q);
        for (j, joint) in model.joints.iter().enumerate() {
            if model.is_dependent(j) {
                continue;
            }
            let d = (state.qpos[joint.qpos_adr] - q[joint.qpos_adr]).abs();
            assert!(d.is_finite(), "step {k}: {} is not finite", joint.name);
            worst_q = worst_q.max(d);
        }
        for (slot, &a) in act_ids.iter().enumerate() {
            worst_act = worst_act.max((state.act[a] - nums(act)[slot]).abs());
        }
        for c in &model.couplings {
            let (ind, dep) = (&model.joints[c.independent], &model.joints[c.dependent]);
            let (want, _, _) = c.eval(q[ind.qpos_adr], ind.reference, dep.reference);
            violation = violation.max((q[dep.qpos_adr] - want).abs());
        }
    }
    (worst_q, worst_act, violation)
}

/// Without couplings our Euler step is MuJoCo's: 0.5 s of passive and of actuated motion agree to
/// round-off accumulated over 250 steps (no joint limit is reached in either).
#[test]
fn uncoupled_motions_match_mujoco() {
    let model = load_model(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/models/two_link_uncoupled.xml"),
    );
    let fx = load_fixture("two_link_uncoupled");
    compare_positions("two_link_uncoupled.xml", "two_link_uncoupled");
    for name in ["passive", "actuated"] {
        let (dq, dact, _) = motion_difference(&model, &fx["motions"][name]);
        eprintln!("two_link_uncoupled {name}: worst joint difference {dq:.2e}, worst activation difference {dact:.2e}");
        assert!(dq < MOTION_TOL, "{name}: joints differ by {dq}");
        assert!(
            dact < ACTIVATION_TOL,
            "{name}: activations differ by {dact}"
        );
    }
}

/// With couplings, MuJoCo enforces them as soft equality constraints (`solref` time constant 0.02 s)
/// while ours are exact: MuJoCo's dependent joints stray from their polynomials, and the independent
/// joints feel a slightly different inertia. The tolerance is three times MuJoCo's own worst coupling
/// violation on the same motion (and at least 1e-4): our difference from MuJoCo is of the size of
/// MuJoCo's difference from the exact coupling. Without couplings the two agree to 1e-15
/// (`uncoupled_motions_match_mujoco`).
fn coupled_motions_follow_mujoco(model_file: &str, fixture: &str) {
    let model = load_model(&model_path(model_file));
    let fx = load_fixture(fixture);
    for name in ["passive", "actuated"] {
        let (dq, dact, violation) = motion_difference(&model, &fx["motions"][name]);
        let tolerance = (3.0 * violation).max(1e-4);
        eprintln!(
            "{model_file} {name}: worst independent-joint difference {dq:.2e} (MuJoCo's coupling violation {violation:.2e}), activations {dact:.2e}"
        );
        assert!(
            dq < tolerance,
            "{name}: joints differ by {dq}, tolerance {tolerance}"
        );
        assert!(
            dact < ACTIVATION_TOL,
            "{name}: activations differ by {dact}"
        );
    }
}

#[test]
fn two_link_coupled_motions_follow_mujoco() {
    coupled_motions_follow_mujoco("two_link.xml", "two_link");
}

#[test]
fn upper_body_kinematics_and_dynamics_match_mujoco() {
    compare_positions("upper_body.xml", "upper_body");
    compare_dynamics("upper_body.xml", "upper_body");
}

#[test]
fn upper_body_motions_follow_mujoco() {
    coupled_motions_follow_mujoco("upper_body.xml", "upper_body");
}

/// A free-floating, spinning body beside a muscle-driven arm: free-joint kinematics, mass matrix,
/// gyroscopic bias and quaternion integration against MuJoCo.
#[test]
fn free_body_matches_mujoco() {
    compare_positions("free_body.xml", "free_body");
    compare_dynamics("free_body.xml", "free_body");
    let model = load_model(&model_path("free_body.xml"));
    let fx = load_fixture("free_body");
    for name in ["passive", "actuated"] {
        let (dq, dact, _) = motion_difference(&model, &fx["motions"][name]);
        eprintln!("free_body {name}: worst joint difference {dq:.2e}, activations {dact:.2e}");
        assert!(dq < MOTION_TOL, "{name}: joints differ by {dq}");
        assert!(dact < ACTIVATION_TOL);
    }
}
