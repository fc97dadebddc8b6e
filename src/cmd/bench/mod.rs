//! `rally bench`: how fast the simulator runs, next to MuJoCo on the same work measured in the same
//! run (through `tools/bench_ball.py`), reported as a ratio.

use std::path::{Path, PathBuf};
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

mod robot;
mod server;
use server::*;
mod scale;

/// What to measure.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum Target {
    /// Ball-world physics steps per second, single thread: ball, table, net and one moving paddle,
    /// P2 serves of 300 control steps each.
    Ball,
    /// Musculoskeletal physics steps per second, single thread: one robot (dynamics, muscles,
    /// grip), and the dual arena (two robots and the ball), from the "ready" keyframe (else the
    /// model's first) with every muscle at 0.1 and the servos holding still; the split of our step
    /// by stage. `--model myochallenge` measures MyoSuite's robot.
    Robot,
    /// Evaluation episodes and match rallies per second per core, with the scripted agent.
    Agents,
    /// PPO training with the default configuration (`config/train.toml`, K-MAC): env steps/s while
    /// training and in the rollout phase, the split between simulation, policy and update, next to
    /// the physics alone (the same environments stepped with fixed controls, all cores) as the
    /// ceiling, measured in the same run.
    Train,
    /// The tournament server from outside: matches per hour, leaderboard requests per second and
    /// p99 latency (next to /healthz) while two matches run, peak memory.
    Server,
    /// Scale-out, per engine (SQLite; PostgreSQL too with --postgres): the store's claim + store
    /// overhead per match, matches per hour with the server's own worker next to 1, 2 and 4
    /// `rally worker` processes on one store, and leaderboard requests/s and p99.
    Scale,
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
    /// Also time MuJoCo (`mj_step`, nstep per serve) on the reference scene's ball, table and net (sim/tests/fixtures/myosuite_tt_ball_only.xml) in this run.
    #[arg(long)]
    mujoco: bool,
    /// Python interpreter that has the `mujoco` package [default: the one `rally model import
    /// myosuite` installed, DATA/venv-myosuite/bin/python, if it exists; else python3].
    #[arg(long)]
    python: Option<PathBuf>,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
    /// `robot`, `agents` and `train`: the model — `default` (the built-in 75-muscle body),
    /// `myochallenge` (MyoSuite's robot, after `rally model import myosuite`) or an MJCF file.
    #[arg(long, default_value = "default")]
    model: String,
    /// Concurrent keep-alive clients (`server` only).
    #[arg(long, default_value = "8", value_parser = clap::value_parser!(u16).range(1..=256))]
    clients: u16,
    /// `scale` only: also measure PostgreSQL, on this server (an admin URL, e.g.
    /// postgres://postgres@127.0.0.1:5432/postgres: each measurement creates a fresh database).
    #[arg(long, value_name = "URL", env = "RALLY_BENCH_POSTGRES")]
    postgres: Option<String>,
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

