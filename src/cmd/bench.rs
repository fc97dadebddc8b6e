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
    /// Musculoskeletal physics steps per second, single thread: one robot (dynamics, 75 muscles,
    /// grip), and the dual arena (two robots and the ball), from "ready" with every muscle at 0.1.
    Robot,
    /// Evaluation episodes and match rallies per second per core, with the scripted agent.
    Agents,
}

/// Arguments of `rally bench`.
#[derive(Args, Debug)]
#[command(
    after_help = "Examples:\n  rally bench ball --mujoco    (tools/bench_ball.py times MuJoCo; needs `pip install mujoco numpy`)\n  rally bench robot --mujoco   (tools/bench_robot.py)"
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

/// Physics steps of a robot between resets, as `tools/bench_robot.py` does.
const ROBOT_STEPS_PER_RESET: usize = 2000;

fn robot_model() -> anyhow::Result<std::sync::Arc<sim::model::Model>> {
    let model = sim::mjcf::parse_str(
        sim::config::DEFAULT_MODEL_XML,
        "config/models/upper_body.xml",
    )?;
    Ok(std::sync::Arc::new(model))
}

/// Puts a robot at "ready" with every muscle's control and activation at 0.1.
fn ready(robot: &mut sim::robot::Robot, model: &sim::model::Model) {
    let key = model
        .keyframes
        .iter()
        .find(|k| k.name == "ready")
        .map(|k| k.qpos.clone());
    robot.reset(key.as_deref());
    for (i, a) in model.actuators.iter().enumerate() {
        if a.muscle().is_some() {
            robot.state.ctrl[i] = 0.1;
            robot.state.act[i] = 0.1;
        }
    }
}

/// (one robot, dual arena) physics steps per second.
pub fn robot_steps_per_second(seconds: f64) -> anyhow::Result<(f64, f64)> {
    let model = robot_model()?;
    let config = sim::config::ArenaConfig::default();
    let budget = Duration::from_secs_f64(seconds);
    let mut robot =
        sim::robot::Robot::new(model.clone(), &config.grip, Side::A).map_err(anyhow::Error::msg)?;
    let start = Instant::now();
    let mut steps = 0usize;
    while start.elapsed() < budget {
        ready(&mut robot, &model);
        for _ in 0..ROBOT_STEPS_PER_RESET {
            robot.physics_step();
        }
        steps += ROBOT_STEPS_PER_RESET;
    }
    let single = steps as f64 / start.elapsed().as_secs_f64();

    let ball = sim::BallState::new(Vector3::new(-1.2, -0.45, 1.45), Vector3::new(5.6, 1.6, 0.1));
    let mut arena = sim::dual::DualArena::new(model.clone(), &config, MYOCHALLENGE, ball)
        .map_err(anyhow::Error::msg)?;
    let mut events = Vec::new();
    let start = Instant::now();
    let mut steps = 0usize;
    while start.elapsed() < budget {
        for r in arena.robots.iter_mut() {
            ready(r, &model);
        }
        arena.world = BallWorld::new(MYOCHALLENGE, ball);
        for _ in 0..ROBOT_STEPS_PER_RESET {
            events.clear();
            arena.physics_step(&mut events);
        }
        steps += ROBOT_STEPS_PER_RESET;
    }
    Ok((single, steps as f64 / start.elapsed().as_secs_f64()))
}

fn run_python(python: &PathBuf, script: &str, seconds: f64) -> anyhow::Result<serde_json::Value> {
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(script);
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
    serde_json::from_slice(&out.stdout).context("reading the MuJoCo timing")
}

fn mujoco_steps_per_second(python: &PathBuf, seconds: f64) -> anyhow::Result<(f64, String)> {
    let v = run_python(python, "tools/bench_ball.py", seconds)?;
    let rate = v["steps_per_second"]
        .as_f64()
        .ok_or_else(|| anyhow!("no steps_per_second in {v}"))?;
    Ok((
        rate,
        v["mujoco_version"].as_str().unwrap_or("?").to_string(),
    ))
}

