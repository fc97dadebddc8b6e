//! Records the git commit the `rally` binary is built from (with `-dirty` when tracked files differ
//! from it), so that a training run's provenance names the code that ran, not whatever the checkout
//! holds when the run starts or resumes.

use std::process::Command;

fn git(args: &[&str]) -> Option<String> {
    Command::new("git")
        .args(args)
        .output()
        .ok()
        .filter(|o| o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
}

fn main() {
    let commit = match git(&["rev-parse", "--short=12", "HEAD"]) {
        Some(head) => match git(&["status", "--porcelain", "--untracked-files=no"]) {
            Some(changes) if !changes.is_empty() => format!("{head}-dirty"),
            _ => head,
        },
        None => "unknown".into(),
    };
    println!("cargo:rustc-env=RALLY_GIT_COMMIT={commit}");
    // A commit, a checkout or an edit to any crate's sources changes the answer.
    for path in [
        ".git/HEAD",
        ".git/index",
        ".git/refs/heads",
        "src",
        "agents/src",
        "sim/src",
        "server/src",
        "config",
    ] {
        println!("cargo:rerun-if-changed={path}");
    }
}