fn run_python(
    python: &Path,
    script: &str,
    seconds: f64,
    extra: &[String],
) -> anyhow::Result<serde_json::Value> {
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(script);
    let out = Command::new(python)
        .arg(&script)
        .arg("--seconds")
        .arg(seconds.to_string())
        .args(extra)
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

fn mujoco_steps_per_second(python: &Path, seconds: f64) -> anyhow::Result<(f64, String)> {
    let v = run_python(python, "tools/bench_ball.py", seconds, &[])?;
    let rate = v["steps_per_second"]
        .as_f64()
        .ok_or_else(|| anyhow!("no steps_per_second in {v}"))?;
    Ok((
        rate,
        v["mujoco_version"].as_str().unwrap_or("?").to_string(),
    ))
}

/// (evaluation episodes/s, match rallies/s, simulated seconds per rally), on one thread.
fn agent_rates(
    seconds: f64,
    model: std::sync::Arc<sim::model::Model>,
    config: sim::config::ArenaConfig,
) -> anyhow::Result<(f64, f64, f64)> {
    use agents::eval::{evaluate, Evaluation};
    use agents::factory::PlayerSpec;
    use agents::matchrun::{play_match, MatchSpec};
    let spec = PlayerSpec::scripted("scripted").expect("built-in agent");
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let budget = Duration::from_secs_f64(seconds);

    let (mut episodes, mut seed) = (0usize, 0u64);
    let start = Instant::now();
    while start.elapsed() < budget {
        let e = Evaluation {
            lead_in: false,
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

/// Training throughput for about `seconds` (at least two iterations), then the physics alone on the
/// same number of environments for as long.
pub fn train_rates(
    seconds: f64,
    model: std::sync::Arc<sim::model::Model>,
    arena: sim::config::ArenaConfig,
) -> anyhow::Result<serde_json::Value> {
    use agents::ppo::trainer::Trainer;
    use agents::ppo::{Method, TrainConfig};
    agents::ppo::tune_candle_threads();
    let config = TrainConfig::default();
    let envs = config.ppo.envs;
    let mut t = Trainer::on(
        model.clone(),
        arena.clone(),
        "bench",
        Method::Kmac,
        config,
        1,
    )
    .map_err(anyhow::Error::msg)?;
    // The first iteration warms caches and starts the segment; time the ones after it.
    t.iterate().map_err(anyhow::Error::msg)?;
    t.timing = Default::default();
    let start = Instant::now();
    let mut iterations = 0;
    while iterations < 2 || start.elapsed().as_secs_f64() < seconds {
        t.iterate().map_err(anyhow::Error::msg)?;
        iterations += 1;
    }
    let wall = start.elapsed().as_secs_f64();
    let tm = t.timing;
    // The physics alone: the same environments, fixed controls (every muscle at 0.1), all cores.
    let physics = agents::vecenv::physics_alone(&model, &arena, envs, seconds.max(0.5))
        .map_err(anyhow::Error::msg)?;
    let training = tm.env_steps as f64 / wall;
    let rollout = tm.env_steps as f64 / (tm.simulation + tm.policy);
    let total = (tm.simulation + tm.policy + tm.update).max(1e-9);
    Ok(json!({
        "target": "train",
        "method": "kmac",
        "threads": rayon::current_num_threads(),
        "envs": envs,
        "iterations": iterations,
        "env_steps": tm.env_steps,
        "training_steps_per_second": training,
        "rollout_steps_per_second": rollout,
        "physics_alone_steps_per_second": physics,
        "rollout_vs_physics": rollout / physics,
        "share": {
            "simulation": tm.simulation / total,
            "policy": tm.policy / total,
            "update": tm.update / total,
        },
    }))
}

/// Runs `rally bench`.
pub fn run(args: &BenchArgs) -> Result<(), CliError> {
    let robotless = matches!(args.target, Target::Ball | Target::Server | Target::Scale);
    if robotless && args.model != "default" {
        return Err(CliError::Usage(
            "--model: only `robot`, `agents` and `train` measure a robot".into(),
        ));
    }
    match args.target {
        Target::Train => bench_train(args),
        Target::Scale => bench_scale(args),
        Target::Server => bench_server(args),
        Target::Ball => bench_ball(args),
        Target::Agents => bench_agents(args),
        Target::Robot => bench_robot(args),
    }
}

/// `rally bench train`: PPO training rates next to the physics alone.
fn bench_train(args: &BenchArgs) -> Result<(), CliError> {
    let (model, config, _) = robot::bench_model(&args.model)?;
    let mut r = train_rates(args.seconds, model, config)?;
    r["model"] = args.model.clone().into();
    if args.json {
        println!("{r}");
    } else {
        let f = |k: &str| r[k].as_f64().unwrap_or(f64::NAN);
        let s = |k: &str| 100.0 * r["share"][k].as_f64().unwrap_or(f64::NAN);
        println!(
            "PPO training, K-MAC, model {}, {} environments, {} threads ({} iterations, {} control steps):",
            args.model, r["envs"], r["threads"], r["iterations"], r["env_steps"]
        );
        println!(
            "  training       {:>9.0} env steps/s (rollout and update)",
            f("training_steps_per_second")
        );
        println!(
            "  rollout phase  {:>9.0} env steps/s (simulation and policy)",
            f("rollout_steps_per_second")
        );
        println!(
            "  physics alone  {:>9.0} env steps/s (same environments, fixed controls: the ceiling)",
            f("physics_alone_steps_per_second")
        );
        println!("  rollout / physics alone {:.2}", f("rollout_vs_physics"));
        println!(
            "  time: simulation {:.0}%, policy {:.0}%, update {:.0}%",
            s("simulation"),
            s("policy"),
            s("update")
        );
    }
    Ok(())
}

/// `rally bench scale`: the store's overhead per match and the scale-out, per engine.
fn bench_scale(args: &BenchArgs) -> Result<(), CliError> {
    let r = scale::scale_bench(args.postgres.as_deref(), args.seconds)?;
    if args.json {
        println!("{r}");
    } else {
        let f = |v: &serde_json::Value, k: &str| v[k].as_f64().unwrap_or(f64::NAN);
        println!(
            "scale-out ({} cores; {} matches of {} rallies per throughput figure, scripted built-ins):",
            r["cores"], r["throughput_matches"], r["throughput_rallies"]
        );
        for e in r["engines"].as_array().into_iter().flatten() {
            let o = &e["overhead"];
            println!("{}:", e["engine"].as_str().unwrap_or("?"));
            for k in ["claim", "store", "claim_and_store"] {
                println!(
                    "  {k:<16} {:>7.2} ms mean   p50 {:.2} ms   p99 {:.2} ms   ({} matches)",
                    f(&o[k], "mean_ms"),
                    f(&o[k], "p50_ms"),
                    f(&o[k], "p99_ms"),
                    o["matches"]
                );
            }
            let serve = f(e, "serve_one_worker_matches_per_hour");
            println!(
                "  matches/h: rally serve, 1 worker of its own       {serve:>8.0}   ({:.2}x SQLite's)",
                f(e, "serve_vs_sqlite_serve")
            );
            for p in e["worker_processes"].as_array().into_iter().flatten() {
                println!(
                    "  matches/h: rally serve --workers 0 + {} x worker  {:>8.0}   ({:.2}x SQLite's rally serve)",
                    p["worker_processes"],
                    f(p, "matches_per_hour"),
                    f(p, "vs_sqlite_serve")
                );
            }
            let b = &e["leaderboard"];
            println!(
                "  leaderboard      {:>7.0} requests/s   p50 {:.2} ms   p99 {:.2} ms   (8 clients)",
                f(b, "requests_per_second"),
                f(b, "p50_ms"),
                f(b, "p99_ms")
            );
        }
        if r["postgres"] != "measured" {
            println!("PostgreSQL: {}", r["postgres"].as_str().unwrap_or(""));
        }
    }
    Ok(())
}

/// `rally bench server`: the tournament server from outside.
fn bench_server(args: &BenchArgs) -> Result<(), CliError> {
    let r = server_bench(args.seconds, args.clients as usize)?;
    if args.json {
        println!("{r}");
    } else {
        let f = |k: &str, q: &str| r[k][q].as_f64().unwrap_or(f64::NAN);
        println!(
            "tournament server (2 workers, fresh SQLite), {} keep-alive clients:",
            r["clients"]
        );
        println!(
            "  matches       {:>9.0} matches/h (20 rallies, scripted built-ins)",
            r["matches_per_hour_20_rallies"]
                .as_f64()
                .unwrap_or(f64::NAN)
        );
        for (k, what) in [
            ("uncached", "every match builds its players"),
            ("cached", "the workers' player cache"),
        ] {
            let c = &r["checkpoints"][k];
            println!(
                "  matches       {:>9.0} matches/h (20 rallies, trained built-ins; {what}), setup {:.1} ms",
                c["matches_per_hour"].as_f64().unwrap_or(f64::NAN),
                c["setup_ms"].as_f64().unwrap_or(f64::NAN)
            );
        }
        println!("  while {} matches run:", r["matches_running_during_load"]);
        for k in ["leaderboard", "healthz"] {
            println!(
                "  {k:<12}  {:>9.0} req/s   p50 {:.2} ms   p99 {:.2} ms",
                f(k, "requests_per_second"),
                f(k, "p50_ms"),
                f(k, "p99_ms")
            );
        }
        println!(
            "  leaderboard / healthz throughput {:.2}",
            r["leaderboard_vs_healthz_throughput"]
                .as_f64()
                .unwrap_or(f64::NAN)
        );
        println!(
            "  server memory: peak RSS {:.1} MiB",
            r["server_peak_rss_mib"].as_f64().unwrap_or(f64::NAN)
        );
    }
    Ok(())
}

impl BenchArgs {
    /// `--python`, else the import's interpreter (it has MuJoCo, pinned), else `python3` on PATH.
    fn python(&self) -> PathBuf {
        self.python.clone().unwrap_or_else(|| {
            let venv = crate::cmd::model::data_dir().join("venv-myosuite/bin/python");
            if venv.exists() {
                venv
            } else {
                PathBuf::from("python3")
            }
        })
    }
}

/// `rally bench ball`: ball-world steps per second, with MuJoCo's beside them on `--mujoco`.
fn bench_ball(args: &BenchArgs) -> Result<(), CliError> {
    let mujoco = if args.mujoco {
        Some(mujoco_steps_per_second(&args.python(), args.seconds)?)
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

/// `rally bench agents`: evaluation episodes and match rallies per second.
fn bench_agents(args: &BenchArgs) -> Result<(), CliError> {
    let (model, config, _) = robot::bench_model(&args.model)?;
    let (eps, rps, rally_s) = agent_rates(args.seconds, model, config)?;
    if args.json {
        println!(
            "{}",
            json!({"target": "agents", "model": args.model, "episodes_per_second": eps, "rallies_per_second": rps, "simulated_seconds_per_rally": rally_s})
        );
    } else {
        println!("scripted agent, model {}, one core:", args.model);
        println!("  evaluation    {eps:>8.1} single-serve episodes/s (P2)");
        println!("  match         {rps:>8.1} rallies/s (scripted vs scripted, {rally_s:.2} simulated s per rally)");
    }
    Ok(())
}

/// `rally bench robot`: musculoskeletal steps per second and their split by stage.
fn bench_robot(args: &BenchArgs) -> Result<(), CliError> {
    let r = robot::measure(
        &args.model,
        args.seconds,
        args.mujoco.then_some(args.python().as_path()),
    )?;
    if args.json {
        println!("{r}");
    } else {
        robot::print(&r);
    }
    Ok(())
}
