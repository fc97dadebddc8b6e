//! `rally model inspect` and `rally model kinematics` through the built binary, on the shipped robot
//! and on broken files (exit 2 with the file and line, nothing on stdout).

use sha2::Digest;
use std::path::PathBuf;
use std::process::{Command, Output};

fn rally(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rally"))
        .args(args)
        .output()
        .expect("rally runs")
}

fn robot() -> String {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("config/models/upper_body.xml")
        .display()
        .to_string()
}

fn json(out: &Output) -> serde_json::Value {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("JSON")
}

#[test]
fn inspect_lists_the_robot() {
    let v = json(&rally(&["model", "inspect", &robot(), "--json"]));
    assert_eq!(v["nq"], 25);
    assert_eq!(v["independent_dof"], 13);
    assert_eq!(v["muscles"].as_array().unwrap().len(), 75);
    assert_eq!(v["couplings"].as_array().unwrap().len(), 12);
    let text = rally(&["model", "inspect", &robot()]);
    assert!(text.status.success());
    let text = String::from_utf8(text.stdout).unwrap();
    assert!(
        text.contains("75 muscles")
            && text.contains("L4L5_flex")
            && text.contains("follows L5S1_flex")
    );
    // The file's digest, as an independent hash of its bytes gives it.
    let bytes = std::fs::read(robot()).unwrap();
    let digest: String = sha2::Sha256::digest(&bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    assert!(text.contains(&format!("MJCF sha256 {digest}\n")), "{text}");
}

#[test]
fn kinematics_prints_lengths_and_one_moment_arm_per_dof() {
    let mut q = vec!["0"; 25];
    q[2] = "0.1"; // L5S1_flex
    q[20] = "1.2"; // elbow_flex
    let v = json(&rally(&[
        "model",
        "kinematics",
        &robot(),
        "--qpos",
        &q.join(","),
    ]));
    assert_eq!(v["joints"].as_array().unwrap().len(), 25);
    let muscles = v["muscles"].as_array().unwrap();
    assert_eq!(muscles.len(), 75);
    assert!(muscles
        .iter()
        .all(|m| m["moment_arms"].as_array().unwrap().len() == 25));
    // A value given for a dependent joint is replaced by its coupling: same output either way.
    let mut q2 = q.clone();
    q2[5] = "0.7"; // L4L5_flex, which follows L5S1_flex
    let v2 = json(&rally(&[
        "model",
        "kinematics",
        &robot(),
        "--qpos",
        &q2.join(","),
    ]));
    assert_eq!(v, v2);
    // The same through a file, as a JSON array.
    let dir = std::env::temp_dir().join(format!("rally-qpos-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("q.json");
    std::fs::write(&file, format!("[{}]", q.join(", "))).unwrap();
    let v3 = json(&rally(&[
        "model",
        "kinematics",
        &robot(),
        "--qpos-file",
        file.to_str().unwrap(),
    ]));
    assert_eq!(v, v3);
}

fn refused(args: &[&str], must_mention: &[&str]) {
    let out = rally(args);
    assert_eq!(
        out.status.code(),
        Some(2),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.stdout.is_empty());
    let err = String::from_utf8_lossy(&out.stderr);
    for m in must_mention {
        assert!(err.contains(m), "{args:?}: '{m}' not in: {err}");
    }
}

#[test]
fn bad_models_and_bad_configurations_exit_2() {
    let dir = std::env::temp_dir().join(format!("rally-bad-models-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let write = |name: &str, text: &str| {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p.display().to_string()
    };
    refused(
        &["model", "inspect", "/no/such/model.xml"],
        &["/no/such/model.xml", "cannot read"],
    );
    let f = write(
        "malformed.xml",
        "<mujoco>\n<worldbody>\n<body>\n</worldbody>\n</mujoco>\n",
    );
    refused(
        &["model", "inspect", &f],
        &["malformed.xml:", "malformed XML"],
    );
    let f = write(
        "unknown.xml",
        "<mujoco>\n<worldbody>\n<body>\n<camera name=\"c\"/>\n</body>\n</worldbody>\n</mujoco>\n",
    );
    refused(&["model", "inspect", &f], &["unknown.xml:4", "<camera>"]);
    let f = write(
        "attr.xml",
        "<mujoco>\n<worldbody>\n<body wobble=\"1\"/>\n</worldbody>\n</mujoco>\n",
    );
    refused(&["model", "inspect", &f], &["attr.xml:3", "wobble"]);
    let f = write(
        "dangling.xml",
        "<mujoco>\n<worldbody><site name=\"a\"/></worldbody>\n<tendon>\n<spatial name=\"t\"><site site=\"a\"/><site site=\"b\"/></spatial>\n</tendon>\n</mujoco>\n",
    );
    refused(&["model", "inspect", &f], &["dangling.xml:4", "'b'"]);
    let f = write(
        "massless.xml",
        "<mujoco>\n<worldbody>\n<body name=\"m\">\n<joint/>\n<inertial pos=\"0 0 0\" mass=\"-1\" diaginertia=\"1 1 1\"/>\n</body>\n</worldbody>\n</mujoco>\n",
    );
    refused(&["model", "inspect", &f], &["massless.xml:5", "mass"]);
    refused(
        &["model", "kinematics", &robot(), "--qpos", "1,2,3"],
        &["--qpos", "nq = 25"],
    );
    refused(
        &[
            "model",
            "kinematics",
            &robot(),
            "--qpos",
            &vec!["x"; 25].join(","),
        ],
        &["--qpos", "'x'"],
    );
    refused(&["model", "kinematics", &robot()], &["--qpos"]);
}

/// `rally bench --mujoco` times MuJoCo with the import's interpreter when there is one (it has the
/// pinned MuJoCo), with `--python` when given: a stand-in interpreter in a data directory shows which
/// one ran.
#[test]
fn bench_times_mujoco_with_the_imports_python_by_default() {
    use std::os::unix::fs::PermissionsExt;
    let data = std::env::temp_dir().join(format!("rally-bench-python-{}", std::process::id()));
    let bin = data.join("venv-myosuite/bin");
    std::fs::create_dir_all(&bin).unwrap();
    let fake = bin.join("python");
    std::fs::write(
        &fake,
        "#!/bin/sh\necho '{\"steps_per_second\": 1000.0, \"mujoco_version\": \"the-imports\"}'\n",
    )
    .unwrap();
    std::fs::set_permissions(&fake, std::fs::Permissions::from_mode(0o755)).unwrap();
    let bench = |extra: &[&str]| {
        let mut args = vec!["bench", "ball", "--mujoco", "--seconds", "0.05", "--json"];
        args.extend_from_slice(extra);
        Command::new(env!("CARGO_BIN_EXE_rally"))
            .args(&args)
            .env("RALLY_DATA_DIR", &data)
            .output()
            .expect("rally runs")
    };
    let v = json(&bench(&[]));
    assert_eq!(v["mujoco_version"], "the-imports");
    assert_eq!(v["mujoco_steps_per_second"], 1000.0);
    // An interpreter given by name wins over the import's; one that does not exist is an error.
    let out = bench(&["--python", "/nonexistent/python"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/python"));
    std::fs::remove_dir_all(&data).ok();
}
