//! The default robot's muscles do what their names say: at the "hang" posture and at a mid-range one
//! (arm forward and a little out, elbow bent, trunk slightly flexed) each
//! muscle's moment arm on its primary joints has the sign of its textbook action and a size of
//! 5 mm to 8 cm (16 cm for the trunk, whose abdominal wall lies far in front of the spine). (Joint signs are documented in `tools/gen_upper_body.py`: positive flexes forward,
//! abducts, rotates inwards, closes the grip; lumbar `lat` > 0 bends right, `rot` > 0 turns left.)
//! A muscle that drives a joint positive shortens as the joint increases: its moment arm
//! ∂l/∂q is negative.

use std::path::Path;

use sim::kinematics::{Kinematics, TendonKinematics};
use sim::model::{Model, Transmission};

fn model() -> Model {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/models/upper_body.xml");
    sim::mjcf::load(&path, &|p| std::fs::read_to_string(p)).unwrap_or_else(|e| panic!("{e}"))
}

/// (muscle, joint, expected sign of ∂l/∂q)
const ACTIONS: &[(&str, &str, f64)] = &[
    // trunk
    ("RA_l", "L5S1_flex", -1.0),
    ("RA_r", "L5S1_flex", -1.0),
    ("PS1_l", "L5S1_flex", -1.0),
    ("IL1_l", "L5S1_flex", 1.0),
    ("LT1_r", "L5S1_flex", 1.0),
    ("MF1_l", "L5S1_flex", 1.0),
    ("QL1_l", "L5S1_lat", 1.0),
    ("QL1_r", "L5S1_lat", -1.0),
    ("IL1_l", "L5S1_lat", 1.0),
    ("EO1_l", "L5S1_rot", 1.0),
    ("EO1_r", "L5S1_rot", -1.0),
    ("IO1_l", "L5S1_rot", -1.0),
    ("IO1_r", "L5S1_rot", 1.0),
    // shoulder
    ("DELT1", "shoulder_flex", -1.0),
    ("PECM1", "shoulder_flex", -1.0),
    ("DELT3", "shoulder_flex", 1.0),
    ("LAT1", "shoulder_flex", 1.0),
    ("DELT2", "shoulder_abd", -1.0),
    ("SUPSP", "shoulder_abd", -1.0),
    ("LAT1", "shoulder_abd", 1.0),
    ("TMAJ", "shoulder_abd", 1.0),
    ("PECM3", "shoulder_abd", 1.0),
    ("SUBSC", "shoulder_rot", -1.0),
    ("INFSP", "shoulder_rot", 1.0),
    ("TMIN", "shoulder_rot", 1.0),
    // elbow
    ("BIClong", "elbow_flex", -1.0),
    ("BICshort", "elbow_flex", -1.0),
    ("BRA", "elbow_flex", -1.0),
    ("BRD", "elbow_flex", -1.0),
    ("TRIlong", "elbow_flex", 1.0),
    ("TRIlat", "elbow_flex", 1.0),
    ("TRImed", "elbow_flex", 1.0),
    ("ANC", "elbow_flex", 1.0),
    // wrist
    ("FCR", "wrist_flex", -1.0),
    ("FCU", "wrist_flex", -1.0),
    ("PL", "wrist_flex", -1.0),
    ("ECRL", "wrist_flex", 1.0),
    ("ECRB", "wrist_flex", 1.0),
    ("ECU", "wrist_flex", 1.0),
    ("ECRL", "wrist_dev", -1.0),
    ("FCR", "wrist_dev", -1.0),
    ("ECU", "wrist_dev", 1.0),
    ("FCU", "wrist_dev", 1.0),
    // grip
    ("FDS", "grip", -1.0),
    ("FDP", "grip", -1.0),
    ("FPL", "grip", -1.0),
    ("EDC", "grip", 1.0),
];

fn moment(m: &Model, ten: &TendonKinematics, muscle: &str, joint: &str) -> f64 {
    let a = m
        .actuator(muscle)
        .unwrap_or_else(|| panic!("no muscle {muscle}"));
    let j = m.joint(joint).unwrap_or_else(|| panic!("no joint {joint}"));
    match m.actuators[a].transmission {
        Transmission::Tendon(t) => ten.moment_arms(t)[m.joints[j].dof_adr],
        Transmission::Joint(_) => panic!("{muscle} is not on a tendon"),
    }
}

#[test]
fn every_muscle_acts_as_its_name_says() {
    let m = model();
    let mut kin = Kinematics::new(&m);
    let mut ten = TendonKinematics::new(&m);
    let mut failures = Vec::new();
    let hang = m
        .keyframes
        .iter()
        .find(|k| k.name == "hang")
        .expect("hang keyframe")
        .qpos
        .clone();
    let mut mid = hang.clone();
    let posture = [
        ("L5S1_flex", 0.08),
        ("shoulder_flex", 0.5),
        ("shoulder_abd", 0.35),
        ("shoulder_rot", 0.2),
        ("elbow_flex", 1.3),
        ("grip", 1.0),
    ];
    for (joint, value) in posture {
        mid[m.joints[m.joint(joint).unwrap()].qpos_adr] = value;
    }
    for (key, start) in [("hang", hang), ("mid", mid)] {
        let mut q = start;
        m.apply_couplings(&mut q);
        kin.update(&m, &q);
        ten.update(&m, &kin);
        for &(muscle, joint, sign) in ACTIONS {
            let r = moment(&m, &ten, muscle, joint);
            let largest = if joint.starts_with('L') { 0.16 } else { 0.08 };
            if r * sign < 0.005 || r.abs() > largest {
                failures.push(format!(
                    "{key}: {muscle} on {joint}: moment arm {r:+.4} m, expected sign {sign:+}"
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn pronators_and_supinators_pull_opposite_ways() {
    let m = model();
    let kin = Kinematics::new(&m);
    let mut ten = TendonKinematics::new(&m);
    ten.update(&m, &kin);
    let pt = moment(&m, &ten, "PT", "pronation");
    let pq = moment(&m, &ten, "PQ", "pronation");
    let sup = moment(&m, &ten, "SUP", "pronation");
    assert!(
        pt * sup < 0.0 && pt * pq > 0.0,
        "PT {pt}, PQ {pq}, SUP {sup}"
    );
    assert!(pt.abs() > 0.003 && sup.abs() > 0.003);
}

#[test]
fn the_model_has_what_the_issue_asks() {
    let m = model();
    let trunk = m
        .muscles()
        .filter(|(_, a)| a.name.ends_with("_l") || a.name.ends_with("_r"))
        .count();
    let arm = m.muscles().count() - trunk;
    assert!(trunk >= 40 && arm >= 30, "trunk {trunk}, arm {arm}");
    let torso_independent: Vec<&str> = ["L5S1_flex", "L5S1_lat", "L5S1_rot"].to_vec();
    for j in &torso_independent {
        assert!(!m.is_dependent(m.joint(j).unwrap()));
    }
    assert_eq!(m.couplings.len(), 12);
    for j in [
        "shoulder_flex",
        "shoulder_abd",
        "shoulder_rot",
        "elbow_flex",
        "pronation",
        "wrist_flex",
        "wrist_dev",
        "grip",
    ] {
        assert!(m.joint(j).is_some(), "no joint {j}");
    }
    for s in ["pelvis_tx_servo", "pelvis_ty_servo"] {
        assert!(m.actuator(s).is_some());
    }
    assert!(
        m.muscles().all(|(_, a)| a.lengthrange_given),
        "every muscle states its lengthrange"
    );
}
