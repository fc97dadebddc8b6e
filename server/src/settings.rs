//! The server's settings (`config/default.toml`), their defaults and checks.

use std::net::SocketAddr;
use std::path::PathBuf;

use serde::Deserialize;

use crate::db;

/// The default settings file, `config/default.toml`.
pub const DEFAULT_SETTINGS_TOML: &str = include_str!("../../config/default.toml");

/// Server settings. Every one has its default in `config/default.toml` (compiled in), the one place
/// they are defined: a settings file names only what it changes.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Settings {
    /// Listen address.
    pub addr: SocketAddr,
    /// The store: an SQLite file (created if missing) or a `postgres://` URL (db::Location).
    pub db: db::Location,
    /// Match workers (each a blocking thread).
    pub workers: usize,
    /// When the queue is empty, keep queuing matches: the agent whose rating is least certain against
    /// the opponent it has met least, and every `continuous_self_play_every`-th a cooperative one.
    pub continuous: bool,
    /// Rallies per match scheduled by the continuous mode.
    pub continuous_rallies: u32,
    /// Least time between two matches queued by the continuous mode, s.
    pub continuous_pause_s: f64,
    /// Every this many matches, continuous mode queues a cooperative one: an agent against itself
    /// (it rates nothing; it fills the rally-length and drift statistics, which a strong agent's
    /// matches against weak ones leave short). 0: never.
    pub continuous_self_play_every: u32,
    /// Most rallies a requested match may have.
    pub max_rallies: u32,
    /// Qualification episodes run for a submitted agent.
    pub qualification_episodes: usize,
    /// Least share of the qualification's P2 serves an agent must hit to be admitted.
    pub qualification_min_hit_rate: f64,
    /// Largest share of the qualification's episodes in which an agent may drop its paddle.
    pub qualification_max_dropped: f64,
    /// CPU time a submitted checkpoint's admission (validation, its network built — tract optimises
    /// an ONNX graph — and the qualification episodes) may use, s, all threads together: past it
    /// its process is stopped and the submission refused (422 naming this setting).
    pub admission_cpu_s: f64,
    /// Memory a submitted checkpoint's admission process may allocate, MiB: past it its
    /// allocations fail and the submission is refused (422 naming this setting).
    pub admission_memory_mb: u64,
    /// Submissions that may wait for their admission at once (one is admitted at a time); past
    /// it, 503 with `Retry-After`.
    pub admission_queue: usize,
    /// Largest request body, bytes.
    pub max_body_bytes: usize,
    /// Admin token (the `RALLY_ADMIN_TOKEN` environment variable overrides it); empty disables
    /// submissions.
    pub admin_token: String,
    /// Matches a submitter token may queue per minute (plain matches, tournaments' and SPRTs'
    /// first ones); the admin token is not limited.
    pub max_matches_per_minute: u32,
    /// Most matches one tournament may queue.
    pub max_tournament_matches: u32,
    /// Replay frames a submitter token's matches may keep, MiB (compressed): past it a match it
    /// asked for keeps none, and its rallies are re-simulated when watched.
    pub replay_quota_mb: f64,
    /// Rallies a submitter token may ask for per hour: a match's, all of a tournament's matches',
    /// the most an SPRT may play (its `max_matches` times its rallies per match).
    pub max_rallies_per_hour: u32,
    /// Agents a submitter token may submit per hour (each one is qualified on
    /// `qualification_episodes` episodes); the admin token is not limited.
    pub max_agents_per_hour: u32,
    /// The checkpoints registered as built-in agents on start, qualified like submissions:
    /// [`EMBEDDED_BUILTINS`] (the default) for those compiled into the binary, whatever directory
    /// it starts in; else a directory of `NAME.json` files; empty: none. One that does not load is
    /// skipped with a warning.
    pub builtin_checkpoints: PathBuf,
    /// How long a running match's lease lasts without a heartbeat, s: a worker that died or lost
    /// the database loses its matches after this long (they are queued again). Heartbeats come
    /// every quarter of it.
    pub lease_s: f64,
    /// HTTP connections open at once; more wait in the kernel's backlog.
    pub max_connections: usize,
    /// How long a client may take to send a request's headers, s (also the longest a keep-alive
    /// connection waits idle for its next request): past it, the connection is closed.
    pub header_read_timeout_s: f64,
    /// How long a shutdown (SIGTERM, Ctrl-C) waits for open HTTP connections (live streams, slow
    /// clients) before closing them, s. Running matches are finished and stored either way.
    pub shutdown_deadline_s: f64,
    /// The reference agent the rating scale is anchored to (its name): its rating is held at
    /// `rating_anchor_value`, so agents that play on unchanged do not move when others join.
    pub rating_anchor: String,
    /// The rating the reference agent is held at.
    pub rating_anchor_value: f64,
    /// An agent whose 95% rating interval is wider than this (Elo points) is provisional, listed
    /// after the established agents; continuous mode pairs it with established ones first.
    pub provisional_interval: f64,
    /// Agents whose built players (a checkpoint parsed, validated, its network built) a process
    /// keeps for its next matches, the least recently used leaving first; 0: none kept.
    pub player_cache: usize,
    /// This process's worker name in the `workers` table and the matches it plays; empty:
    /// `HOST:PID`.
    pub worker_name: String,
}

impl Settings {
    /// The lease of a claimed match, ms.
    pub fn lease_ms(&self) -> i64 {
        (self.lease_s * 1000.0).round() as i64
    }

