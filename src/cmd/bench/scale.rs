//! `rally bench scale`: what scale-out costs and gives (docs/design.md §12), on the embedded SQLite and, given
//! a PostgreSQL server (`--postgres`), on PostgreSQL in the same run — per engine: the store's
//! overhead per match (claim, then store a played result under the lease), matches per hour with
//! the server's own worker and with 1, 2 and 4 `rally worker` processes, and the leaderboard's
//! requests per second and p99 once those matches are stored.

use std::io::BufRead;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context};
use serde_json::{json, Value};

/// Matches of the overhead measurement.
const OVERHEAD_MATCHES: usize = 300;
/// Matches (of `THROUGHPUT_RALLIES` rallies) each throughput configuration plays.
const THROUGHPUT_MATCHES: usize = 12;
const THROUGHPUT_RALLIES: u32 = 10;

/// Mean, median and 99th percentile of `xs`, ms.
fn summary(mut xs: Vec<f64>) -> Value {
    xs.sort_by(f64::total_cmp);
    let q = |p: f64| xs[((xs.len() - 1) as f64 * p).round() as usize];
    json!({"mean_ms": xs.iter().sum::<f64>() / xs.len() as f64, "p50_ms": q(0.5), "p99_ms": q(0.99)})
}

/// Where each measurement keeps its fresh store: files in a directory, or databases on a
/// PostgreSQL server.
enum Stores<'a> {
    Sqlite(&'a std::path::Path),
    Postgres(&'a str),
}

impl Stores<'_> {
    fn engine(&self) -> &'static str {
        match self {
            Stores::Sqlite(_) => "sqlite",
            Stores::Postgres(_) => "postgres",
        }
    }

    /// A fresh, empty store named `tag`.
    fn fresh(&self, tag: &str) -> anyhow::Result<server::db::Location> {
        Ok(match self {
            Stores::Sqlite(dir) => server::db::Location::Sqlite(dir.join(format!("{tag}.db"))),
            Stores::Postgres(admin) => {
                let name = format!("rally_bench_{}", tag.replace('-', "_"));
                let url = tokio::runtime::Builder::new_current_thread()
                    .enable_all()
                    .build()?
                    .block_on(server::db::recreate_postgres_database(admin, &name))?;
                server::db::Location::Postgres(url)
            }
        })
    }
}

/// Claim and store `OVERHEAD_MATCHES` one-rally matches in a fresh store (the same played record
/// each time: the simulation is not what is measured).
fn overhead(stores: &Stores) -> anyhow::Result<Value> {
    let location = stores.fresh("overhead")?;
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    runtime.block_on(async {
        let pool = server::db::open(&location).await?;
        server::db::register_builtins(&pool, "default").await?;
        let all = server::db::agents(&pool).await?;
        anyhow::ensure!(all.len() >= 2, "fewer than two built-in agents");
        let spec = agents::matchrun::MatchSpec {
            model: std::sync::Arc::new(sim::config::default_model()),
            config: sim::config::ArenaConfig::default(),
            preset: sim::arena::MYOCHALLENGE,
            rallies: 1,
            seed: 1,
            replay: false,
        };
        let scripted = agents::factory::PlayerSpec::scripted("scripted").context("scripted")?;
        let (record, replay) =
            agents::matchrun::play_match(&spec, &scripted, &scripted, &mut |_| {})
                .map_err(|e| anyhow!(e))?;
        for k in 0..OVERHEAD_MATCHES {
            let (a, b) = (&all[k % 2], &all[1 - k % 2]);
            server::db::queue_match(&pool, a, b, 1, k as u64, false, Default::default()).await?;
        }
        server::db::workers::register(&pool, "bench", "localhost", std::process::id(), 1, 60_000)
            .await?;
        let (mut claims, mut stores) = (Vec::new(), Vec::new());
        let frames = server::db::compress_replay(&record, &replay);
        for _ in 0..OVERHEAD_MATCHES {
            let t0 = Instant::now();
            let (_, lease) = server::db::workers::claim(&pool, "bench", 60_000, &["default"])
                .await?
                .context("a queued match")?;
            let t1 = Instant::now();
            let stored = server::db::store_result(&pool, &lease, &record, &frames, u64::MAX).await?;
            anyhow::ensure!(stored == server::db::Stored::Done, "not stored: {stored:?}");
            claims.push((t1 - t0).as_secs_f64() * 1e3);
            stores.push(t1.elapsed().as_secs_f64() * 1e3);
        }
        pool.close().await;
        let total: Vec<f64> = claims.iter().zip(&stores).map(|(c, s)| c + s).collect();
        Ok(json!({"matches": OVERHEAD_MATCHES, "claim": summary(claims), "store": summary(stores), "claim_and_store": summary(total)}))
    })
}

/// A child that is killed when dropped.
struct Kill(Child);

