//! `rally train` and `rally plot` through the binary: a run killed with SIGKILL and resumed ends with
//! the very checkpoint of a run that was never stopped; bad arguments exit 2 and write nothing.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

fn rally(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rally"))
        .args(args)
        .env_remove("RALLY_FONT")
        .output()
        .expect("rally runs")
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("rally-cli-train-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// A small configuration: 8 environments × 16 steps per iteration, state every 2 iterations.
fn config(dir: &Path) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    let p = dir.join("tiny.toml");
    std::fs::write(
        &p,
        "[ppo]\nenvs = 8\nsteps_per_env = 16\nhidden = [16, 16]\ncheckpoint_every = 2\n",
    )
    .unwrap();
    p
}

/// `rally train --method kmac --steps STEPS --seed SEED --config CFG --quiet --out OUT` plus `extra`.
fn train_args<'a>(
    steps: &'a str,
    seed: &'a str,
    cfg: &'a str,
    out: &'a Path,
    extra: &[&'a str],
) -> Vec<&'a str> {
    let mut a = vec![
        "train",
        "--method",
        "kmac",
        "--steps",
        steps,
        "--seed",
        seed,
        "--config",
        cfg,
        "--quiet",
        "--out",
        out.to_str().unwrap(),
    ];
    a.extend_from_slice(extra);
    a
}

fn policy_of(run: &Path) -> (serde_json::Value, serde_json::Value, serde_json::Value) {
    let text = std::fs::read_to_string(run.join("checkpoint.json")).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    (
        v["policy"].clone(),
        v["observation"].clone(),
        v["training"]["env_steps"].clone(),
    )
}

fn saved_iteration(run: &Path) -> Option<u64> {
    let text = std::fs::read_to_string(run.join("resume/state.json")).ok()?;
    let v: serde_json::Value = serde_json::from_str(&text).ok()?;
    v["progress"]["iteration"].as_u64()
}

