//! Our MJCF loader and kinematics against MuJoCo itself, on models under `fixtures/models/`.
//! The fixtures under `fixtures/mujoco/` were written by `tools/mujoco_crosscheck.py` (MuJoCo 4.0);
//! set `RALLY_MUJOCO_FIXTURES` to a folder of freshly generated ones to compare against a live MuJoCo
//! (`.ci/run` does). Tolerances: muscle lengths 1e-6 relative, moment arms 1e-6 m absolute.

use std::path::{Path, PathBuf};

use nalgebra::DMatrix;
use serde_json::Value;
use sim::kinematics::{actuator_length, Kinematics, TendonKinematics};
use sim::mjcf;
use sim::model::{Model, Transmission};

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

fn compare_positions(model_file: &str, fixture: &str) {
    let model = load_model(
        &Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/fixtures/models")
            .join(model_file),
    );
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
            (model.bodies[b].mass - m).abs() < 1e-9 * m.max(1.0),
            "body {b} mass {} vs {m}",
            model.bodies[b].mass
        );
    }
    let mut kin = Kinematics::new(&model);
    let mut ten = TendonKinematics::new(&model);
    let mut worst_len: f64 = 0.0;
    let mut worst_moment: f64 = 0.0;
    for (i, c) in fx["configs"].as_array().unwrap().iter().enumerate() {
        let qpos = nums(&c["qpos"]);
        kin.update(&model, &qpos);
        ten.update(&model, &kin);
        for (s, p) in c["site_xpos"].as_array().unwrap().iter().enumerate() {
            let p = nums(p);
            let d = (kin.site_pos[s] - nalgebra::Vector3::new(p[0], p[1], p[2])).norm();
            assert!(
                d < 1e-9,
                "config {i}: site {} off by {d}",
                model.sites[s].name
            );
        }
        for (a, l) in nums(&c["actuator_length"]).iter().enumerate() {
            let ours = actuator_length(&model, model.actuators[a].transmission, &ten, &qpos);
            let rel = (ours - l).abs() / l.abs().max(1e-3);
            worst_len = worst_len.max(rel);
            assert!(
                rel < 1e-6,
                "config {i}: {} length {ours} vs MuJoCo {l}",
                names[a]
            );
        }
        let ours = actuator_moments(&model, &ten);
        let theirs = matrix(&c["actuator_moment"]);
        let diff = (&ours - &theirs).abs().max();
        worst_moment = worst_moment.max(diff);
        assert!(
            diff < 1e-6,
            "config {i}: moment arms differ by {diff}\nours {ours}\nMuJoCo {theirs}"
        );
    }
    eprintln!("{model_file}: worst length error {worst_len:.2e} (relative), worst moment-arm error {worst_moment:.2e} m");
}

#[test]
fn two_link_kinematics_match_mujoco() {
    compare_positions("two_link.xml", "two_link");
}
