//! What the server's integration tests share: a `rally serve` child process on a loopback port with
//! a real store, raw HTTP/1.1 requests, polling and event streams.
//!
//! The store is an SQLite file in the test's directory, or — when `RALLY_TEST_POSTGRES` holds the
//! URL of a PostgreSQL server's admin database (`.ci/run` sets it for a second pass) — a fresh
//! PostgreSQL database per test directory: every test that runs the server runs on both engines.
#![allow(dead_code)] // each test file uses its own part

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use serde_json::Value;

pub const TOKEN: &str = "test-admin-token";

pub struct Server {
    pub child: Child,
    pub addr: String,
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A test's directory under the system's temporary directory (its store, its server's log, the files it
/// sends): removed when the test passes, kept when it fails, for a look at what the server wrote.
pub struct TestDir(PathBuf);

impl std::ops::Deref for TestDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for TestDir {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl Drop for TestDir {
    fn drop(&mut self) {
        if std::thread::panicking() {
            eprintln!("the failed test's directory is kept: {}", self.0.display());
        } else {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

pub fn tempdir(tag: &str) -> TestDir {
    let d = std::env::temp_dir().join(format!("rally-server-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    if let Some(admin) = postgres_admin() {
        let name: String = format!("rally_{tag}_{}", std::process::id())
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() {
                    c.to_ascii_lowercase()
                } else {
                    '_'
                }
            })
            .collect();
        let url = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap()
            .block_on(server::db::recreate_postgres_database(&admin, &name))
            .unwrap_or_else(|e| panic!("a PostgreSQL database for {tag} on {admin}: {e}"));
        std::fs::write(d.join("db.url"), url).unwrap();
    }
    TestDir(d)
}

/// The PostgreSQL admin URL the tests run on (`RALLY_TEST_POSTGRES`), if any.
pub fn postgres_admin() -> Option<String> {
    std::env::var("RALLY_TEST_POSTGRES")
        .ok()
        .filter(|u| !u.is_empty())
}

/// The store of the tests in `dir`: its PostgreSQL database's URL, or the SQLite file `dir/rally.db`.
pub fn db(dir: &Path) -> String {
    std::fs::read_to_string(dir.join("db.url"))
        .unwrap_or_else(|_| dir.join("rally.db").display().to_string())
}

pub fn start(dir: &Path, continuous: bool) -> Server {
    start_with(dir, continuous, "")
}

/// Starts `rally serve` with `extra` lines appended to the test configuration.
pub fn start_with(dir: &Path, continuous: bool, extra: &str) -> Server {
    // Continuous mode runs two workers: concurrent claims and stores on one SQLite file.
    start_serve(dir, if continuous { 2 } else { 1 }, continuous, extra)
}

/// Writes the test configuration (`workers` match workers in the server, leases of 4 s) to
/// `dir/server.toml` and returns its path. A setting in `extra` replaces the test default of the
/// same name.
pub fn write_config(dir: &Path, workers: usize, continuous: bool, extra: &str) -> PathBuf {
    let config = dir.join("server.toml");
    let defaults = [
        ("addr", "\"127.0.0.1:0\"".to_string()),
        ("db", format!("\"{}\"", db(dir))),
        ("workers", workers.to_string()),
        ("continuous", continuous.to_string()),
        ("continuous_rallies", "4".into()),
        ("continuous_pause_s", "0.0".into()),
        ("max_rallies", "1000".into()),
        ("qualification_episodes", "6".into()),
        // The tests submit untrained templates: no admission thresholds unless a test sets them.
        ("qualification_min_hit_rate", "0.0".into()),
        ("qualification_max_dropped", "1.0".into()),
        ("max_body_bytes", "65536".into()),
        ("admin_token", "\"\"".into()),
        ("lease_s", "4.0".into()),
    ];
    let given: Vec<&str> = extra
        .lines()
        .filter_map(|l| l.split('=').next())
        .map(str::trim)
        .collect();
    let mut text = String::new();
    for (key, value) in defaults {
        if !given.contains(&key) {
            text.push_str(&format!("{key} = {value}\n"));
        }
    }
    text.push_str(extra);
    std::fs::write(&config, text).unwrap();
    config
}

/// Starts `rally serve` with `workers` match workers of its own (0: the API alone).
pub fn start_serve(dir: &Path, workers: usize, continuous: bool, extra: &str) -> Server {
    let config = write_config(dir, workers, continuous, extra);
    // From the test's own directory, not the checkout: the server needs nothing from where it starts.
    let mut child = Command::new(env!("CARGO_BIN_EXE_rally"))
        .current_dir(dir)
        .args(["serve", "--config"])
        .arg(&config)
        // The robots it plays are those imported under the test's directory (none: the default
        // robot alone), whatever the machine's own data directory holds.
        .env("RALLY_DATA_DIR", dir)
        .env("RALLY_ADMIN_TOKEN", TOKEN)
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("rally serve starts");
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let addr = line
        .trim()
        .strip_prefix("listening on http://")
        .unwrap_or_else(|| panic!("unexpected first line {line:?}"))
        .to_string();
    Server { child, addr }
}

/// A `rally worker` process named `name` on the database of `dir/server.toml`, once it says it is
/// ready; killed when dropped.
pub fn start_worker(dir: &Path, name: &str) -> Server {
    start_worker_with_data(dir, name, dir)
}

/// [`start_worker`] with the data directory `data` (the robots it has imported).
pub fn start_worker_with_data(dir: &Path, name: &str, data: &Path) -> Server {
    let mut child = Command::new(env!("CARGO_BIN_EXE_rally"))
        .args(["worker", "--config"])
        .arg(dir.join("server.toml"))
        .args(["--db", &db(dir)])
        .args(["--name", name])
        .env("RALLY_DATA_DIR", data)
        .env("RUST_LOG", "warn")
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("rally worker starts");
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    assert_eq!(line.trim(), format!("worker {name} ready"));
    Server {
        child,
        addr: name.to_string(),
    }
}

/// One HTTP/1.1 request (Connection: close); returns (status, body).
pub fn raw(
    addr: &str,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &[u8],
) -> (u16, Vec<u8>) {
    let (status, _, body) = raw_full(addr, method, path, headers, body);
    (status, body)
}

/// [`raw`] with the response's header block too.
pub fn raw_full(
    addr: &str,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &[u8],
) -> (u16, String, Vec<u8>) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(120))).unwrap();
    let mut req = format!(
        "{method} {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\nContent-Length: {}\r\n",
        body.len()
    );
    for (k, v) in headers {
        req.push_str(&format!("{k}: {v}\r\n"));
    }
    req.push_str("\r\n");
    s.write_all(req.as_bytes()).unwrap();
    s.write_all(body).unwrap();
    let mut resp = Vec::new();
    let _ = s.read_to_end(&mut resp);
    let split = resp
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .expect("a header block");
    let head = String::from_utf8_lossy(&resp[..split]).to_string();
    let mut body = resp[split + 4..].to_vec();
    let status: u16 = head.split_whitespace().nth(1).unwrap().parse().unwrap();
    if head
        .to_ascii_lowercase()
        .contains("transfer-encoding: chunked")
    {
        let mut out = Vec::new();
        let mut rest = &body[..];
        loop {
            let nl = rest.windows(2).position(|w| w == b"\r\n").unwrap();
            let n = usize::from_str_radix(std::str::from_utf8(&rest[..nl]).unwrap().trim(), 16)
                .unwrap();
            if n == 0 {
                break;
            }
            out.extend_from_slice(&rest[nl + 2..nl + 2 + n]);
            rest = &rest[nl + 2 + n + 2..];
        }
        body = out;
    }
    (status, head, body)
}

pub fn call(
    addr: &str,
    method: &str,
    path: &str,
    body: Option<&Value>,
    token: Option<&str>,
) -> (u16, Value) {
    let auth = token.map(|t| format!("Bearer {t}"));
    let mut headers = vec![];
    if body.is_some() {
        headers.push(("Content-Type", "application/json"));
    }
    if let Some(a) = &auth {
        headers.push(("Authorization", a.as_str()));
    }
    let bytes = body.map(|b| b.to_string().into_bytes()).unwrap_or_default();
    let (status, body) = raw(addr, method, path, &headers, &bytes);
    let v = serde_json::from_slice(&body)
        .unwrap_or_else(|_| Value::String(String::from_utf8_lossy(&body).into()));
    (status, v)
}

pub fn wait_for(addr: &str, id: i64, status: &str, limit: Duration) -> Value {
    let t0 = Instant::now();
    loop {
        let (code, m) = call(addr, "GET", &format!("/api/v1/matches/{id}"), None, None);
        assert_eq!(code, 200, "{m}");
        if m["status"] == status {
            return m;
        }
        assert!(
            !["failed", "cancelled"].contains(&m["status"].as_str().unwrap())
                || m["status"] == status,
            "{m}"
        );
        assert!(
            t0.elapsed() < limit,
            "match {id} still {} after {limit:?}",
            m["status"]
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// A GET that must answer 200 with the body type the server sends (`server::wire`).
pub fn get_as<T: serde::de::DeserializeOwned>(addr: &str, path: &str) -> T {
    let (code, v) = call(addr, "GET", path, None, None);
    assert_eq!(code, 200, "{path}: {v}");
    serde_json::from_value(v.clone()).unwrap_or_else(|e| panic!("{path}: {e}: {v}"))
}

/// A POST of a request type (`server::wire`) that must answer `expect`, read as `T`.
pub fn post_as<B: serde::Serialize, T: serde::de::DeserializeOwned>(
    addr: &str,
    path: &str,
    body: &B,
    token: Option<&str>,
    expect: u16,
) -> T {
    let (code, v) = call(
        addr,
        "POST",
        path,
        Some(&serde_json::to_value(body).unwrap()),
        token,
    );
    assert_eq!(code, expect, "{path}: {v}");
    serde_json::from_value(v.clone()).unwrap_or_else(|e| panic!("{path}: {e}: {v}"))
}

/// Polls `path` (a `T`) until `done` holds.
pub fn poll_as<T: serde::de::DeserializeOwned + std::fmt::Debug>(
    addr: &str,
    path: &str,
    limit: Duration,
    done: impl Fn(&T) -> bool,
) -> T {
    let t0 = Instant::now();
    loop {
        let v: T = get_as(addr, path);
        if done(&v) {
            return v;
        }
        assert!(
            t0.elapsed() < limit,
            "{path} did not get there in {limit:?}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// A DELETE with a bearer token (or none).
pub fn delete(addr: &str, path: &str, token: Option<&str>) -> (u16, Value) {
    call(addr, "DELETE", path, None, token)
}

/// Polls `path` until `done(value)` holds.
pub fn poll(addr: &str, path: &str, limit: Duration, done: impl Fn(&Value) -> bool) -> Value {
    poll_as(addr, path, limit, done)
}

/// Opens a server-sent event stream (a raw HTTP/1.1 GET); its reader past the header block, which is
/// returned too (asserted 200).
pub fn subscribe(addr: &str, path: &str) -> (BufReader<TcpStream>, String) {
    let mut sub = TcpStream::connect(addr).unwrap();
    sub.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
    write!(
        sub,
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nAccept: text/event-stream\r\n\r\n"
    )
    .unwrap();
    let mut reader = BufReader::new(sub);
    let mut head = String::new();
    while reader.read_line(&mut head).unwrap() > 2 && !head.ends_with("\r\n\r\n") {}
    assert!(head.starts_with("HTTP/1.1 200"), "{path}: {head}");
    (reader, head)
}

/// Sends SIGTERM to `p` and waits (at most two minutes) for it to exit; its exit status.
pub fn terminate(p: &mut Server) -> std::process::ExitStatus {
    let term = Command::new("kill")
        .args(["-TERM", &p.child.id().to_string()])
        .status()
        .unwrap();
    assert!(term.success());
    let t0 = Instant::now();
    loop {
        if let Some(s) = p.child.try_wait().unwrap() {
            return s;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "no exit after SIGTERM"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The server process's resident memory, KiB (Linux's `/proc`).
pub fn rss_kib(srv: &Server) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{}/status", srv.child.id())).unwrap();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .expect("VmRSS in /proc/PID/status")
}

/// How long `GET /api/v1/healthz` takes on an idle server: the slowest of ten.
pub fn healthz_idle(addr: &str) -> Duration {
    (0..10)
        .map(|_| {
            let t = Instant::now();
            let (code, _) = raw(addr, "GET", "/api/v1/healthz", &[], b"");
            assert_eq!(code, 200);
            t.elapsed()
        })
        .max()
        .unwrap()
}

/// The longest a busy server's `/healthz` may take, against its idle figure: 20 times it and half a
/// second (a busy 2-core machine shares its cores with the work; a blocked runtime takes seconds).
pub fn responsive_bound(idle: Duration) -> Duration {
    idle * 20 + Duration::from_millis(500)
}

/// Runs `work` while another thread asks `/healthz` every 50 ms; returns what `work` returned and
/// the slowest answer meanwhile (each must be a 200).
pub fn while_probing<T>(addr: &str, work: impl FnOnce() -> T) -> (T, Duration) {
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let probe = {
        let (addr, stop) = (addr.to_string(), stop.clone());
        std::thread::spawn(move || {
            let mut worst = Duration::ZERO;
            while !stop.load(std::sync::atomic::Ordering::SeqCst) {
                let t = Instant::now();
                let (code, _) = raw(&addr, "GET", "/api/v1/healthz", &[], b"");
                assert_eq!(code, 200);
                worst = worst.max(t.elapsed());
                std::thread::sleep(Duration::from_millis(50));
            }
            worst
        })
    };
    let out = work();
    stop.store(true, std::sync::atomic::Ordering::SeqCst);
    (out, probe.join().unwrap())
}
