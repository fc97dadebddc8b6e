//! The API's bodies as types: what a client sends and what the server answers, shared by the
//! server's handlers, `rally batch` and the tests, so that the three cannot drift apart (the OpenAPI
//! document describes the same shapes for everyone else; `page::tests` holds it to the rows).
//!
//! Requests refuse unknown fields. Responses are the store's rows (`Match`, `Agent`, …),
//! flattened where the answer adds to a row.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::{
    Agent, AgentCrossing, AgentDrift, Cell, Match, MatchStatus, Progress, Rally, RatingPoint, Sprt,
    Standing, TournamentKind, Worker,
};

/// An agent in a request: its id or its name.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize, JsonSchema)]
#[serde(untagged)]
pub enum AgentRef {
    /// By id.
    Id(i64),
    /// By name.
    Name(String),
}

impl From<&str> for AgentRef {
    fn from(name: &str) -> AgentRef {
        AgentRef::Name(name.to_string())
    }
}

impl From<i64> for AgentRef {
    fn from(id: i64) -> AgentRef {
        AgentRef::Id(id)
    }
}

/// `POST /matches`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct QueueMatch {
    /// Side A.
    pub a: AgentRef,
    /// Side B.
    pub b: AgentRef,
    /// Rallies to play.
    pub rallies: u32,
    /// Match seed (default: from the clock).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
}

/// `POST /tournaments`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NewTournament {
    /// `round_robin` or `gauntlet`.
    pub kind: TournamentKind,
    /// The agents (a gauntlet's challenger first).
    pub agents: Vec<AgentRef>,
    /// Rallies per match.
    pub rallies_per_match: u32,
    /// Rounds (sides swapped every round).
    #[serde(default = "one")]
    pub rounds: u32,
    /// Seed of match 0 (match k gets seed + k; default: from the clock).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
}

fn one() -> u32 {
    1
}

/// `POST /sprt`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NewSprt {
    /// The agent under test.
    pub a: AgentRef,
    /// The baseline.
    pub b: AgentRef,
    /// H0: A's Elo advantage is `elo0`.
    #[serde(default)]
    pub elo0: f64,
    /// H1: A's Elo advantage is `elo1`.
    #[serde(default = "default_elo1")]
    pub elo1: f64,
    /// False-positive rate.
    #[serde(default = "default_error")]
    pub alpha: f64,
    /// False-negative rate.
    #[serde(default = "default_error")]
    pub beta: f64,
    /// Rallies per match.
    #[serde(default = "default_sprt_rallies")]
    pub rallies_per_match: u32,
    /// Matches at most (then inconclusive).
    #[serde(default = "default_sprt_matches")]
    pub max_matches: u32,
    /// Seed of match 0 (default: from the clock).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
}

impl NewSprt {
    /// An SPRT of `a` against `b` with the server's defaults (H0 0, H1 50 Elo, α = β = 0.05, 20
    /// rallies a match, at most 200 matches, the seed from the clock).
    pub fn new(a: AgentRef, b: AgentRef) -> NewSprt {
        NewSprt {
            a,
            b,
            elo0: 0.0,
            elo1: default_elo1(),
            alpha: default_error(),
            beta: default_error(),
            rallies_per_match: default_sprt_rallies(),
            max_matches: default_sprt_matches(),
            seed: None,
        }
    }
}

fn default_elo1() -> f64 {
    50.0
}

fn default_error() -> f64 {
    0.05
}

fn default_sprt_rallies() -> u32 {
    20
}

fn default_sprt_matches() -> u32 {
    200
}

/// `POST /agents` (JSON; the multipart form has the same two fields).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SubmitAgent {
    /// Unique name.
    pub name: String,
    /// The checkpoint, in the agents' format.
    pub checkpoint: Value,
}

/// `POST /tokens`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct NewToken {
    /// The submitter's name.
    pub name: String,
}

/// Every 4xx and 5xx answer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ErrorBody {
    /// What went wrong.
    pub error: ErrorDetail,
}

/// What went wrong, and where.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ErrorDetail {
    /// Machine-readable code (`bad_request`, `not_found`, `rate_limited`, …).
    pub code: String,
    /// For people.
    pub message: String,
    /// The request field at fault, if one is.
    pub field: Option<String>,
}

/// `GET /healthz`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Health {
    /// `ok`.
    pub status: String,
    /// The simulator version this server plays with.
    pub sim_version: String,
    /// What a submission must reach to be admitted.
    #[serde(default)]
    pub qualification: Option<QualificationRule>,
    /// The robots this server plays, each with a leaderboard of its own (`?model=`).
    #[serde(default)]
    pub models: Vec<String>,
}

