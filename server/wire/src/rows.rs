//! The store's rows as the API shows them: an agent, a match, its rallies, a tournament, an SPRT, an
//! agent's drift, crossings and rating history, a worker. The server's store decodes its rows into
//! these by column name; clients read them from the JSON answers.

use schemars::JsonSchema;
use serde::{Deserialize, Deserializer, Serialize};

use crate::{AgentKind, MatchStatus, SprtStatus, TournamentKind, WorkerStatus};

/// The robot of rows from a server older than robots of their own.
fn default_robot() -> String {
    "default".into()
}

/// A yes/no the store may keep as 0/1 (SQLite has no boolean): true/false or an integer.
fn flag<'de, D: Deserializer<'de>>(d: D) -> Result<bool, D::Error> {
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Flag {
        Bool(bool),
        Int(i64),
    }
    Ok(match Flag::deserialize(d)? {
        Flag::Bool(b) => b,
        Flag::Int(i) => i != 0,
    })
}

/// An agent row.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Agent {
    /// Id.
    pub id: i64,
    /// Unique name.
    pub name: String,
    /// What it is.
    pub kind: AgentKind,
    /// The robot it plays (`default`, `myochallenge`): it meets only agents of the same robot.
    #[serde(default = "default_robot")]
    pub model: String,
    /// Hash of its spec.
    pub spec_hash: String,
    /// Registered by the server itself.
    #[serde(deserialize_with = "flag")]
    pub builtin: bool,
    /// When registered.
    pub created_at: String,
    /// Qualification episodes played.
    pub qual_episodes: Option<i64>,
    /// Qualification hit rate.
    pub hit_rate: Option<f64>,
    /// Qualification success rate.
    pub success_rate: Option<f64>,
    /// Qualification effort.
    pub effort: Option<f64>,
    /// When its owner or the admin retired it (UTC); none while it plays.
    #[serde(default)]
    pub retired_at: Option<String>,
}

/// A match row.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Match {
    /// Id.
    pub id: i64,
    /// Agent on side A.
    pub agent_a: i64,
    /// Agent on side B.
    pub agent_b: i64,
    /// Rallies.
    pub rallies: i64,
    /// Seed.
    pub seed: i64,
    /// The robot both sides play (`default`, `myochallenge`).
    #[serde(default = "default_robot")]
    pub model: String,
    /// Arena preset.
    pub preset: String,
    /// Simulator version.
    pub sim_version: String,
    /// Played (or queued) under another simulator version than this server's: its result stands,
    /// but it cannot be re-simulated or played here.
    #[serde(deserialize_with = "flag")]
    pub outdated: bool,
    /// Hash of A's spec when queued.
    pub spec_hash_a: String,
    /// Hash of B's spec when queued.
    pub spec_hash_b: String,
    /// Replay frames are stored (else its rallies are re-simulated when watched: continuous-mode,
    /// tournament and SPRT matches, and those past their submitter's replay quota).
    #[serde(deserialize_with = "flag")]
    pub keep_replay: bool,
    /// The stored replay frames, bytes (compressed): what the match counts against its submitter's
    /// replay quota.
    pub replay_bytes: i64,
    /// Where it is in its life.
    pub status: MatchStatus,
    /// When queued.
    pub created_at: String,
    /// When a worker took it.
    pub started_at: Option<String>,
    /// When it finished.
    pub finished_at: Option<String>,
    /// Points of A.
    pub points_a: Option<i64>,
    /// Points of B.
    pub points_b: Option<i64>,
    /// Mean rally length.
    pub mean_rally_length: Option<f64>,
    /// Longest rally.
    pub max_rally_length: Option<i64>,
    /// Fraction of crossings in the serve box.
    pub in_box_fraction: Option<f64>,
    /// Serve → return energy distance.
    pub energy_distance: Option<f64>,
    /// Drift slope.
    pub drift_slope: Option<f64>,
    /// Why it failed.
    pub error: Option<String>,
    /// The tournament it belongs to.
    pub tournament_id: Option<i64>,
    /// The SPRT it belongs to.
    pub sprt_id: Option<i64>,
    /// The submitter token that queued it (null: the admin or the server).
    pub created_by: Option<i64>,
    /// The worker that holds its lease (running) or played it (done, failed).
    pub worker: Option<String>,
    /// How many times a worker claimed it (more than once: a worker died or lost its lease).
    pub attempts: i64,
}

