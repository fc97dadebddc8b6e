//! `rally bench robot`: musculoskeletal physics steps per second for one robot and for the dual arena
//! (two robots and the ball), single thread, next to MuJoCo's `mj_step` on the same model measured in
//! the same run (`tools/bench_robot.py`), with the split of our step by stage.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use nalgebra::Vector3;
use serde_json::json;
use sim::arena::{Side, MYOCHALLENGE};
use sim::config::ArenaConfig;
use sim::dynamics::{self, Data, State};
use sim::model::Model;
use sim::robot::Robot;
use sim::BallWorld;

use super::super::model::resolve_model;
use super::super::CliError;
use super::run_python;

/// Physics steps of a robot between resets, as `tools/bench_robot.py` does.
const STEPS_PER_RESET: usize = 2000;

/// Passes over the recorded stretch per stage of the split.
const SPLIT_REPEATS: usize = 7;

/// The model to measure and its arena configuration: `default`, `myochallenge` or a file (with the
/// default robot's grip settings).
pub fn bench_model(arg: &str) -> Result<(Arc<Model>, ArenaConfig, PathBuf), CliError> {
    let (model, path) = resolve_model(arg)?;
    Ok((Arc::new(model), crate::cmd::arena_config(arg), path))
}

/// The start of every stretch: the keyframe, every muscle's control and activation at 0.1, every
/// position servo holding its joint where the keyframe puts it (as `tools/bench_robot.py`).
fn ready(robot: &mut Robot, model: &Model) {
    robot.reset(sim::episode::ready_pose(model).as_deref());
    set_controls(model, &mut robot.state);
}

fn set_controls(model: &Model, state: &mut State) {
    for (i, a) in model.actuators.iter().enumerate() {
        if a.muscle().is_some() {
            state.ctrl[i] = 0.1;
            state.act[i] = 0.1;
        } else if let sim::model::Transmission::Joint(j) = a.transmission {
            let q = state.qpos[model.joints[j].qpos_adr];
            state.ctrl[i] = a.ctrlrange.map_or(q, |[lo, hi]| q.clamp(lo, hi));
        }
    }
}

/// Steps per second of `step` on `target` over stretches of [`STEPS_PER_RESET`] from `reset`.
fn rate<T>(
    seconds: f64,
    target: &mut T,
    reset: impl Fn(&mut T),
    mut step: impl FnMut(&mut T),
) -> f64 {
    let budget = Duration::from_secs_f64(seconds);
    let start = Instant::now();
    let mut steps = 0usize;
    while start.elapsed() < budget {
        reset(target);
        for _ in 0..STEPS_PER_RESET {
            step(target);
        }
        steps += STEPS_PER_RESET;
    }
    steps as f64 / start.elapsed().as_secs_f64()
}

/// Microseconds per robot step by stage, measured on the states of one recorded stretch: forward
/// kinematics, tendons (paths, wrapping, moment arms), the rest of the dynamics (mass matrix, bias,
/// muscles, couplings, limits, integration) and what the robot adds (grip and paddle). Each stage's
/// time is the fastest of [`SPLIT_REPEATS`] passes over the stretch (another process slows a pass;
/// nothing makes one faster), and the stages are differences of nested timings.
fn split(model: &Arc<Model>, config: &ArenaConfig) -> anyhow::Result<serde_json::Value> {
    let mut robot = Robot::new(model.clone(), &config.grip, Side::A).map_err(anyhow::Error::msg)?;
    ready(&mut robot, model);
    let mut states = Vec::with_capacity(STEPS_PER_RESET);
    for _ in 0..STEPS_PER_RESET {
        states.push(robot.state.clone());
        robot.physics_step();
    }
    let per_step = |f: &mut dyn FnMut(&State)| -> f64 {
        (0..SPLIT_REPEATS)
            .map(|_| {
                let start = Instant::now();
                for s in &states {
                    f(s);
                }
                start.elapsed().as_secs_f64() * 1e6 / states.len() as f64
            })
            .fold(f64::INFINITY, f64::min)
    };
    let mut data = Data::new(model);
    let kinematics = per_step(&mut |s| data.kin.update(model, &s.qpos));
    let tendons = per_step(&mut |s| {
        data.kin.update(model, &s.qpos);
        data.ten.update(model, &data.kin);
    }) - kinematics;
    let dynamics = per_step(&mut |s| {
        let mut s = s.clone();
        dynamics::step(model, &mut data, &mut s);
    }) - kinematics
        - tendons;
    // The whole robot step on the same stretch, played from its start (the grip keeps state).
    let whole = (0..SPLIT_REPEATS)
        .map(|_| {
            ready(&mut robot, model);
            let start = Instant::now();
            for _ in 0..STEPS_PER_RESET {
                robot.physics_step();
            }
            start.elapsed().as_secs_f64() * 1e6 / STEPS_PER_RESET as f64
        })
        .fold(f64::INFINITY, f64::min);
    Ok(json!({
        "kinematics": kinematics,
        "tendons_and_wrapping": tendons,
        "dynamics": dynamics,
        "grip_and_paddle": whole - kinematics - tendons - dynamics,
        "total": whole,
    }))
}

