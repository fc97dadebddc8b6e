//! `rally bench server`: a real server, its matches per hour and its answers under load.

use super::*;

/// A keep-alive HTTP/1.1 client for GET requests with a `Content-Length` answer (the server's JSON).
pub(super) struct KeepAlive {
    reader: std::io::BufReader<std::net::TcpStream>,
    host: String,
}

impl KeepAlive {
    fn connect(addr: &str) -> anyhow::Result<KeepAlive> {
        let s = std::net::TcpStream::connect(addr)?;
        s.set_nodelay(true)?;
        s.set_read_timeout(Some(Duration::from_secs(30)))?;
        Ok(KeepAlive {
            reader: std::io::BufReader::new(s),
            host: addr.to_string(),
        })
    }

    /// GETs `path`; returns the status.
    fn get(&mut self, path: &str) -> anyhow::Result<u16> {
        use std::io::{BufRead, Read, Write};
        let req = format!("GET {path} HTTP/1.1\r\nHost: {}\r\n\r\n", self.host);
        self.reader.get_mut().write_all(req.as_bytes())?;
        let mut line = String::new();
        self.reader.read_line(&mut line)?;
        let status: u16 = line
            .split_whitespace()
            .nth(1)
            .and_then(|s| s.parse().ok())
            .ok_or_else(|| anyhow!("bad status line {line:?}"))?;
        let mut len = 0usize;
        loop {
            line.clear();
            self.reader.read_line(&mut line)?;
            if line == "\r\n" || line.is_empty() {
                break;
            }
            if let Some((k, v)) = line.split_once(':') {
                if k.eq_ignore_ascii_case("content-length") {
                    len = v.trim().parse()?;
                }
            }
        }
        let mut body = vec![0u8; len];
        self.reader.read_exact(&mut body)?;
        Ok(status)
    }
}

/// Requests per second and latency quantiles of `path` with `clients` keep-alive clients.
pub(super) fn load(
    addr: &str,
    path: &str,
    clients: usize,
    seconds: f64,
) -> anyhow::Result<(f64, f64, f64)> {
    let t0 = Instant::now();
    let budget = Duration::from_secs_f64(seconds);
    let lat: Vec<Vec<f64>> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..clients)
            .map(|_| {
                s.spawn(|| -> anyhow::Result<Vec<f64>> {
                    let mut c = KeepAlive::connect(addr)?;
                    let mut out = Vec::new();
                    while t0.elapsed() < budget {
                        let t = Instant::now();
                        let status = c.get(path)?;
                        anyhow::ensure!(status == 200, "{path} answered {status}");
                        out.push(t.elapsed().as_secs_f64());
                    }
                    Ok(out)
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().map_err(|_| anyhow!("a load client panicked"))?)
            .collect::<anyhow::Result<Vec<_>>>()
    })?;
    let wall = t0.elapsed().as_secs_f64();
    let mut all: Vec<f64> = lat.into_iter().flatten().collect();
    all.sort_by(f64::total_cmp);
    anyhow::ensure!(!all.is_empty(), "no request finished");
    let q = |p: f64| all[((all.len() - 1) as f64 * p).round() as usize];
    Ok((all.len() as f64 / wall, q(0.5), q(0.99)))
}

/// The admin token of the server the benchmark starts.
pub(crate) const BENCH_TOKEN: &str = "rally-bench-admin";

pub(crate) fn call_json(
    addr: &str,
    method: &str,
    path: &str,
    body: &str,
) -> anyhow::Result<serde_json::Value> {
    Ok(serde_json::from_str(&call(addr, method, path, body)?)?)
}

