//! `rally ball` end to end, through the built binary: the line format, determinism to the byte, and
//! bad arguments (exit 2 with a message that names the argument, nothing on stdout).

use std::process::{Command, Output};

fn rally(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rally"))
        .args(args)
        .output()
        .expect("rally runs")
}

fn lines(out: &Output) -> Vec<serde_json::Value> {
    String::from_utf8(out.stdout.clone())
        .expect("utf-8")
        .lines()
        .map(|l| serde_json::from_str(l).expect("each line is JSON"))
        .collect()
}

#[test]
fn one_line_per_control_step_with_the_documented_fields() {
    let out = rally(&["ball", "--serve", "p1", "--seed", "4", "--duration", "1.5"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let ls = lines(&out);
    assert_eq!(ls.len(), 151, "t = 0 plus 150 control steps");
    let first = String::from_utf8(out.stdout.clone()).unwrap();
    assert!(
        first.starts_with("{\"t\":0.0,\"pos\":["),
        "field order t, pos, vel, events: {}",
        &first[..40]
    );
    assert_eq!(ls[37]["t"], serde_json::json!(0.37));
    let events: Vec<&serde_json::Value> = ls
        .iter()
        .flat_map(|l| l["events"].as_array().unwrap())
        .collect();
    // A P1 serve bounces on A's half and, with nobody to hit it, flies on to the floor.
    assert_eq!(events[0]["kind"], "table");
    assert_eq!(events[0]["side"], "a");
    assert_eq!(events[0]["face"], "top");
    let ev_t = events[0]["t"].as_f64().unwrap();
    let line = ls
        .iter()
        .position(|l| !l["events"].as_array().unwrap().is_empty())
        .unwrap();
    assert!(
        ev_t > (line - 1) as f64 * 0.01 && ev_t <= line as f64 * 0.01 + 1e-12,
        "event inside its step"
    );
    // Table contact begins when the centre is one radius above the playing surface.
    assert!((events[0]["pos"][2].as_f64().unwrap() - 0.815).abs() < 1e-9);
    assert!(
        events.iter().any(|e| e["kind"] == "floor"),
        "it does not stop at z = 0.3"
    );
}

#[test]
fn same_seed_same_bytes_different_seed_different_bytes() {
    for serve in ["p0", "p1", "p2", "rally"] {
        let a = rally(&["ball", "--serve", serve, "--seed", "12", "--judge"]);
        let b = rally(&["ball", "--serve", serve, "--seed", "12", "--judge"]);
        assert!(a.status.success());
        assert_eq!(a.stdout, b.stdout, "serve {serve}");
    }
    let a = rally(&["ball", "--serve", "p2", "--seed", "1"]);
    let b = rally(&["ball", "--serve", "p2", "--seed", "2"]);
    assert_ne!(a.stdout, b.stdout);
}

#[test]
fn explicit_state_spin_and_presets() {
    let out = rally(&[
        "ball",
        "--pos",
        "-1.2,-0.45,1.45",
        "--vel",
        "5.6,1.6,0.1",
        "--spin",
        "0,-100,0",
        "--preset",
        "realistic",
        "--duration",
        "2",
        "--judge",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let ls = lines(&out);
    assert_eq!(ls.len(), 202, "201 states and the verdict");
    let verdict = &ls[201]["verdict"];
    assert_eq!(verdict["server"], "b");
    assert_eq!(verdict["end"], "MISS");
    assert_eq!(verdict["failing_side"], "a");
    // Drag slows the ball in `realistic`.
    assert!(ls[20]["vel"][0].as_f64().unwrap() < 5.6);
}

fn bad(args: &[&str], must_mention: &str) {
    let out = rally(args);
    assert_eq!(out.status.code(), Some(2), "{args:?} should exit 2");
    assert!(out.stdout.is_empty(), "{args:?} printed to stdout");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(must_mention),
        "{args:?}: message should mention {must_mention}: {err}"
    );
}

#[test]
fn bad_arguments_exit_2_naming_the_argument() {
    bad(&["ball"], "--pos");
    bad(&["ball", "--pos", "1,2,3"], "--vel");
    bad(&["ball", "--pos", "1,2", "--vel", "1,2,3"], "--pos");
    bad(&["ball", "--pos", "1,x,3", "--vel", "1,2,3"], "--pos");
    bad(&["ball", "--pos", "0,3,1", "--vel", "1,2,nan"], "--vel");
    bad(&["ball", "--serve", "p9", "--seed", "1"], "--serve");
    bad(&["ball", "--serve", "p1"], "--seed");
    bad(&["ball", "--serve", "p1", "--seed", "-3"], "--seed");
    bad(&["ball", "--serve", "p1", "--seed", "abc"], "--seed");
    bad(
        &["ball", "--serve", "p1", "--seed", "1", "--duration", "-1"],
        "--duration",
    );
    bad(
        &["ball", "--serve", "p1", "--seed", "1", "--duration", "0"],
        "--duration",
    );
    bad(
        &["ball", "--serve", "p1", "--seed", "1", "--preset", "moon"],
        "--preset",
    );
    bad(
        &["ball", "--serve", "p1", "--seed", "1", "--pos", "0,0,2"],
        "--pos",
    );
    bad(
        &["ball", "--pos", "0.5,0,0.8", "--vel", "0,0,0"],
        "inside the table",
    );
    bad(
        &["ball", "--pos", "0,0.04,0.9", "--vel", "0,0,0"],
        "inside the net",
    );
    bad(
        &["ball", "--pos", "3,0,0.01", "--vel", "0,0,0"],
        "below the floor",
    );
}

#[test]
fn a_reader_that_goes_away_ends_a_command_quietly() {
    use std::io::Read;
    use std::process::Stdio;
    // A long flight (BufWriter, io errors) and a one-shot JSON print (println!).
    for args in [
        vec!["ball", "--serve", "p2", "--seed", "1", "--duration", "3600"],
        vec!["checkpoint", "template", "--hidden", "512,512"],
    ] {
        let mut child = Command::new(env!("CARGO_BIN_EXE_rally"))
            .args(&args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("rally runs");
        let mut head = [0u8; 100];
        child
            .stdout
            .take()
            .unwrap()
            .read_exact(&mut head)
            .expect("the first bytes");
        // The reader is dropped here, as `| head -c 100` would.
        let out = child.wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            matches!(out.status.code(), Some(0) | Some(141)),
            "{args:?}: {:?} {stderr}",
            out.status
        );
        assert!(stderr.is_empty(), "{args:?}: {stderr}");
    }
}
