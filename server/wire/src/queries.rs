//! The query strings the API takes, as types: an unknown parameter, or a value of the wrong kind, is
//! refused naming it.

use schemars::JsonSchema;
use serde::{Deserialize, Deserializer, Serialize};

use crate::MatchStatus;

/// `GET /agents?all=1&model=`: the retired agents too; one robot's.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct AgentsQuery {
    /// List the retired agents too (`1`/`true`; `0`/`false` or absent: not).
    #[serde(default, deserialize_with = "yes_no")]
    pub all: bool,
    /// Only the agents of this robot (absent: every robot's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<String>,
}

/// `?model=NAME`: the robot whose leaderboard, arena or body is asked for (absent: `default`).
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ModelQuery {
    /// The robot: `default` or `myochallenge` (`GET /health` lists the ones this server plays).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<String>,
}

impl ModelQuery {
    /// The robot asked for, `default` when none is.
    pub fn robot(&self) -> &str {
        self.model.as_deref().unwrap_or("default")
    }
}

/// `?limit=N`: the lists of tournaments, SPRTs and an agent's crossings.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LimitQuery {
    /// Most rows to answer (each list has its default and maximum).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub limit: Option<i64>,
}

/// `GET /matches?agent=&status=&model=&limit=&before=`: a page of matches, newest first.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MatchesQuery {
    /// Only the matches of this robot.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<String>,
    /// Only the matches of this agent (either side).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub agent: Option<i64>,
    /// Only the matches in this state.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub status: Option<MatchStatus>,
    /// Most matches to answer (default 100, at most 1000).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub limit: Option<i64>,
    /// Only the matches with a smaller id (the previous page's `next_before`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub before: Option<i64>,
}

/// `GET /matches/{id}/replay?rally=K`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ReplayQuery {
    /// The rally, from 0 (default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rally: Option<i64>,
}

/// A yes/no in a query string: `1`, `true`, `0` or `false`.
fn yes_no<'de, D: Deserializer<'de>>(d: D) -> Result<bool, D::Error> {
    match String::deserialize(d)?.as_str() {
        "1" | "true" => Ok(true),
        "0" | "false" => Ok(false),
        other => Err(serde::de::Error::custom(format!(
            "must be 1 or 0, not '{other}'"
        ))),
    }
}
