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
        md.contains("| kmac-rally | kmac-rally | not trained yet"),
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
