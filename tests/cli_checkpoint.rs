//! `rally checkpoint spec` and `rally checkpoint from-onnx` through the binary: the entries a
//! method's network reads and writes, an ONNX network made a checkpoint that validates and plays,
//! and bad input refused with the field named and nothing written.

use std::process::{Command, Output};

fn rally(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rally"))
        .args(args)
        .output()
        .expect("rally runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

const POLICY: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/agents/tests/fixtures/policy.onnx"
);

#[test]
fn spec_names_every_entry_of_each_method() {
    let out = rally(&["checkpoint", "spec", "--method", "kmac", "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["model"], "default");
    assert_eq!(v["normalised"], true);
    let obs = v["observation"].as_array().unwrap();
    // The ONNX fixture was exported for this shape: 206 in, 13 K-MAC joint targets out.
    assert_eq!(obs.len(), 206);
    assert_eq!(v["action"].as_array().unwrap().len(), 13);
    assert!(obs.iter().any(|n| n == "ball_pos.x"), "{obs:?}");
    let muscle = rally(&["checkpoint", "spec", "--method", "muscle", "--json"]);
    let m: serde_json::Value = serde_json::from_slice(&muscle.stdout).unwrap();
    let actions = m["action"].as_array().unwrap();
    assert!(actions.len() > 13, "Muscle-PPO drives every muscle");
    // The text form says the normalisation and lists the entries by index.
    let text = rally(&["checkpoint", "spec", "--method", "kmac"]);
    let t = String::from_utf8_lossy(&text.stdout);
    assert!(
        t.contains("(x - observation.mean) / observation.std"),
        "{t}"
    );
    assert!(t.contains("  205  "), "{t}");
    let bad = rally(&["checkpoint", "spec", "--method", "ppo"]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(stderr(&bad).contains("--method"), "{}", stderr(&bad));
}

#[test]
fn from_onnx_writes_a_checkpoint_that_validates_and_plays() {
    let dir = std::env::temp_dir().join(format!("rally-from-onnx-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("mine.json");
    let o = out.to_str().unwrap();
    let norm = dir.join("norm.json");
    let n = serde_json::json!({"mean": vec![0.1; 206], "std": vec![2.0; 206]});
    std::fs::write(&norm, n.to_string()).unwrap();
    let args = [
        "checkpoint",
        "from-onnx",
        POLICY,
        "--method",
        "kmac",
        "--obs-norm",
        norm.to_str().unwrap(),
        "--name",
        "mine",
        "--out",
        o,
    ];
    let made = rally(&args);
    assert!(made.status.success(), "{}", stderr(&made));
    let c: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(c["name"], "mine");
    assert_eq!(c["controller"]["kind"], "kmac");
    assert_eq!(c["observation"]["std"][0], 2.0);
    assert!(c["onnx"].is_object() && c["policy"].is_null());
    assert!(rally(&["checkpoint", "validate", o]).status.success());
    let trace = dir.join("steps.jsonl");
    let t = trace.to_str().unwrap();
    let ev = rally(&["eval", o, "--episodes", "2", "--json", "--trace", t]);
    assert!(ev.status.success(), "{}", stderr(&ev));
    // Every control step of both episodes, in order: what the network read and wrote.
    let steps: Vec<serde_json::Value> = std::fs::read_to_string(&trace)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let first_of_second = steps.iter().position(|s| s["episode"] == 1).unwrap();
    assert!(first_of_second > 10, "{first_of_second} steps in episode 0");
    for (k, s) in steps.iter().enumerate() {
        let step = if k < first_of_second {
            k
        } else {
            k - first_of_second
        };
        assert_eq!(s["step"], step);
        assert_eq!(s["observation"].as_array().unwrap().len(), 206);
        assert_eq!(s["action"].as_array().unwrap().len(), 13);
        assert!(!s["controls"].as_array().unwrap().is_empty());
    }
    let many = rally(&["eval", o, "--episodes", "101", "--trace", t]);
    assert_eq!(many.status.code(), Some(2));
    assert!(stderr(&many).contains("--trace"), "{}", stderr(&many));
    // Standard output without --out: the same checkpoint.
    let printed = rally(&args[..args.len() - 2]);
    assert!(printed.status.success());
    let again: serde_json::Value = serde_json::from_slice(&printed.stdout).unwrap();
    assert_eq!(again, c);

    // Another method's controller wants another width: refused naming the network's field.
    let other = dir.join("other.json");
    let wrong = rally(&[
        "checkpoint",
        "from-onnx",
        POLICY,
        "--method",
        "muscle",
        "--name",
        "x",
        "--out",
        other.to_str().unwrap(),
    ]);
    assert_eq!(wrong.status.code(), Some(2));
    assert!(stderr(&wrong).contains("onnx"), "{}", stderr(&wrong));
    assert!(!other.exists(), "nothing written");
    // A normalisation of the wrong length, and a file that is not ONNX.
    std::fs::write(&norm, r#"{"mean": [0.0], "std": [1.0]}"#).unwrap();
    let short = rally(&[
        "checkpoint",
        "from-onnx",
        POLICY,
        "--method",
        "kmac",
        "--obs-norm",
        norm.to_str().unwrap(),
        "--name",
        "x",
    ]);
    assert_eq!(short.status.code(), Some(2));
    assert!(
        stderr(&short).contains("mean has 1 entries"),
        "{}",
        stderr(&short)
    );
    let junk = dir.join("junk.onnx");
    std::fs::write(&junk, b"not a network").unwrap();
    let j = rally(&[
        "checkpoint",
        "from-onnx",
        junk.to_str().unwrap(),
        "--method",
        "kmac",
        "--name",
        "x",
    ]);
    assert_eq!(j.status.code(), Some(2));
    assert!(stderr(&j).contains("onnx"), "{}", stderr(&j));
    let _ = std::fs::remove_dir_all(&dir);
}