/// The admission rule: a submission plays `episodes` P2 serves (seed 0) and must hit at least
/// `min_hit_rate` of them and drop its paddle in at most `max_dropped` of them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct QualificationRule {
    /// Qualification episodes.
    pub episodes: usize,
    /// Least share of serves hit.
    pub min_hit_rate: f64,
    /// Largest share of episodes with the paddle dropped.
    pub max_dropped: f64,
}

/// `GET /agents`.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
pub struct AgentList {
    /// Every agent, by id.
    pub agents: Vec<Agent>,
}

/// `GET /agents/{id}`: the row, its drift, its rally lengths and a trained checkpoint's provenance.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
pub struct AgentDetail {
    /// The row.
    #[serde(flatten)]
    pub row: Agent,
    /// Its drift over its finished matches.
    pub drift: AgentDrift,
    /// How many of its finished matches' rallies had each length (returns), shortest first.
    pub rally_lengths: Vec<RallyCount>,
    /// The `training` record a trained checkpoint carries (provenance, learning curve); none for
    /// the scripted agents and for checkpoints without one.
    pub training: Option<Value>,
}

/// Rallies of one length.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
pub struct RallyCount {
    /// Returns in the rally.
    pub length: i64,
    /// Rallies that long.
    pub rallies: i64,
}

/// `GET /agents/{id}/ratings?limit=`: its Glicko-2 history, one point per finished match: the
/// newest `limit` points (default 1 000, at most 10 000).
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
pub struct RatingHistory {
    /// The agent.
    pub agent_id: i64,
    /// Its name.
    pub agent: String,
    /// `glicko2`.
    pub system: String,
    /// Points in all (the answer has the newest of them).
    pub total: i64,
    /// Oldest first.
    pub history: Vec<RatingPoint>,
}

/// `GET /agents/{id}/crossings`: the crossings of the hitting plane it is answerable for.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
pub struct AgentCrossings {
    /// The agent.
    pub agent_id: i64,
    /// Its name.
    pub agent: String,
    /// The serve box, in the receiver's frame.
    pub serve_box: ServeBox,
    /// How many there are in all (the list stops at `limit`).
    pub total: i64,
    /// Newest match first.
    pub crossings: Vec<AgentCrossing>,
}

/// The serve box at the hitting plane (docs/design.md §7), m.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ServeBox {
    /// |y| at most.
    pub half_width: f64,
    /// Lowest z.
    pub z_low: f64,
    /// Highest z.
    pub z_high: f64,
}

/// `POST /agents` (201): the stored agent and the qualification it passed.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
pub struct Submitted {
    /// The new row.
    pub agent: Agent,
    /// Its qualification on P2 serves.
    pub qualification: Qualification,
}

/// A value with its 95% interval.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Interval {
    /// The value.
    pub value: f64,
    /// Lower end of the interval.
    pub low: f64,
    /// Upper end of the interval.
    pub high: f64,
}

/// A qualification: the submitted agent's evaluation on single P2 serves (the report of `rally eval
/// --json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Qualification {
    /// The agent's name.
    pub agent: String,
    /// Serve kind ("p2").
    pub serve: String,
    /// Evaluation seed.
    pub seed: u64,
    /// Episodes played.
    pub episodes: usize,
    /// Share of the serves hit (Wilson interval).
    pub hit_rate: Interval,
    /// Share of the serves returned into the opponent's court (Wilson interval).
    pub success_rate: Interval,
    /// Effort, ‖a‖₂ / n_a (normal interval).
    pub effort: Interval,
    /// Mean activation, ‖a‖₁ / n_a (normal interval).
    pub mean_activation: Interval,
    /// Mean activation up to and including the first contact.
    #[serde(default)]
    pub activation_to_contact: Option<Interval>,
    /// Mean activation after the first contact.
    #[serde(default)]
    pub activation_after_contact: Option<Interval>,
    /// Share of all control steps played after a first contact.
    #[serde(default)]
    pub after_contact_steps: Option<f64>,
    /// How many episodes ended each way (SUCCESS, the referee's reason, TIME_LIMIT).
    #[schemars(with = "Vec<Vec<Value>>")]
    pub ends: Vec<(String, usize)>,
}

/// `POST /tokens` (201): the token, shown this once.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct IssuedToken {
    /// Token id.
    pub id: i64,
    /// The submitter's name.
    pub name: String,
    /// The bearer token (only its SHA-256 is stored).
    pub token: String,
    /// For people.
    pub note: String,
}

/// `GET /matches`.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
pub struct MatchList {
    /// The page, newest first.
    pub matches: Vec<Match>,
    /// `?before=` this id gets the next page (absent on the last one).
    pub next_before: Option<i64>,
}

