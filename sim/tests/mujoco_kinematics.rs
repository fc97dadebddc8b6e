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
/// Moment arms of muscles whose path has an inside wrap, relative to the muscle's largest: MuJoCo
/// 4.0 stops that solve early (residuals up to 2e-6 on random cases: its contact point up to ~5e-7
/// of the radius off the shortest path's), ours solves it to round-off; the point moves the moment
/// arms (not the length, which is stationary in it). Measured: 1.0e-7 on MyoSuite's robot, 7.1e-7 on
/// the random wrap cases.
const INSIDE_WRAP_MOMENT_TOL: f64 = 5e-6;
/// Moment arms against finite differences of MuJoCo's own lengths (the fixture's
/// `actuator_moment_fd`: five-point differences where two step sizes agree to 1e-10), relative to
/// the muscle's largest: a check of every moment arm, through inside wraps too, that does not rest on
/// MuJoCo's moment-arm solve.
const FD_MOMENT_TOL: f64 = 1e-9;
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

/// For each actuator, whether its tendon's path has an inside wrap (a side site inside its geom at
/// the reference configuration: side sites move with their geoms, so this never changes).
fn inside_wrap_actuators(model: &Model) -> Vec<bool> {
    use sim::model::PathPoint;
    let kin = Kinematics::new(model);
    let inside_tendon = |t: usize| {
        model.tendons[t].path.iter().any(|p| match *p {
            PathPoint::Wrap {
                geom,
                sidesite: Some(s),
            } => {
                let g = &model.geoms[geom];
                let center = kin.xpos[g.body] + kin.xrot[g.body] * g.pos;
                let local =
                    g.quat.inverse() * (kin.xrot[g.body].transpose() * (kin.site_pos[s] - center));
                local.norm() < g.size[0]
            }
            _ => false,
        })
    };
    model
        .actuators
        .iter()
        .map(|a| matches!(a.transmission, Transmission::Tendon(t) if inside_tendon(t)))
        .collect()
}

