//! `rally match` through the binary: byte-identical output and replay for the same inputs, bad
//! arguments refused.

use std::process::{Command, Output};

fn rally(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rally"))
        .args(args)
        .output()
        .expect("rally runs")
}

#[test]
fn same_agents_and_seed_give_the_same_bytes() {
    let dir = std::env::temp_dir().join(format!("rally-match-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (r1, r2) = (dir.join("r1.json"), dir.join("r2.json"));
    let run = |replay: &std::path::Path| {
        rally(&[
            "match",
            "scripted",
            "scripted-drive",
            "--rallies",
            "4",
            "--seed",
            "7",
            "--json",
            "--replay",
            replay.to_str().unwrap(),
        ])
    };
    let (a, b) = (run(&r1), run(&r2));
    assert!(a.status.success(), "{}", String::from_utf8_lossy(&a.stderr));
    assert_eq!(a.stdout, b.stdout);
    assert_eq!(std::fs::read(&r1).unwrap(), std::fs::read(&r2).unwrap());
    let v: serde_json::Value = serde_json::from_slice(&a.stdout).unwrap();
    assert_eq!(v["rallies"].as_array().unwrap().len(), 4);
    let replay: serde_json::Value = serde_json::from_slice(&std::fs::read(&r1).unwrap()).unwrap();
    assert_eq!(replay["hz"], 50);
    assert_eq!(replay["rallies"].as_array().unwrap().len(), 4);
}

#[test]
fn bad_match_arguments_exit_2() {
    for args in [
        vec!["match", "scripted", "ghost"],
        vec!["match", "scripted", "scripted", "--rallies", "0"],
        vec!["match", "scripted"],
    ] {
        let out = rally(&args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
    }
}

#[test]
fn committed_checkpoints_play_by_name_from_any_directory() {
    // From a directory that has no config/: the built-ins are compiled into the binary.
    let elsewhere = std::env::temp_dir();
    let out = Command::new(env!("CARGO_BIN_EXE_rally"))
        .current_dir(&elsewhere)
        .args([
            "match",
            "kmac",
            "scripted",
            "--rallies",
            "2",
            "--seed",
            "4",
            "--json",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["a"], "kmac");
    let out = Command::new(env!("CARGO_BIN_EXE_rally"))
        .current_dir(&elsewhere)
        .args(["match", "no-such-agent", "scripted"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("'no-such-agent' is neither a scripted agent")
            && err.contains("a built-in checkpoint (dynsyn, kmac, kmac-rally"),
        "{err}"
    );
}