/// One side's drift statistics in a match.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
pub struct SideDrift {
    /// `A` or `B`.
    pub side: String,
    /// Its agent.
    pub agent_id: i64,
    /// The statistics (docs/design.md §7).
    pub drift: Value,
}

/// `GET /matches/{id}`: the match row, its rallies and drift.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
pub struct MatchDetail {
    /// The row.
    #[serde(flatten)]
    pub row: Match,
    /// Its rallies, by index.
    pub rally_log: Vec<Rally>,
    /// The match's drift statistics (both sides' returns), once done.
    pub drift: Option<Value>,
    /// Each side's.
    pub drift_by_side: Vec<SideDrift>,
}

/// A match as a tournament or an SPRT lists it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ContestMatch {
    /// Match id.
    pub id: i64,
    /// Side A.
    pub agent_a: i64,
    /// Side B.
    pub agent_b: i64,
    /// Its state.
    pub status: MatchStatus,
    /// A's points, once done.
    pub points_a: Option<i64>,
    /// B's points, once done.
    pub points_b: Option<i64>,
    /// Its seed.
    pub seed: i64,
}

/// A match as an SPRT lists it: with the point share of the SPRT's agent A, once done.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct SprtMatch {
    /// The match.
    #[serde(flatten)]
    pub m: ContestMatch,
    /// A's share of the points.
    pub share_of_a: Option<f64>,
}

impl ContestMatch {
    /// The listed fields of `m`.
    pub fn of(m: &Match) -> ContestMatch {
        ContestMatch {
            id: m.id,
            agent_a: m.agent_a,
            agent_b: m.agent_b,
            status: m.status,
            points_a: m.points_a,
            points_b: m.points_b,
            seed: m.seed,
        }
    }
}

/// An agent's id and name.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct NamedAgent {
    /// Id.
    pub id: i64,
    /// Name.
    pub name: String,
}

/// A tournament as `GET /tournaments` lists it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TournamentSummary {
    /// Id.
    pub id: i64,
    /// `round_robin` or `gauntlet`.
    pub kind: TournamentKind,
    /// Its agents, in the order given.
    pub agents: Vec<NamedAgent>,
    /// Rallies per match.
    pub rallies_per_match: i64,
    /// Rounds.
    pub rounds: i64,
    /// When created.
    pub created_at: String,
    /// Matches by state.
    pub progress: Progress,
}

/// `GET /tournaments/{id}`: the summary, its seed, standings, cross-table and matches.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TournamentView {
    /// What the list shows.
    #[serde(flatten)]
    pub summary: TournamentSummary,
    /// Seed of match 0.
    pub seed: i64,
    /// Standings, best first.
    pub standings: Vec<Standing>,
    /// The cross-table's agents (rows and columns).
    pub cross_table_agents: Vec<String>,
    /// Row agent's record against the column agent (none on the diagonal).
    pub cross_table: Vec<Vec<Option<Cell>>>,
    /// Its matches, by id.
    pub matches: Vec<ContestMatch>,
}

/// `GET /tournaments`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct TournamentList {
    /// Newest first.
    pub tournaments: Vec<TournamentSummary>,
}

/// An SPRT's log-likelihood-ratio bounds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct Bounds {
    /// Accept H0 at or below.
    pub lower: f64,
    /// Accept H1 at or above.
    pub upper: f64,
}

/// `GET /sprt/{id}`: the row, names, bounds, estimates and matches.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
pub struct SprtView {
    /// The row.
    #[serde(flatten)]
    pub row: Sprt,
    /// Agent A's name.
    pub agent_a_name: String,
    /// Agent B's name.
    pub agent_b_name: String,
    /// The decision bounds.
    pub bounds: Bounds,
    /// Mean point share of A over the finished matches.
    pub mean_share_of_a: Option<f64>,
    /// The Elo difference that share means.
    pub elo_estimate: Option<f64>,
    /// Its matches, by id.
    pub matches: Vec<SprtMatch>,
}

/// `GET /sprt`.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
pub struct SprtList {
    /// Newest first.
    pub sprts: Vec<Sprt>,
}

/// A worker as `GET /workers` shows it: its row, its heartbeat's age, whether its lease would still
/// hold, and the matches it holds now.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
pub struct WorkerView {
    /// The row.
    #[serde(flatten)]
    pub row: Worker,
    /// Seconds since its last heartbeat.
    pub seconds_since_heartbeat: f64,
    /// Running and beating within the lease time.
    pub alive: bool,
    /// The matches whose lease it holds.
    pub matches_running: Vec<i64>,
}

/// `GET /workers`.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
pub struct WorkerList {
    /// The most recent heartbeat first.
    pub workers: Vec<WorkerView>,
    /// The lease time, s.
    pub lease_s: f64,
}