/// The numbers `rally bench robot` prints.
pub fn measure(
    arg: &str,
    seconds: f64,
    python: Option<&Path>,
) -> Result<serde_json::Value, CliError> {
    let (model, config, path) = bench_model(arg)?;
    let mujoco = match python {
        None => None,
        Some(py) => {
            let extra = match arg {
                "default" => vec![],
                _ => vec![
                    "--model".to_string(),
                    std::path::absolute(&path)?.display().to_string(),
                ],
            };
            Some(run_python(py, "tools/bench_robot.py", seconds, &extra)?)
        }
    };
    let mut robot = Robot::new(model.clone(), &config.grip, Side::A).map_err(anyhow::Error::msg)?;
    let single = rate(
        seconds,
        &mut robot,
        |r| ready(r, &model),
        |r| {
            r.physics_step();
        },
    );
    let ball = sim::BallState::new(Vector3::new(-1.2, -0.45, 1.45), Vector3::new(5.6, 1.6, 0.1));
    let mut arena = sim::dual::DualArena::new(model.clone(), &config, MYOCHALLENGE, ball)
        .map_err(anyhow::Error::msg)?;
    let mut events = Vec::new();
    let dual = rate(
        seconds,
        &mut arena,
        |a| {
            for r in a.robots.iter_mut() {
                ready(r, &model);
            }
            a.world = BallWorld::new(MYOCHALLENGE, ball);
        },
        |a| {
            events.clear();
            a.physics_step(&mut events);
        },
    );
    let split = split(&model, &config)?;
    let mj = |key: &str| mujoco.as_ref().and_then(|m| m[key].as_f64());
    let mj_single = mj("single_steps_per_second");
    // The default robot's script composes a MuJoCo dual arena; for another model, an arena step is
    // two MuJoCo robot steps.
    let mj_dual = mj("dual_steps_per_second").or(mj_single.map(|s| s / 2.0));
    let side = |ours: f64, theirs: Option<f64>| {
        json!({
            "ours_steps_per_s": ours,
            "mujoco_steps_per_s": theirs,
            "ratio": theirs.map(|t| ours / t),
        })
    };
    Ok(json!({
        "model": path.display().to_string(),
        "dof": model.nv,
        "muscles": model.muscles().count(),
        "one_robot": side(single, mj_single),
        "dual_arena": side(dual, mj_dual),
        "split_us_per_step": split,
        "mujoco_version": mujoco.as_ref().map(|m| m["mujoco_version"].clone()),
    }))
}

/// Prints [`measure`]'s numbers as a table.
pub fn print(r: &serde_json::Value) {
    let f = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    println!(
        "musculoskeletal robot ({}: {} DoF, {} muscles), single thread:",
        r["model"].as_str().unwrap_or("?"),
        r["dof"],
        r["muscles"]
    );
    for (label, key) in [("one robot ", "one_robot"), ("dual arena", "dual_arena")] {
        let s = &r[key];
        println!(
            "  {label}    muscle-rally {:>9.0} steps/s  ({:.0} µs/step)",
            f(&s["ours_steps_per_s"]),
            1e6 / f(&s["ours_steps_per_s"])
        );
        if let Some(m) = s["mujoco_steps_per_s"].as_f64() {
            println!(
                "                MuJoCo       {m:>9.0} steps/s  ({:.0} µs/step)   ratio {:.1}x",
                1e6 / m,
                f(&s["ratio"])
            );
        }
    }
    // Stages are differences of timings: one below a microsecond is within their noise.
    let us = |key: &str| {
        let v = f(&r["split_us_per_step"][key]);
        if v < 1.0 {
            "<1".to_string()
        } else {
            format!("{v:.1}")
        }
    };
    println!(
        "  our robot step, µs: kinematics {}, tendons and wrapping {}, dynamics {}, grip and paddle {} (total {})",
        us("kinematics"),
        us("tendons_and_wrapping"),
        us("dynamics"),
        us("grip_and_paddle"),
        us("total")
    );
}
