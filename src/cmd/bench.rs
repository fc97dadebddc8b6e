//! `rally bench`: how fast the simulator runs, next to MuJoCo on the same work measured in the same
//! run (through `tools/bench_ball.py`), reported as a ratio.

use std::path::PathBuf;
use std::process::Command;
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context};
use clap::{Args, ValueEnum};
use nalgebra::{UnitQuaternion, Vector3};
use serde_json::json;
use sim::arena::{self, Side, MYOCHALLENGE};
use sim::geometry::Pose;
use sim::predict::MYOCHALLENGE_BOUNCE;
use sim::rng::Rng;
use sim::serve::{self, ServeKind};
use sim::{BallWorld, Paddle};

use super::{parse_seconds, CliError};

/// What to measure.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum Target {
    /// Ball-world physics steps per second, single thread: ball, table, net and one moving paddle,
    /// P2 serves of 300 control steps each.
    Ball,
}

/// Arguments of `rally bench`.
#[derive(Args, Debug)]
#[command(
    after_help = "Example:\n  rally bench ball --mujoco   (needs `pip install mujoco`; see tools/bench_ball.py)"
)]
pub struct BenchArgs {
    /// What to measure.
    #[arg(value_enum)]
    target: Target,
    /// Seconds of measurement for each side.
    #[arg(long, default_value = "3", value_parser = parse_seconds)]
    seconds: f64,
    /// Also time MuJoCo (`mj_step`, nstep per serve) on shared/reference's ball-only scene in this run.
    #[arg(long)]
    mujoco: bool,
    /// Python interpreter that has the `mujoco` package.
    #[arg(long, default_value = "python3")]
    python: PathBuf,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
}

/// Runs the ball-world benchmark for about `seconds`; returns physics steps per second.
pub fn ball_steps_per_second(seconds: f64) -> (f64, u64) {
    let budget = Duration::from_secs_f64(seconds);
    let mut rng = Rng::seeded(1);
    let start = Instant::now();
    let mut steps: u64 = 0;
    let mut events = Vec::new();
    while start.elapsed() < budget {
        let s = serve::generate(ServeKind::P2, &mut rng, &MYOCHALLENGE_BOUNCE);
        let mut world = BallWorld::new(MYOCHALLENGE, s.ball);
        // A paddle swinging through the strike region in front of A's end, blade facing the net.
        let rot =
            UnitQuaternion::rotation_between(&Vector3::z(), &-Vector3::x()).expect("not opposite");
        let mut paddle = Paddle::at_rest(
            Side::A,
            Pose {
                pos: Vector3::new(arena::STRIKE_PLANE_X, 0.0, 1.1),
                rot,
            },
        );
        for k in 0..arena::EPISODE_STEPS {
            let phase = k as f64 * arena::CONTROL_DT * 6.0;
            paddle.lin_vel = Vector3::new(0.0, 1.5 * phase.cos(), 0.8 * phase.sin());
            paddle.ang_vel = Vector3::new(0.0, 0.0, 2.0 * phase.cos());
            events.clear();
            world.control_step(std::slice::from_mut(&mut paddle), &mut events);
        }
        steps += (arena::EPISODE_STEPS * arena::SUBSTEPS) as u64;
        std::hint::black_box(&world.ball);
    }
    (steps as f64 / start.elapsed().as_secs_f64(), steps)
}

fn mujoco_steps_per_second(python: &PathBuf, seconds: f64) -> anyhow::Result<(f64, String)> {
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tools/bench_ball.py");
    let out = Command::new(python)
        .arg(&script)
        .arg("--seconds")
        .arg(seconds.to_string())
        .output()
        .with_context(|| format!("running {} {}", python.display(), script.display()))?;
    if !out.status.success() {
        return Err(anyhow!(
            "{} failed: {}",
            script.display(),
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    let v: serde_json::Value =
        serde_json::from_slice(&out.stdout).context("reading the MuJoCo timing")?;
    let rate = v["steps_per_second"]
        .as_f64()
        .ok_or_else(|| anyhow!("no steps_per_second in {v}"))?;
    Ok((
        rate,
        v["mujoco_version"].as_str().unwrap_or("?").to_string(),
    ))
}

/// Runs `rally bench`.
pub fn run(args: &BenchArgs) -> Result<(), CliError> {
    match args.target {
        Target::Ball => {
            let mujoco = if args.mujoco {
                Some(mujoco_steps_per_second(&args.python, args.seconds)?)
            } else {
                None
            };
            let (ours, steps) = ball_steps_per_second(args.seconds);
            let ratio = mujoco.as_ref().map(|(m, _)| ours / m);
            if args.json {
                println!(
                    "{}",
                    json!({
                        "target": "ball",
                        "steps_per_second": ours,
                        "steps": steps,
                        "mujoco_steps_per_second": mujoco.as_ref().map(|m| m.0),
                        "mujoco_version": mujoco.as_ref().map(|m| m.1.clone()),
                        "ratio_vs_mujoco": ratio,
                    })
                );
            } else {
                println!("ball world (ball, table, net, one moving paddle), single thread:");
                println!("  muscle-rally  {ours:>12.0} steps/s");
                if let (Some((m, version)), Some(r)) = (&mujoco, ratio) {
                    println!("  MuJoCo {version:<6} {m:>12.0} steps/s  (ball-only reference scene, mj_step nstep)");
                    println!("  ratio         {r:>12.1}x");
                }
            }
            Ok(())
        }
    }
}
