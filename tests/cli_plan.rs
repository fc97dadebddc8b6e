//! `rally plan` through the binary: the documented JSON, the planner's closed form, defaults and errors.

use std::process::{Command, Output};

fn rally(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rally"))
        .args(args)
        .output()
        .expect("rally runs")
}

fn vec3(v: &serde_json::Value) -> [f64; 3] {
    let a = v.as_array().unwrap();
    [
        a[0].as_f64().unwrap(),
        a[1].as_f64().unwrap(),
        a[2].as_f64().unwrap(),
    ]
}

#[test]
fn plan_prints_a_racket_command_that_returns_v_out() {
    let out = rally(&[
        "plan",
        "--pos",
        "-1.2,-0.45,1.45",
        "--vel",
        "5.6,1.6,0.1",
        "--seed",
        "3",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let keys: Vec<&str> = v.as_object().unwrap().keys().map(|k| k.as_str()).collect();
    assert_eq!(
        keys,
        [
            "receiver",
            "t_strike",
            "strike_pos",
            "strike_vel",
            "v_out",
            "racket_vel",
            "racket_quat"
        ]
    );
    assert_eq!(v["receiver"], "a");
    assert!((vec3(&v["strike_pos"])[0] - 1.8).abs() < 1e-9);
    // An elastic racket (C_r = 1) moving at racket_vel along the normal turns strike_vel into v_out.
    let (vi, vo, vr) = (
        vec3(&v["strike_vel"]),
        vec3(&v["v_out"]),
        vec3(&v["racket_vel"]),
    );
    let d: Vec<f64> = (0..3).map(|i| vo[i] - vi[i]).collect();
    let n = d.iter().map(|x| x * x).sum::<f64>().sqrt();
    let u: Vec<f64> = d.iter().map(|x| x / n).collect();
    let rel: f64 = (0..3).map(|i| (vi[i] - vr[i]) * u[i]).sum();
    for i in 0..3 {
        assert!((vi[i] - 2.0 * rel * u[i] - vo[i]).abs() < 1e-9);
    }
    // The quaternion turns +z onto u: its rotated z axis is (2(xz + wy), 2(yz − wx), 1 − 2(x² + y²)).
    let q: Vec<f64> = v["racket_quat"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let (w, x, y, z) = (q[0], q[1], q[2], q[3]);
    let zr = [
        2.0 * (x * z + w * y),
        2.0 * (y * z - w * x),
        1.0 - 2.0 * (x * x + y * y),
    ];
    for i in 0..3 {
        assert!((zr[i] - u[i]).abs() < 1e-9);
    }
    // Same seed, same plan; given v_out is used as is.
    let again = rally(&[
        "plan",
        "--pos",
        "-1.2,-0.45,1.45",
        "--vel",
        "5.6,1.6,0.1",
        "--seed",
        "3",
    ]);
    assert_eq!(out.stdout, again.stdout);
    let given = rally(&[
        "plan",
        "--pos",
        "-1.2,-0.45,1.45",
        "--vel",
        "5.6,1.6,0.1",
        "--v-out",
        "-5,0,0.7",
    ]);
    let g: serde_json::Value = serde_json::from_slice(&given.stdout).unwrap();
    assert_eq!(vec3(&g["v_out"]), [-5.0, 0.0, 0.7]);
}

#[test]
fn plan_refuses_balls_it_cannot_plan_for() {
    for args in [
        vec!["plan", "--pos", "0,0,1", "--vel", "0,1,0"],
        vec![
            "plan",
            "--pos",
            "1,0,1",
            "--vel",
            "-3,0,0",
            "--receiver",
            "a",
        ],
        vec!["plan", "--pos", "1,0", "--vel", "1,0,0"],
        vec![
            "plan",
            "--pos",
            "1,0,1",
            "--vel",
            "1,0,0",
            "--receiver",
            "c",
        ],
    ] {
        let out = rally(&args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(out.stdout.is_empty());
    }
}
