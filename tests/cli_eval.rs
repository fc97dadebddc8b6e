//! `rally eval` through the binary: JSON output, determinism, bad arguments.

use std::process::{Command, Output};

fn rally(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rally"))
        .args(args)
        .output()
        .expect("rally runs")
}

#[test]
fn eval_prints_rates_with_intervals_and_repeats_itself() {
    let args = [
        "eval",
        "scripted",
        "--episodes",
        "12",
        "--seed",
        "4",
        "--json",
    ];
    let out = rally(&args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["episodes"], 12);
    for key in ["hit_rate", "success_rate", "effort", "mean_activation"] {
        let (lo, x, hi) = (
            v[key]["low"].as_f64().unwrap(),
            v[key]["value"].as_f64().unwrap(),
            v[key]["high"].as_f64().unwrap(),
        );
        assert!(lo <= x && x <= hi, "{key}: {lo} {x} {hi}");
    }
    assert_eq!(rally(&args).stdout, out.stdout);
    let table = rally(&["eval", "scripted-drive", "--episodes", "4", "--serve", "p1"]);
    assert!(String::from_utf8_lossy(&table.stdout).contains("hit rate"));
}

#[test]
fn eval_refuses_unknown_agents_and_bad_counts() {
    for args in [
        vec!["eval", "nobody", "--episodes", "3"],
        vec!["eval", "scripted", "--episodes", "0"],
        vec!["eval", "scripted", "--serve", "p7"],
    ] {
        let out = rally(&args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(out.stdout.is_empty());
    }
}

#[test]
fn checkpoint_templates_validate_and_play_and_broken_ones_are_named() {
    let dir = std::env::temp_dir().join(format!("rally-ckpt-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("t.json");
    let out = rally(&[
        "checkpoint",
        "template",
        "--controller",
        "kmac",
        "--hidden",
        "16",
    ]);
    assert!(out.status.success());
    std::fs::write(&file, &out.stdout).unwrap();
    let f = file.to_str().unwrap();
    assert!(rally(&["checkpoint", "validate", f]).status.success());
    let ev = rally(&["eval", f, "--episodes", "2", "--json"]);
    assert!(
        ev.status.success(),
        "{}",
        String::from_utf8_lossy(&ev.stderr)
    );
    let m = rally(&["match", f, "scripted", "--rallies", "2", "--json"]);
    assert!(m.status.success(), "{}", String::from_utf8_lossy(&m.stderr));
    // A checkpoint whose network gives the wrong number of actions.
    let text = String::from_utf8(out.stdout)
        .unwrap()
        .replace("\"kind\":\"kmac\"", "\"kind\":\"direct\"");
    let bad = dir.join("bad.json");
    std::fs::write(&bad, text).unwrap();
    let v = rally(&["checkpoint", "validate", bad.to_str().unwrap()]);
    assert_eq!(v.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&v.stderr).contains("policy.layers[1].bias"),
        "{}",
        String::from_utf8_lossy(&v.stderr)
    );
    assert_eq!(
        rally(&["eval", bad.to_str().unwrap(), "--episodes", "1"])
            .status
            .code(),
        Some(2)
    );
}

#[test]
fn scale_noise_writes_the_same_network_with_scaled_noise_and_records_it() {
    let dir = std::env::temp_dir().join(format!("rally-noise-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let src = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/config/checkpoints/kmac-rally.json"
    );
    let read = |p: &std::path::Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
    };
    let (half, quarter) = (dir.join("half.json"), dir.join("quarter.json"));
    let scale = |from: &str, to: &std::path::Path, factor: &str| {
        rally(&[
            "checkpoint",
            "scale-noise",
            from,
            "--factor",
            factor,
            "--out",
            to.to_str().unwrap(),
        ])
    };
    let out = scale(src, &half, "0.5");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(scale(half.to_str().unwrap(), &quarter, "0.5")
        .status
        .success());
    let (orig, h, q) = (read(src.as_ref()), read(&half), read(&quarter));
    let std = |v: &serde_json::Value| -> Vec<f64> {
        v["policy_std"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    for ((o, h1), q1) in std(&orig).iter().zip(std(&h)).zip(std(&q)) {
        assert_eq!((h1, q1), (0.5 * o, 0.25 * o));
    }
    assert_eq!(h["policy"], orig["policy"], "the network is untouched");
    // The product of every factor applied (the committed built-in already plays at some scale).
    let base = orig["training"]["noise_scale"].as_f64().unwrap_or(1.0);
    assert_eq!(h["training"]["noise_scale"], 0.5 * base);
    assert_eq!(q["training"]["noise_scale"], 0.25 * base);
    // Bad factors and writing over the input are refused, and nothing is written.
    let none = dir.join("none.json");
    for f in ["-1", "nan", "inf"] {
        let out = rally(&[
            "checkpoint",
            "scale-noise",
            src,
            &format!("--factor={f}"),
            "--out",
            none.to_str().unwrap(),
        ]);
        assert_eq!(out.status.code(), Some(2), "{f}");
        assert!(String::from_utf8_lossy(&out.stderr).contains("--factor"));
    }
    assert!(!none.exists());
    let over = scale(half.to_str().unwrap(), &half, "0.5");
    assert_eq!(over.status.code(), Some(2));
    assert_eq!(read(&half)["training"]["noise_scale"], 0.5 * base);
}

#[test]
fn model_choices_that_cannot_play_are_refused_with_what_to_do() {
    let empty = std::env::temp_dir().join(format!("rally-no-data-{}", std::process::id()));
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_rally"))
            .args(args)
            .env("RALLY_DATA_DIR", &empty)
            .output()
            .expect("rally runs")
    };
    // Not imported yet: the message says how to import it.
    for args in [
        vec![
            "eval",
            "scripted",
            "--model",
            "myochallenge",
            "--episodes",
            "1",
        ],
        vec!["match", "scripted", "scripted", "--model", "myochallenge"],
        vec![
            "checkpoint",
            "validate",
            "x.json",
            "--model",
            "myochallenge",
        ],
    ] {
        let out = run(&args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(
            String::from_utf8_lossy(&out.stderr).contains("rally model import myosuite"),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    // A model without the grip's bodies, and a file that is not there.
    let model = empty.join("bare.xml");
    std::fs::create_dir_all(&empty).unwrap();
    std::fs::write(
        &model,
        r#"<mujoco><worldbody><body name="a"><joint name="j"/><geom size="0.1" mass="1"/></body></worldbody></mujoco>"#,
    )
    .unwrap();
    let out = run(&["eval", "scripted", "--model", model.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("grip.hand_body"));
    let out = run(&["eval", "scripted", "--model", "no-such-file.xml"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no-such-file.xml"));
    let _ = std::fs::remove_dir_all(&empty);
}

#[test]
fn a_builtin_checkpoint_prints_as_committed_and_an_unknown_name_is_a_usage_error() {
    let out = rally(&["checkpoint", "builtin", "kmac"]);
    assert!(out.status.success());
    let committed = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/config/checkpoints/kmac.json"
    ))
    .unwrap();
    assert_eq!(
        String::from_utf8(out.stdout).unwrap().trim_end(),
        committed.trim_end()
    );
    let bad = rally(&["checkpoint", "builtin", "nope"]);
    assert_eq!(bad.status.code(), Some(2));
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        err.contains("no built-in checkpoint 'nope'") && err.contains("kmac-rally"),
        "{err}"
    );
}

#[test]
fn eval_with_a_lead_in_says_so() {
    let out = rally(&[
        "eval",
        "scripted",
        "--episodes",
        "3",
        "--serve",
        "stroke",
        "--lead-in",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(table.contains("stroke serves after a lead-in"), "{table}");
    let json = rally(&["eval", "scripted", "--episodes", "3", "--lead-in", "--json"]);
    let v: serde_json::Value = serde_json::from_slice(&json.stdout).unwrap();
    assert_eq!(v["lead_in"], true);
}
