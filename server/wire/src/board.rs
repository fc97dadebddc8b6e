//! The leaderboard as the API shows it (`GET /leaderboard`).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// One leaderboard row.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
pub struct LeaderboardRow {
    /// 1-based rank by rating.
    pub rank: usize,
    /// Agent id.
    pub agent_id: i64,
    /// Agent name.
    pub agent: String,
    /// Built in.
    pub builtin: bool,
    /// Bradley–Terry rating (Elo scale).
    pub rating: f64,
    /// 95% bootstrap interval (null without a finished match against another agent).
    pub rating_low: Option<f64>,
    /// Upper end.
    pub rating_high: Option<f64>,
    /// Its interval is wider than the server's `provisional_interval` (or it has none): listed after
    /// the established agents, whatever its rating.
    #[serde(default)]
    pub provisional: bool,
    /// Finished rated matches: against another agent (points won and the rating come from these).
    pub matches: usize,
    /// Finished cooperative matches against itself: they rate nothing and count in the rally
    /// lengths and drift only.
    #[serde(default)]
    pub self_play_matches: usize,
    /// Points won / points decided, in percent (null without points).
    pub points_won_pct: Option<f64>,
    /// Mean rally length over its matches' rallies (each rally counts once).
    pub mean_rally_length: Option<f64>,
    /// Longest rally it played.
    pub max_rally_length: Option<i64>,
    /// Fraction of the crossings it is answerable for — the serves and its own returns — inside the
    /// serve box (pooled over its matches' crossings, as its page shows it).
    pub in_box_fraction: Option<f64>,
    /// Energy distance between the serves' crossings and its own returns' (mean over its matches
    /// that have one): how far its returns drift from the serve distribution.
    pub drift: Option<f64>,
    /// Glicko-2 rating (online, one game per match, in the order matches finished).
    pub glicko2: f64,
    /// Its rating deviation.
    pub glicko2_deviation: f64,
    /// Qualification hit rate (checkpoints).
    pub hit_rate: Option<f64>,
    /// Qualification success rate.
    pub success_rate: Option<f64>,
}

/// The leaderboard.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
pub struct Leaderboard {
    /// Finished matches it is computed from.
    pub matches: usize,
    /// The reference agent the scale is anchored to, and its rating (none: the fit's own scale).
    #[serde(default)]
    pub anchor: Option<Anchor>,
    /// Rows, best first.
    pub rows: Vec<LeaderboardRow>,
}

/// The reference agent a rating scale is anchored to.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Anchor {
    /// Its name.
    pub agent: String,
    /// The rating it is held at.
    pub rating: f64,
}