#[test]
fn a_run_killed_with_sigkill_resumes_as_the_same_run() {
    let base = tmp("kill");
    let cfg = config(&base);
    let cfg = cfg.to_str().unwrap();
    let steps = "2560"; // 20 iterations
    let straight = base.join("straight");
    let out = rally(&train_args(steps, "4", cfg, &straight, &[]));
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // The same run, killed as soon as it has saved a state, then resumed.
    let killed = base.join("killed");
    let mut child = Command::new(env!("CARGO_BIN_EXE_rally"))
        .args(train_args(steps, "4", cfg, &killed, &[]))
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    while saved_iteration(&killed).is_none() && t0.elapsed() < Duration::from_secs(120) {
        std::thread::sleep(Duration::from_millis(2));
    }
    child.kill().unwrap(); // SIGKILL
    child.wait().unwrap();
    let at = saved_iteration(&killed).expect("a state was saved");
    assert!(at < 20, "killed mid-run (state at iteration {at})");
    let out = rally(&train_args(steps, "4", cfg, &killed, &["--resume"]));
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(policy_of(&killed), policy_of(&straight));
    let curve = std::fs::read_to_string(killed.join("curve.csv")).unwrap();
    assert_eq!(
        curve.lines().count(),
        21,
        "a header and one row per iteration"
    );
    // `rally plot` draws both runs.
    let png = base.join("curves.png");
    let out = rally(&[
        "plot",
        straight.to_str().unwrap(),
        killed.to_str().unwrap(),
        "--out",
        png.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(std::fs::read(&png).unwrap().starts_with(b"\x89PNG"));
    // The font is built in; RALLY_FONT replaces it, and a file that is not a font is named.
    let bad_png = base.join("bad-font.png");
    let out = Command::new(env!("CARGO_BIN_EXE_rally"))
        .args(["plot", straight.to_str().unwrap(), "--out"])
        .arg(&bad_png)
        .env("RALLY_FONT", killed.join("curve.csv"))
        .output()
        .expect("rally runs");
    assert_ne!(out.status.code(), Some(0));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("RALLY_FONT=") && err.contains("curve.csv"),
        "{err}"
    );
    assert!(!bad_png.exists());
    // A second start without --resume refuses to overwrite the run.
    let out = rally(&train_args(steps, "4", cfg, &straight, &[]));
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--resume"));
    // Resuming with another seed is refused and changes nothing.
    let before = policy_of(&straight);
    let out = rally(&train_args("5000", "5", cfg, &straight, &["--resume"]));
    assert_eq!(out.status.code(), Some(2));
    assert_eq!(policy_of(&straight), before);
    let _ = std::fs::remove_dir_all(&base);
}

#[test]
fn bad_arguments_exit_2_and_name_what_is_wrong() {
    let base = tmp("bad");
    let out = rally(&[
        "train",
        "--method",
        "telepathy",
        "--steps",
        "10",
        "--out",
        base.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("kmac"));
    let out = rally(&[
        "train",
        "--method",
        "kmac",
        "--steps",
        "-3",
        "--out",
        base.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(2));
    std::fs::create_dir_all(&base).unwrap();
    let bad = base.join("bad.toml");
    let run = base.join("run");
    let with_config = |text: &str| {
        std::fs::write(&bad, text).unwrap();
        rally(&[
            "train",
            "--method",
            "kmac",
            "--steps",
            "10",
            "--config",
            bad.to_str().unwrap(),
            "--out",
            run.to_str().unwrap(),
        ])
    };
    let out = with_config("[ppo]\nepochz = 3\n");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("epochz"));
    assert!(!base.join("run/checkpoint.json").exists());
    // A ball bank that is not there is named, and nothing is written.
    let out = with_config("[bank]\nfile = \"no/such/bank.json\"\n");
    assert_ne!(out.status.code(), Some(0));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("bank.file no/such/bank.json"), "{err}");
    assert!(!base.join("run/checkpoint.json").exists());
    let _ = std::fs::remove_dir_all(&base);
}

#[test]
fn a_checkpoint_file_starts_a_run_that_keeps_its_policy_while_the_critic_warms_up() {
    let base = tmp("from-file");
    let cfg = config(&base);
    let cfg = cfg.to_str().unwrap();
    let a = base.join("a");
    let out = rally(&train_args("256", "1", cfg, &a, &[]));
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let ck = a.join("checkpoint.json");
    let ck = ck.to_str().unwrap();
    let b = base.join("b");
    // A checkpoint holds no critic and no optimiser: the run must say how long the critic warms
    // up, and cannot carry an optimiser; nothing is written.
    let out = rally(&train_args("256", "2", cfg, &b, &["--init", ck]));
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--critic-warmup"));
    let out = rally(&train_args(
        "256",
        "2",
        cfg,
        &b,
        &[
            "--init",
            ck,
            "--critic-warmup",
            "2",
            "--init-optimizer",
            "carry",
        ],
    ));
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no optimiser"));
    assert!(!b.join("checkpoint.json").exists());
    // Two iterations of critic warm-up: the policy is the checkpoint's, to the bit.
    let out = rally(&train_args(
        "256",
        "2",
        cfg,
        &b,
        &["--init", ck, "--critic-warmup", "2"],
    ));
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(policy_of(&b).0, policy_of(&a).0);
    let text = std::fs::read_to_string(b.join("checkpoint.json")).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let warm = v["training"]["warm_start"].as_str().unwrap();
    assert!(
        warm.contains("checkpoint.json") && warm.contains("critic"),
        "{warm}"
    );
    // Its warm-up is part of the run: a resume with another is refused.
    let out = rally(&train_args(
        "512",
        "2",
        cfg,
        &b,
        &["--resume", "--critic-warmup", "3"],
    ));
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--critic-warmup 2"));
    // Left out, the run's own stands: the file it started with resumes it.
    let out = rally(&train_args("512", "2", cfg, &b, &["--resume"]));
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(saved_iteration(&b), Some(4));
    // A path that is not there is named, and nothing is made of it.
    let typo = base.join("kmac.jsn");
    let c = base.join("c");
    let out = rally(&train_args(
        "256",
        "2",
        cfg,
        &c,
        &["--init", typo.to_str().unwrap(), "--critic-warmup", "2"],
    ));
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no such file"));
    assert!(!typo.exists());
    let _ = std::fs::remove_dir_all(&base);
}