/// One request with the admin token on a fresh connection (closed after it); the answer's body.
fn call(addr: &str, method: &str, path: &str, body: &str) -> anyhow::Result<String> {
    use std::io::{Read, Write};
    let mut s = std::net::TcpStream::connect(addr)?;
    write!(
        s,
        "{method} {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\nAuthorization: Bearer {BENCH_TOKEN}\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    )?;
    let mut resp = String::new();
    s.read_to_string(&mut resp)?;
    Ok(resp
        .split_once("\r\n\r\n")
        .map(|x| x.1)
        .unwrap_or("")
        .to_string())
}

pub(super) fn proc_status_kib(pid: u32, key: &str) -> Option<f64> {
    let text = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = text.lines().find(|l| l.starts_with(key))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// A sample's value in the server's metrics.
fn metric(addr: &str, name: &str) -> anyhow::Result<f64> {
    let text = call(addr, "GET", "/api/v1/metrics", "")?;
    text.lines()
        .find_map(|l| l.strip_prefix(name)?.strip_prefix(' ')?.trim().parse().ok())
        .ok_or_else(|| anyhow!("no metric {name} in the server's answer"))
}

/// A `rally serve` of this binary on SQLite file `db` (2 workers, no continuous mode), with the
/// settings `toml` changes; returns it and its address.
fn start_server(db: &std::path::Path, toml: &str) -> anyhow::Result<(std::process::Child, String)> {
    use std::io::BufRead;
    let config = db.with_extension("toml");
    std::fs::write(&config, toml)?;
    let mut child = Command::new(std::env::current_exe()?)
        .args([
            "serve",
            "--addr",
            "127.0.0.1:0",
            "--workers",
            "2",
            "--no-continuous",
        ])
        .arg("--config")
        .arg(&config)
        .arg("--db")
        .arg(db)
        // The default robot alone, whatever the machine has imported.
        .env(
            "RALLY_DATA_DIR",
            db.parent().unwrap_or(std::path::Path::new(".")),
        )
        .env("RUST_LOG", "warn")
        .env("RALLY_ADMIN_TOKEN", BENCH_TOKEN)
        .stdout(std::process::Stdio::piped())
        .spawn()
        .context("starting rally serve")?;
    let mut line = String::new();
    let read = child
        .stdout
        .take()
        .context("stdout")
        .and_then(|out| Ok(std::io::BufReader::new(out).read_line(&mut line)?));
    let addr = line
        .trim()
        .strip_prefix("listening on http://")
        .map(str::to_string);
    match (read, addr) {
        (Ok(_), Some(addr)) => Ok((child, addr)),
        (read, _) => {
            let _ = child.kill();
            let _ = child.wait();
            read?;
            Err(anyhow!("unexpected first line {line:?}"))
        }
    }
}

/// Plays 12 matches of 20 rallies among `agents` (by name) on 2 workers; returns the matches per
/// hour and the server's mean setup time of a match (claim to first frame), s.
fn matches_per_hour(addr: &str, agents: [&str; 3]) -> anyhow::Result<(f64, f64)> {
    let (setups0, sum0) = (
        metric(addr, "rally_match_setup_seconds_count")?,
        metric(addr, "rally_match_setup_seconds_sum")?,
    );
    let t0 = Instant::now();
    let mut ids = Vec::new();
    for k in 0..12 {
        let q = wire::QueueMatch {
            a: agents[k % 3].into(),
            b: agents[(k + 1) % 3].into(),
            rallies: 20,
            seed: Some(k as u64),
        };
        let answer = call_json(addr, "POST", "/api/v1/matches", &serde_json::to_string(&q)?)?;
        let m: wire::Match = serde_json::from_value(answer.clone())
            .map_err(|e| anyhow!("queueing failed ({e}): {answer}"))?;
        ids.push(m.id);
    }
    loop {
        // One request a poll: the workers share the machine with this loop.
        let list: wire::MatchList =
            serde_json::from_value(call_json(addr, "GET", "/api/v1/matches?limit=1000", "")?)?;
        let ours: Vec<&wire::Match> = list
            .matches
            .iter()
            .filter(|m| ids.contains(&m.id))
            .collect();
        if let Some(m) = ours.iter().find(|m| m.status == wire::MatchStatus::Failed) {
            return Err(anyhow!("benchmark match {} failed: {:?}", m.id, m.error));
        }
        if ours.len() == ids.len() && ours.iter().all(|m| m.status == wire::MatchStatus::Done) {
            break;
        }
        anyhow::ensure!(
            t0.elapsed() < Duration::from_secs(600),
            "matches did not finish in 10 minutes"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let per_hour = ids.len() as f64 / t0.elapsed().as_secs_f64() * 3600.0;
    let setups = metric(addr, "rally_match_setup_seconds_count")? - setups0;
    let setup = (metric(addr, "rally_match_setup_seconds_sum")? - sum0) / setups.max(1.0);
    Ok((per_hour, setup))
}

/// The trained built-ins the checkpoint phases play with.
const CHECKPOINT_AGENTS: [&str; 3] = ["kmac", "muscle-ppo", "dynsyn"];

/// `rally bench server`: a real server (this binary, `serve`, fresh database, 2 workers, no
/// continuous mode) measured from outside: matches per hour — the scripted built-ins', then the
/// trained checkpoints' with every match building its players (`player_cache = 0`) and with the
/// workers' cache, on one store — then leaderboard and health-check throughput and latency while two
/// long matches run, then the server's peak memory.
pub fn server_bench(seconds: f64, clients: usize) -> anyhow::Result<serde_json::Value> {
    let dir = std::env::temp_dir().join(format!("rally-bench-server-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir)?;
    let db = dir.join("bench.db");
    let result = (|| -> anyhow::Result<serde_json::Value> {
        // Without the cache first (its start qualifies the built-ins into the store).
        let (mut child, addr) = start_server(&db, "player_cache = 0\n")?;
        let uncached = matches_per_hour(&addr, CHECKPOINT_AGENTS);
        let _ = child.kill();
        let _ = child.wait();
        let uncached = uncached?;
        let (mut child, addr) = start_server(&db, "")?;
        let r = (|| -> anyhow::Result<serde_json::Value> {
            let cached = matches_per_hour(&addr, CHECKPOINT_AGENTS)?;
            let loads = metric(&addr, "rally_player_loads_total")?;
            let scripted =
                matches_per_hour(&addr, ["scripted", "scripted-drive", "scripted-soft"])?;
            // Two long matches keep both workers busy during the load.
            let mut long = Vec::new();
            for (a, b) in [(1, 2), (3, 1)] {
                let m = call_json(
                    &addr,
                    "POST",
                    "/api/v1/matches",
                    &format!("{{\"a\":{a},\"b\":{b},\"rallies\":1000,\"seed\":99}}"),
                )?;
                long.push(m["id"].as_i64().unwrap_or(0));
            }
            std::thread::sleep(Duration::from_millis(300));
            let running = call_json(&addr, "GET", "/api/v1/matches?status=running", "")?;
            let running = running["matches"].as_array().map_or(0, |m| m.len());
            let board = load(&addr, "/api/v1/leaderboard", clients, seconds)?;
            let health = load(&addr, "/api/v1/healthz", clients, seconds)?;
            for id in long {
                let _ = call_json(&addr, "DELETE", &format!("/api/v1/matches/{id}"), "");
            }
            let pid = child.id();
            Ok(json!({
                "target": "server",
                "workers": 2,
                "clients": clients,
                "matches_per_hour_20_rallies": scripted.0,
                "checkpoints": {
                    "agents": CHECKPOINT_AGENTS,
                    "uncached": {"matches_per_hour": uncached.0, "setup_ms": uncached.1 * 1e3},
                    "cached": {"matches_per_hour": cached.0, "setup_ms": cached.1 * 1e3},
                    "player_loads": loads,
                },
                "matches_running_during_load": running,
                "leaderboard": {"requests_per_second": board.0, "p50_ms": board.1 * 1e3, "p99_ms": board.2 * 1e3},
                "healthz": {"requests_per_second": health.0, "p50_ms": health.1 * 1e3, "p99_ms": health.2 * 1e3},
                "leaderboard_vs_healthz_throughput": board.0 / health.0,
                "server_peak_rss_mib": proc_status_kib(pid, "VmHWM:").map(|k| k / 1024.0),
                "server_rss_mib": proc_status_kib(pid, "VmRSS:").map(|k| k / 1024.0),
            }))
        })();
        let _ = child.kill();
        let _ = child.wait();
        r
    })();
    let _ = std::fs::remove_dir_all(&dir);
    result
}
