//! The event stream's messages (`GET /events`, server-sent events).

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::MatchStatus;

/// What changed on the server, as `GET /api/v1/events` streams it (server-sent events): a match
/// queued, started, finished, failed or cancelled, or an agent registered.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct ServerEvent {
    /// What it is about.
    pub kind: EventKind,
    /// The match's or the agent's id.
    pub id: i64,
    /// A match's new status; none for agents.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub status: Option<MatchStatus>,
}

/// What a [`ServerEvent`] is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum EventKind {
    /// A match (queued, running, done, failed, cancelled).
    Match,
    /// An agent (registered).
    Agent,
}