/// Dense actuator moment arms (nu × nv), MuJoCo's `actuator_moment`.
pub fn actuator_moments(model: &Model, ten: &TendonKinematics) -> DMatrix<f64> {
    let mut out = DMatrix::zeros(model.actuators.len(), model.nv);
    for (a, act) in model.actuators.iter().enumerate() {
        match act.transmission {
            Transmission::Tendon(t) => out.row_mut(a).copy_from_slice(ten.moment_arms(t)),
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
    compare_positions_of(
        &load_model(&model_path(model_file)),
        model_file,
        &load_fixture(fixture),
    );
}

fn compare_positions_of(model: &Model, model_file: &str, fx: &Value) {
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
    let mut kin = Kinematics::new(model);
    let mut ten = TendonKinematics::new(model);
    let mut lengths_only = TendonKinematics::new(model);
    let mut worst_len: f64 = 0.0;
    let (mut worst_moment, mut worst_inside): (f64, f64) = (0.0, 0.0);
    // Against MuJoCo's lengths' derivatives: (worst, worst through an inside wrap, entries compared).
    let (mut worst_fd, mut worst_fd_inside, mut fd_entries): (f64, f64, usize) = (0.0, 0.0, 0);
    let inside = inside_wrap_actuators(model);
    for (i, c) in fx["configs"].as_array().unwrap().iter().enumerate() {
        let qpos = nums(&c["qpos"]);
        kin.update(model, &qpos);
        ten.update(model, &kin);
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
            let ours = actuator_length(model, model.actuators[a].transmission, &ten, &qpos);
            let rel = (ours - l).abs() / l.abs().max(1e-3);
            worst_len = worst_len.max(rel);
            assert!(
                rel < KINEMATICS_TOL,
                "config {i}: {} length {ours} vs MuJoCo {l}",
                names[a]
            );
        }
        let ours = actuator_moments(model, &ten);
        let theirs = matrix(&c["actuator_moment"]);
        for a in 0..model.actuators.len() {
            let scale = theirs.row(a).amax().max(1e-3);
            let diff = (ours.row(a) - theirs.row(a)).amax();
            let (tol, worst) = if inside[a] {
                (INSIDE_WRAP_MOMENT_TOL, &mut worst_inside)
            } else {
                (KINEMATICS_TOL, &mut worst_moment)
            };
            *worst = worst.max(diff / scale);
            assert!(
                diff < tol * scale,
                "config {i}: {} moment arms differ by {diff} m ({:.1e} of its largest)\nours {}\nMuJoCo {}",
                names[a],
                diff / scale,
                ours.row(a),
                theirs.row(a)
            );
        }
        if let Some(fd) = c.get("actuator_moment_fd").and_then(Value::as_array) {
            for (a, row) in fd.iter().enumerate() {
                let scale = theirs.row(a).amax().max(1e-3);
                for (d, x) in row.as_array().unwrap().iter().enumerate() {
                    let Some(x) = x.as_f64() else { continue };
                    let rel = (ours[(a, d)] - x).abs() / scale;
                    fd_entries += 1;
                    if inside[a] {
                        worst_fd_inside = worst_fd_inside.max(rel);
                    } else {
                        worst_fd = worst_fd.max(rel);
                    }
                    assert!(
                        rel < FD_MOMENT_TOL,
                        "config {i}: {} moment arm in DoF {d}: ours {} vs MuJoCo's length \
                         derivative {x} ({rel:.1e} of its largest)",
                        names[a],
                        ours[(a, d)]
                    );
                }
            }
        }
    }
    eprintln!(
        "{model_file}: worst length error {worst_len:.2e}, worst moment-arm error {worst_moment:.2e} \
         ({worst_inside:.2e} through an inside wrap), relative to the muscle's largest moment arm"
    );
    if fd_entries > 0 {
        eprintln!(
            "{model_file}: worst moment arm against MuJoCo's lengths' finite differences \
             {worst_fd:.2e} ({worst_fd_inside:.2e} through an inside wrap), {fd_entries} entries"
        );
    }
}

#[test]
fn two_link_kinematics_match_mujoco() {
    compare_positions("two_link.xml", "two_link");
}

fn compare_dynamics(model_file: &str, fixture: &str) {
    compare_dynamics_of(
        &load_model(&model_path(model_file)),
        model_file,
        &load_fixture(fixture),
    );
}

fn compare_dynamics_of(model: &Model, model_file: &str, fx: &Value) {
    use sim::dynamics::Data;
    let mut data = Data::new(model);
    let inside = inside_wrap_actuators(model);
    let (mut worst_m, mut worst_c): (f64, f64) = (0.0, 0.0);
    for (i, c) in fx["configs"].as_array().unwrap().iter().enumerate() {
        let (qpos, qvel) = (nums(&c["qpos"]), nums(&c["qvel"]));
        data.positions(model, &qpos);
        data.velocities(model, &qvel);
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
        // A velocity is a moment-arm row times qvel: its tolerance is the moment arms', on the
        // row's scale.
        let moments = matrix(&c["actuator_moment"]);
        for (a, v) in nums(&c["actuator_velocity"]).iter().enumerate() {
            let scale = moments
                .row(a)
                .abs()
                .dot(
                    &nalgebra::DVector::from_vec(qvel.iter().map(|x| x.abs()).collect())
                        .transpose(),
                )
                .max(1e-3);
            let tol = if inside[a] {
                INSIDE_WRAP_MOMENT_TOL
            } else {
                KINEMATICS_TOL
            };
            let d = (data.actuator_velocity[a] - v).abs();
            assert!(
                d < tol * scale,
                "config {i}: actuator {a} velocity {} vs MuJoCo {v}",
                data.actuator_velocity[a]
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
            let (want, _, _) = c.at(model, &q);
            violation = violation.max((q[model.joints[c.dependent].qpos_adr] - want).abs());
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
    coupled_motions_follow_mujoco_of(
        &load_model(&model_path(model_file)),
        model_file,
        &load_fixture(fixture),
    );
}

fn coupled_motions_follow_mujoco_of(model: &Model, model_file: &str, fx: &Value) {
    for name in ["passive", "actuated"] {
        let (dq, dact, violation) = motion_difference(model, &fx["motions"][name]);
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

/// MyoSuite's 273-muscle MyoChallenge robot, imported by `rally model import myosuite` (not
/// committed: MyoSuite's licence terms travel with the import). Runs when `RALLY_MYOCHALLENGE` names
/// the imported file and `RALLY_MUJOCO_FIXTURES` holds `myochallenge.json`, which
/// `tools/mujoco_fixtures.sh` writes from that file; `.ci/run` does both. Otherwise it says why it
/// did not run.
#[test]
fn myochallenge_matches_mujoco() {
    let Some(path) = std::env::var_os("RALLY_MYOCHALLENGE") else {
        eprintln!("myochallenge_matches_mujoco: not run (set RALLY_MYOCHALLENGE to the file `rally model import myosuite` wrote)");
        return;
    };
    let model = load_model(Path::new(&path));
    let fx = load_fixture("myochallenge");
    assert_eq!(model.muscles().count(), 273);
    compare_positions_of(&model, "myochallenge", &fx);
    compare_dynamics_of(&model, "myochallenge", &fx);
    coupled_motions_follow_mujoco_of(&model, "myochallenge", &fx);
}

/// One tendon over one sphere or cylinder, with no side site, one outside and one inside, on
/// random small models that `tools/mujoco_wrap_cases.py` wrote with MuJoCo's lengths and moment
/// arms: the wrapping geometry case by case, not only through a whole body.
#[test]
fn wrap_cases_match_mujoco() {
    let fx = load_fixture("wrap_cases");
    let cases = fx["cases"].as_array().expect("cases");
    let (mut worst_len, mut worst_moment, mut worst_inside): (f64, f64, f64) = (0.0, 0.0, 0.0);
    let mut wrapped = 0;
    for (i, c) in cases.iter().enumerate() {
        let xml = c["xml"].as_str().expect("xml");
        let model =
            mjcf::parse_str(xml, "wrap_case.xml").unwrap_or_else(|e| panic!("case {i}: {e}"));
        let qpos = nums(&c["qpos"]);
        let mut kin = Kinematics::new(&model);
        kin.update(&model, &qpos);
        let mut ten = TendonKinematics::new(&model);
        ten.update(&model, &kin);
        let length = c["length"].as_f64().unwrap();
        let rel = (ten.length[0] - length).abs() / length;
        assert!(
            rel < KINEMATICS_TOL,
            "case {i} ({} {} side): length {} vs MuJoCo {length}",
            c["shape"],
            c["side"],
            ten.length[0]
        );
        let theirs = nums(&c["moment"]);
        let scale = theirs.iter().fold(0.0f64, |m, x| m.max(x.abs())).max(1e-3);
        let diff = (0..model.nv)
            .map(|d| (ten.moment_arms(0)[d] - theirs[d]).abs())
            .fold(0.0, f64::max)
            / scale;
        let inside = c["side"] == "inside" && c["wrapped"] == true;
        let tol = if inside {
            INSIDE_WRAP_MOMENT_TOL
        } else {
            KINEMATICS_TOL
        };
        assert!(
            diff < tol,
            "case {i} ({} {} side): moment arms differ by {diff:.2e} of the largest\nours {:?}\nMuJoCo {theirs:?}",
            c["shape"],
            c["side"],
            ten.moment_arms(0)
        );
        worst_len = worst_len.max(rel);
        if inside {
            worst_inside = worst_inside.max(diff);
        } else {
            worst_moment = worst_moment.max(diff);
        }
        wrapped += usize::from(c["wrapped"] == true);
    }
    eprintln!(
        "{} wrap cases ({wrapped} wrapped): worst length error {worst_len:.2e}, moment arms {worst_moment:.2e} ({worst_inside:.2e} inside wraps)",
        cases.len()
    );
}
