//! `rally reproduce` through the binary, small: the Table I analogue, the activation split and the
//! dual-rally section are written with their plots, a pairing whose checkpoint is missing says so, and the same seed writes
//! the same report.

use std::process::Command;

#[test]
fn reproduce_writes_the_table_and_the_rally_section() {
    let dir = std::env::temp_dir().join(format!("rally-cli-reproduce-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let ck = dir.join("checkpoints");
    std::fs::create_dir_all(&ck).unwrap();
    std::fs::copy("config/checkpoints/kmac.json", ck.join("kmac.json")).unwrap();
    let run = |out: &str| {
        let o = Command::new(env!("CARGO_BIN_EXE_rally"))
            .args([
                "reproduce",
                "--episodes",
                "3",
                "--rallies",
                "4",
                "--seed",
                "5",
            ])
            .arg("--checkpoints")
            .arg(&ck)
            .arg("--out")
            .arg(dir.join(out))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        std::fs::read_to_string(dir.join(out)).unwrap()
    };
    let md = run("a/reproduce.md");
    assert!(md.contains("| Diff-Muscle |"), "{md}");
    assert!(md.contains("## Dual-robot rallies"), "{md}");
    // The activation split: a row per evaluated method, its columns filled.
    let split = md
        .lines()
        .skip_while(|l| !l.starts_with("## Where the activation goes"))
        .find(|l| l.starts_with("| Diff-Muscle |"))
        .unwrap_or_else(|| panic!("no activation split row: {md}"));
    assert_eq!(split.matches(" | ").count(), 4, "{split}");
    assert!(split.trim_end().ends_with("% |"), "{split}");
    assert!(md.contains("| kmac | kmac | "), "{md}");
    assert!(md.contains("| scripted | scripted | "), "{md}");
    assert!(
        md.contains("| kmac-rally | kmac-rally | no checkpoint ("),
        "{md}"
    );
    for png in ["reproduce_rallies.png", "reproduce_curves.png"] {
        let bytes = std::fs::read(dir.join("a").join(png)).unwrap();
        assert_eq!(&bytes[1..4], b"PNG", "{png}");
    }
    // No kmac-rally checkpoint: no return-distribution panel to draw.
    assert!(!dir.join("a/reproduce_returns.png").exists());
    assert_eq!(run("b/reproduce.md"), md);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn reproduce_on_myosuites_robot_reads_its_checkpoints_and_names_its_report_after_it() {
    // Needs the imported robot: `RALLY_MYOCHALLENGE` names the file `rally model import myosuite`
    // wrote (`.ci/run` sets it in its MyoChallenge step).
    let Some(xml) = std::env::var_os("RALLY_MYOCHALLENGE") else {
        eprintln!(
            "not run: set RALLY_MYOCHALLENGE to the file `rally model import myosuite` wrote"
        );
        return;
    };
    let dir = std::env::temp_dir().join(format!("rally-cli-reproduce-mc-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("data/models")).unwrap();
    std::fs::copy(&xml, dir.join("data/models/myochallenge.xml")).unwrap();
    // From a directory of its own: the defaults find config/checkpoints/myochallenge/ there and
    // write docs/reproduce-myochallenge.md there.
    std::fs::create_dir_all(dir.join("config/checkpoints/myochallenge")).unwrap();
    std::fs::copy(
        "config/checkpoints/myochallenge/kmac.json",
        dir.join("config/checkpoints/myochallenge/kmac.json"),
    )
    .unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_rally"))
        .current_dir(&dir)
        .env("RALLY_DATA_DIR", dir.join("data"))
        .args([
            "reproduce",
            "--model",
            "myochallenge",
            "--episodes",
            "2",
            "--rallies",
            "2",
            "--seed",
            "5",
        ])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let md = std::fs::read_to_string(dir.join("docs/reproduce-myochallenge.md")).unwrap();
    assert!(
        md.starts_with("# Reproducing the paper's Table I on the myochallenge robot (273 muscles)"),
        "{md}"
    );
    assert!(
        md.contains("`rally reproduce --model myochallenge --episodes 2"),
        "{md}"
    );
    assert!(md.contains("config/train-myochallenge.toml"), "{md}");
    let row = md
        .lines()
        .find(|l| l.starts_with("| Diff-Muscle |"))
        .unwrap_or_else(|| panic!("no Diff-Muscle row: {md}"));
    assert!(!row.contains("no checkpoint"), "{row}");
    assert!(
        md.contains("| Muscle-PPO | no checkpoint |"),
        "a method without a checkpoint of this robot is listed unplayed: {md}"
    );
    let png = std::fs::read(dir.join("docs/reproduce-myochallenge_curves.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn reproduce_ablations_groups_the_checkpoints_by_variant_over_their_seeds() {
    let dir = std::env::temp_dir().join(format!("rally-cli-ablations-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let ck = dir.join("checkpoints");
    std::fs::create_dir_all(ck.join("ablations")).unwrap();
    let rally = || Command::new(env!("CARGO_BIN_EXE_rally"));
    let reproduce = |out: &str| {
        let o = rally()
            .args([
                "reproduce",
                "--ablations",
                "--episodes",
                "2",
                "--rallies",
                "0",
            ])
            .arg("--checkpoints")
            .arg(&ck)
            .arg("--out")
            .arg(dir.join(out))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        std::fs::read_to_string(dir.join(out)).unwrap()
    };
    let empty = reproduce("empty.md");
    assert!(empty.contains("No ablation runs yet"), "{empty}");
    // Tiny runs: two seeds of Diff-Muscle, one of Without-Planner, one of Without-Task.
    let runs = [
        ("full", true, 1),
        ("full", true, 2),
        ("none", true, 1),
        ("full", false, 3),
    ];
    for (k, (command, task, seed)) in runs.iter().enumerate() {
        let config = dir.join(format!("train{k}.toml"));
        std::fs::write(
            &config,
            format!(
                "[ppo]\nenvs = 2\nsteps_per_env = 64\nhidden = [8, 8]\ncheckpoint_every = 1\n\
                 [ablation]\ncommand = \"{command}\"\ntask_reward = {task}\n"
            ),
        )
        .unwrap();
        let out = dir.join(format!("run{k}"));
        let o = rally()
            .args(["train", "--method", "kmac", "--steps", "256", "--quiet"])
            .arg("--seed")
            .arg(seed.to_string())
            .arg("--config")
            .arg(&config)
            .arg("--out")
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        std::fs::copy(
            out.join("checkpoint.json"),
            ck.join("ablations").join(format!("{k}.json")),
        )
        .unwrap();
    }
    let md = reproduce("a/reproduce.md");
    assert!(
        md.contains("`rally reproduce --ablations --episodes 2"),
        "{md}"
    );
    assert!(md.contains("## Ablations (paper §V-C)"), "{md}");
    // Table I gains Diff-Muscle's spread over its two seeds.
    assert!(
        md.contains("Diff-Muscle over its 2 training seeds of the ablation runs (seeds 1, 2;"),
        "{md}"
    );
    for row in [
        "| Diff-Muscle | 2 |",
        "| Without-Planner | 1 |",
        "| Without-Task | 1 |",
    ] {
        assert!(md.contains(row), "{row}: {md}");
    }
    assert!(
        md.contains("**Position-only** (paper:") && md.contains("not run"),
        "{md}"
    );
    // One seed has no spread: its rates stand alone, and its finding says it rests on one seed.
    assert!(md.contains("| Without-Planner | 1 | 0.0 | 0.0 |"), "{md}");
    assert!(md.contains("hit 0.0%, success 0.0% (one seed)"), "{md}");
    // Untrained policies hit nothing: Without-Planner's "fails" holds, Without-Task's finding not.
    assert!(md.contains("**reproduces** (rule: hit below 10%"), "{md}");
    assert!(
        md.contains("**does not reproduce** (rule: hit at least 50%"),
        "{md}"
    );
    let png = std::fs::read(dir.join("a/reproduce_ablations.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    assert_eq!(reproduce("b/reproduce.md"), md);
    if std::env::var_os("RALLY_KEEP").is_none() {
        let _ = std::fs::remove_dir_all(&dir);
    }
}