/// A stored rally.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Rally {
    /// Index in the match.
    pub idx: i64,
    /// Who served.
    pub server: String,
    /// Legal returns.
    pub length: i64,
    /// End reason.
    pub end_reason: String,
    /// Who failed.
    pub failing_side: Option<String>,
    /// Simulated duration, s.
    pub duration: f64,
}

/// A tournament row.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Tournament {
    /// Id.
    pub id: i64,
    /// Round robin or gauntlet.
    pub kind: TournamentKind,
    /// Agent ids (JSON array) in the order given.
    pub agents_json: String,
    /// Rallies per match.
    pub rallies_per_match: i64,
    /// Rounds.
    pub rounds: i64,
    /// Seed of its first match (the k-th gets seed + k).
    pub seed: i64,
    /// The submitter token that created it (null: the admin).
    pub created_by: Option<i64>,
    /// When created.
    pub created_at: String,
}

/// An SPRT row.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Sprt {
    /// Id.
    pub id: i64,
    /// The agent tested.
    pub agent_a: i64,
    /// Its opponent.
    pub agent_b: i64,
    /// H0: A's Elo advantage on points is elo0.
    pub elo0: f64,
    /// H1: it is elo1.
    pub elo1: f64,
    /// False-positive rate.
    pub alpha: f64,
    /// False-negative rate.
    pub beta: f64,
    /// Rallies per match.
    pub rallies_per_match: i64,
    /// Matches after which it stops undecided.
    pub max_matches: i64,
    /// Seed of the first match (the k-th gets seed + k).
    pub seed: i64,
    /// Where it is in its life.
    pub status: SprtStatus,
    /// Log-likelihood ratio after the finished matches.
    pub llr: f64,
    /// Finished matches.
    pub matches_done: i64,
    /// The submitter token that created it (null: the admin).
    pub created_by: Option<i64>,
    /// When created.
    pub created_at: String,
    /// When it ended.
    pub finished_at: Option<String>,
}

/// An agent's drift over its finished matches (its side's serves and returns, `match_drift`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct AgentDrift {
    /// Matches with drift statistics.
    pub matches: i64,
    /// Crossings counted over them.
    pub crossings: i64,
    /// Fraction of those crossings inside the serve box (pooled over matches).
    pub in_box_fraction: Option<f64>,
    /// Mean serve → return energy distance (matches that have one).
    pub energy_distance: Option<f64>,
    /// Mean drift slope over exchange index (matches that have one).
    pub drift_slope: Option<f64>,
}

/// A crossing of the hitting plane that an agent is answerable for.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct AgentCrossing {
    /// The match.
    pub match_id: i64,
    /// The rally in it.
    pub rally: i64,
    /// 0 for a serve, k for the k-th return of the rally.
    pub exchange: i64,
    /// Lateral coordinate in the receiver's frame, m.
    pub y_r: f64,
    /// Height, m.
    pub z: f64,
    /// Inside the serve box.
    #[serde(deserialize_with = "flag")]
    pub in_box: bool,
    /// Extrapolated (the receiver hit before the plane).
    #[serde(deserialize_with = "flag")]
    pub extrapolated: bool,
}

/// One point of an agent's rating history.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct RatingPoint {
    /// Order in which matches finished (server-wide).
    pub seq: i64,
    /// The match after which it was computed.
    pub match_id: i64,
    /// Glicko-2 rating.
    pub rating: f64,
    /// Its deviation.
    pub deviation: f64,
    /// Its volatility.
    pub volatility: f64,
    /// When.
    pub created_at: String,
}

/// A worker as `GET /api/v1/workers` shows it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Worker {
    /// Its name (unique; `HOST:PID` unless given).
    pub name: String,
    /// The machine it runs on.
    pub host: String,
    /// Its process id there.
    pub pid: i64,
    /// Matches it plays at once.
    pub slots: i64,
    /// When it started, Unix ms.
    pub started_ms: i64,
    /// Its last heartbeat, Unix ms.
    pub heartbeat_ms: i64,
    /// Matches it stored.
    pub matches_played: i64,
    /// Running, or stopped by itself (after SIGTERM); a worker that died stays running with an old
    /// heartbeat.
    pub status: WorkerStatus,
}