    /// This process's worker name (`worker_name`, or `HOST:PID`).
    pub fn worker(&self) -> String {
        if self.worker_name.is_empty() {
            format!("{}:{}", hostname(), std::process::id())
        } else {
            self.worker_name.clone()
        }
    }
}

/// Where rally keeps what it makes and imports — the default store (`rally.db`), the imported
/// MyoChallenge model (`models/`) and the Python environment that imported it — whatever directory a
/// command starts in: `$RALLY_DATA_DIR`, else the user's data directory (on Linux
/// `$XDG_DATA_HOME/muscle-rally`, by default `~/.local/share/muscle-rally`).
pub fn data_dir() -> PathBuf {
    match std::env::var_os("RALLY_DATA_DIR").filter(|d| !d.is_empty()) {
        Some(dir) => PathBuf::from(dir),
        None => dirs::data_dir()
            .map(|d| d.join("muscle-rally"))
            .unwrap_or_else(|| PathBuf::from("data")),
    }
}

/// This machine's name (Linux: the kernel's; else `HOSTNAME`, else "localhost").
pub fn hostname() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .map(|h| h.trim().to_string())
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "localhost".into())
}

/// `builtin_checkpoints = "embedded"`: the checkpoints compiled into the binary
/// ([`agents::builtins`]).
pub const EMBEDDED_BUILTINS: &str = "embedded";

impl Settings {
    /// Parses settings: `text`'s over the defaults of `config/default.toml`, naming the field that
    /// is wrong (an unknown one included).
    pub fn from_toml(text: &str) -> Result<Settings, String> {
        let mut merged: toml::Table = DEFAULT_SETTINGS_TOML
            .parse()
            .map_err(|e| format!("the built-in config/default.toml: {e}"))?;
        let given: toml::Table = text.parse().map_err(|e: toml::de::Error| e.to_string())?;
        merged.extend(given);
        if !merged.contains_key("db") {
            let store = data_dir().join("rally.db").display().to_string();
            merged.insert("db".into(), toml::Value::String(store));
        }
        let s: Settings = toml::Value::Table(merged)
            .try_into()
            .map_err(|e: toml::de::Error| e.to_string())?;
        if s.workers > 64 {
            return Err("workers must be between 0 (serve the API alone) and 64".into());
        }
        if !(s.lease_s.is_finite() && s.lease_s >= 1.0) {
            return Err("lease_s must be at least 1 second".into());
        }
        if s.max_connections == 0 {
            return Err("max_connections must be positive".into());
        }
        for (name, v) in [
            ("header_read_timeout_s", s.header_read_timeout_s),
            ("shutdown_deadline_s", s.shutdown_deadline_s),
            ("admission_cpu_s", s.admission_cpu_s),
        ] {
            if !(v.is_finite() && v > 0.0 && v <= 86_400.0) {
                return Err(format!(
                    "{name} must be a positive number of seconds (at most a day)"
                ));
            }
        }
        if s.max_rallies == 0 || s.continuous_rallies == 0 || s.continuous_rallies > s.max_rallies {
            return Err("max_rallies and continuous_rallies must be positive, continuous_rallies ≤ max_rallies".into());
        }
        if !(s.continuous_pause_s.is_finite() && s.continuous_pause_s >= 0.0) {
            return Err("continuous_pause_s must be a non-negative number of seconds".into());
        }
        if !(s.replay_quota_mb.is_finite() && s.replay_quota_mb >= 0.0) {
            return Err("replay_quota_mb must be a non-negative number of MiB".into());
        }
        if s.max_rallies_per_hour == 0 {
            return Err("max_rallies_per_hour must be positive".into());
        }
        if !(64..=1 << 30).contains(&s.admission_memory_mb) {
            return Err("admission_memory_mb must be between 64 and 2^30 MiB".into());
        }
        if s.admission_queue == 0 {
            return Err("admission_queue must be positive".into());
        }
        if s.max_matches_per_minute == 0 {
            return Err("max_matches_per_minute must be positive".into());
        }
        if s.max_agents_per_hour == 0 {
            return Err("max_agents_per_hour must be positive".into());
        }
        if s.max_tournament_matches == 0 {
            return Err("max_tournament_matches must be positive".into());
        }
        if s.qualification_episodes == 0 || s.qualification_episodes > 10_000 {
            return Err("qualification_episodes must be between 1 and 10000".into());
        }
        for (name, v) in [
            ("qualification_min_hit_rate", s.qualification_min_hit_rate),
            ("qualification_max_dropped", s.qualification_max_dropped),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(format!("{name} must be a share, from 0 to 1"));
            }
        }
        Ok(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_settings_file_names_only_what_it_changes() {
        let defaults = Settings::from_toml("").unwrap();
        assert_eq!(defaults.qualification_episodes, 100);
        assert_eq!(
            defaults.builtin_checkpoints,
            PathBuf::from(EMBEDDED_BUILTINS)
        );
        let s = Settings::from_toml("workers = 3\nlease_s = 8.0\n").unwrap();
        assert_eq!((s.workers, s.lease_s), (3, 8.0));
        assert_eq!(s.max_connections, defaults.max_connections);
        assert_eq!(
            s.qualification_min_hit_rate,
            defaults.qualification_min_hit_rate
        );
        let e = Settings::from_toml("wrokers = 3\n").unwrap_err();
        assert!(e.contains("wrokers"), "{e}");
        let e = Settings::from_toml("workers = \"many\"\n").unwrap_err();
        assert!(e.contains("workers"), "{e}");
        let e = Settings::from_toml("qualification_min_hit_rate = 2.0\n").unwrap_err();
        assert!(e.contains("qualification_min_hit_rate"), "{e}");
    }
}