/// (evaluation episodes/s, match rallies/s, simulated seconds per rally), on one thread.
fn agent_rates(seconds: f64) -> anyhow::Result<(f64, f64, f64)> {
    use agents::eval::{evaluate, Evaluation};
    use agents::matchrun::{play_match, MatchSpec};
    use agents::player::PlayerSpec;
    let model = robot_model()?;
    let config = sim::config::ArenaConfig::default();
    let spec = PlayerSpec::scripted("scripted").expect("built-in agent");
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let budget = Duration::from_secs_f64(seconds);

    let (mut episodes, mut seed) = (0usize, 0u64);
    let start = Instant::now();
    while start.elapsed() < budget {
        let e = Evaluation {
            model: model.clone(),
            config: config.clone(),
            preset: MYOCHALLENGE,
            kind: ServeKind::P2,
            episodes: 20,
            seed,
        };
        episodes += pool
            .install(|| evaluate(&e, &spec, &|| {}))
            .map_err(anyhow::Error::msg)?
            .episodes;
        seed += 1;
    }
    let episodes_per_second = episodes as f64 / start.elapsed().as_secs_f64();

    let (mut rallies, mut simulated, mut seed) = (0usize, 0.0, 0u64);
    let start = Instant::now();
    while start.elapsed() < budget {
        let m = MatchSpec {
            model: model.clone(),
            config: config.clone(),
            preset: MYOCHALLENGE,
            rallies: 10,
            seed,
            replay: false,
        };
        let (r, _) = play_match(&m, &spec, &spec, &mut |_| {}).map_err(anyhow::Error::msg)?;
        rallies += r.rallies.len();
        simulated += r.rallies.iter().map(|x| x.duration).sum::<f64>();
        seed += 1;
    }
    let rallies_per_second = rallies as f64 / start.elapsed().as_secs_f64();
    Ok((
        episodes_per_second,
        rallies_per_second,
        simulated / rallies.max(1) as f64,
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
        Target::Agents => {
            let (eps, rps, rally_s) = agent_rates(args.seconds)?;
            if args.json {
                println!(
                    "{}",
                    json!({"target": "agents", "episodes_per_second": eps, "rallies_per_second": rps, "simulated_seconds_per_rally": rally_s})
                );
            } else {
                println!("scripted agent, one core:");
                println!("  evaluation    {eps:>8.1} single-serve episodes/s (P2)");
                println!("  match         {rps:>8.1} rallies/s (scripted vs scripted, {rally_s:.2} simulated s per rally)");
            }
            Ok(())
        }
        Target::Robot => {
            let mujoco = if args.mujoco {
                Some(run_python(
                    &args.python,
                    "tools/bench_robot.py",
                    args.seconds,
                )?)
            } else {
                None
            };
            let (single, dual) = robot_steps_per_second(args.seconds)?;
            let mj = |key: &str| mujoco.as_ref().and_then(|m| m[key].as_f64());
            let (mj_single, mj_dual) = (mj("single_steps_per_second"), mj("dual_steps_per_second"));
            if args.json {
                println!(
                    "{}",
                    json!({
                        "target": "robot",
                        "single_steps_per_second": single,
                        "dual_steps_per_second": dual,
                        "mujoco_single_steps_per_second": mj_single,
                        "mujoco_dual_steps_per_second": mj_dual,
                        "mujoco_version": mujoco.as_ref().map(|m| m["mujoco_version"].clone()),
                        "ratio_single": mj_single.map(|m| single / m),
                        "ratio_dual": mj_dual.map(|m| dual / m),
                    })
                );
            } else {
                println!("musculoskeletal robot (config/models/upper_body.xml: 25 DoF, 75 muscles), single thread:");
                println!("  one robot     muscle-rally {single:>9.0} steps/s");
                if let Some(m) = mj_single {
                    println!(
                        "                MuJoCo       {m:>9.0} steps/s   ratio {:.1}x",
                        single / m
                    );
                }
                println!("  dual arena    muscle-rally {dual:>9.0} steps/s");
                if let Some(m) = mj_dual {
                    println!(
                        "                MuJoCo       {m:>9.0} steps/s   ratio {:.1}x",
                        dual / m
                    );
                }
            }
            Ok(())
        }
    }
}