impl Drop for Kill {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts this binary with `args` (its data directory `dir`: the default robot alone, whatever the
/// machine has imported); returns it once its first stdout line is out, and that line.
fn spawn(dir: &std::path::Path, args: &[&str]) -> anyhow::Result<(Kill, String)> {
    let mut child = Command::new(std::env::current_exe()?)
        .args(args)
        .env("RALLY_DATA_DIR", dir)
        .env("RUST_LOG", "error")
        .env("RALLY_ADMIN_TOKEN", super::BENCH_TOKEN)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .with_context(|| format!("starting rally {}", args.join(" ")))?;
    let mut line = String::new();
    std::io::BufReader::new(child.stdout.take().context("stdout")?).read_line(&mut line)?;
    Ok((Kill(child), line.trim().to_string()))
}

/// Matches per hour with `in_server` workers in `rally serve` and `processes` `rally worker`s on a
/// fresh store; with `board`, then the leaderboard's requests per second and p99 (8 keep-alive
/// clients for `board` seconds) on the stored matches.
fn throughput(
    dir: &std::path::Path,
    stores: &Stores,
    in_server: usize,
    processes: usize,
    board: Option<f64>,
) -> anyhow::Result<(f64, Option<Value>)> {
    let tag = format!("s{in_server}-w{processes}");
    let db = stores.fresh(&tag)?.arg();
    let config = dir.join(format!("{}-{tag}.toml", stores.engine()));
    let settings = server::DEFAULT_SETTINGS_TOML
        .lines()
        .filter(|l| !l.starts_with("builtin_checkpoints"))
        .collect::<Vec<_>>()
        .join("\n");
    std::fs::write(&config, format!("{settings}\nbuiltin_checkpoints = \"\"\n"))?;
    let config = config.display().to_string();
    let workers = in_server.to_string();
    let (_server, line) = spawn(
        dir,
        &[
            "serve",
            "--config",
            &config,
            "--db",
            &db,
            "--addr",
            "127.0.0.1:0",
            "--workers",
            &workers,
            "--no-continuous",
        ],
    )?;
    let addr = line
        .strip_prefix("listening on http://")
        .ok_or_else(|| anyhow!("unexpected first line {line:?}"))?
        .to_string();
    let mut ids = Vec::new();
    for k in 0..THROUGHPUT_MATCHES {
        let (a, b) = [(1, 2), (2, 3), (3, 1)][k % 3];
        let m = super::call_json(
            &addr,
            "POST",
            "/api/v1/matches",
            &format!("{{\"a\":{a},\"b\":{b},\"rallies\":{THROUGHPUT_RALLIES},\"seed\":{k}}}"),
        )?;
        ids.push(
            m["id"]
                .as_i64()
                .ok_or_else(|| anyhow!("queueing failed: {m}"))?,
        );
    }
    let t0 = Instant::now();
    let mut children = Vec::new();
    for w in 0..processes {
        let name = format!("bench-{w}");
        children.push(
            spawn(
                dir,
                &["worker", "--config", &config, "--db", &db, "--name", &name],
            )?
            .0,
        );
    }
    loop {
        let done = super::call_json(&addr, "GET", "/api/v1/matches?status=done&limit=1000", "")?;
        if done["matches"].as_array().map_or(0, |m| m.len()) >= ids.len() {
            break;
        }
        anyhow::ensure!(
            t0.elapsed() < Duration::from_secs(900),
            "{tag}: matches did not finish in 15 minutes"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let per_hour = ids.len() as f64 / t0.elapsed().as_secs_f64() * 3600.0;
    let board = match board {
        Some(seconds) => {
            let (rps, p50, p99) = super::load(&addr, "/api/v1/leaderboard", 8, seconds)?;
            Some(json!({"requests_per_second": rps, "p50_ms": p50 * 1e3, "p99_ms": p99 * 1e3}))
        }
        None => None,
    };
    Ok((per_hour, board))
}

/// One engine's figures.
fn engine_bench(
    dir: &std::path::Path,
    stores: &Stores,
    board_seconds: f64,
) -> anyhow::Result<Value> {
    let overhead = overhead(stores)?;
    let (serve, board) = throughput(dir, stores, 1, 0, Some(board_seconds))?;
    let mut processes = Vec::new();
    for n in [1, 2, 4] {
        let (per_hour, _) = throughput(dir, stores, 0, n, None)?;
        processes.push(json!({"worker_processes": n, "matches_per_hour": per_hour, "vs_serve": per_hour / serve}));
    }
    Ok(json!({
        "engine": stores.engine(),
        "overhead": overhead,
        "serve_one_worker_matches_per_hour": serve,
        "worker_processes": processes,
        "leaderboard": board,
    }))
}

/// The whole benchmark, as JSON: SQLite, and PostgreSQL when `postgres` (an admin URL of a server
/// where databases may be created: each measurement gets a fresh one) is given.
pub fn scale_bench(postgres: Option<&str>, board_seconds: f64) -> anyhow::Result<Value> {
    let dir = std::env::temp_dir().join(format!("rally-bench-scale-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir)?;
    let result = (|| -> anyhow::Result<Value> {
        let mut engines = vec![engine_bench(&dir, &Stores::Sqlite(&dir), board_seconds)?];
        if let Some(admin) = postgres {
            engines.push(engine_bench(&dir, &Stores::Postgres(admin), board_seconds)?);
        }
        // Every figure also next to one `rally serve` on SQLite, the default set-up.
        let reference = engines[0]["serve_one_worker_matches_per_hour"]
            .as_f64()
            .unwrap_or(f64::NAN);
        for e in &mut engines {
            let serve = e["serve_one_worker_matches_per_hour"]
                .as_f64()
                .unwrap_or(f64::NAN);
            e["serve_vs_sqlite_serve"] = json!(serve / reference);
            for p in e["worker_processes"].as_array_mut().into_iter().flatten() {
                let m = p["matches_per_hour"].as_f64().unwrap_or(f64::NAN);
                p["vs_sqlite_serve"] = json!(m / reference);
            }
        }
        Ok(json!({
            "target": "scale",
            "cores": std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
            "throughput_matches": THROUGHPUT_MATCHES,
            "throughput_rallies": THROUGHPUT_RALLIES,
            "engines": engines,
            "postgres": if postgres.is_some() { "measured" } else { "not measured: give --postgres postgres://USER@HOST:PORT/postgres (a server where this user may create databases)" },
        }))
    })();
    let _ = std::fs::remove_dir_all(&dir);
    result
}
