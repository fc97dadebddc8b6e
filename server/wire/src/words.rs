//! The API's vocabulary: the states of matches, SPRTs and workers, the kinds of agents and of
//! tournaments, each a word spelled once here — the JSON bodies, the store's TEXT columns and the
//! `CHECK` constraints of `migrations/` use the same words.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Declares a string-valued enum: serde spells each variant as given, `as_str` and `FromStr` too (the
/// store writes `as_str` into its TEXT columns), and `ALL` lists them in order.
macro_rules! words {
    ($(#[$doc:meta])* $name:ident { $($(#[$vdoc:meta])* $variant:ident = $word:literal),+ $(,)? }) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, JsonSchema)]
        pub enum $name {
            $($(#[$vdoc])* #[serde(rename = $word)] $variant),+
        }

        impl $name {
            /// Every value, in order.
            pub const ALL: &'static [$name] = &[$($name::$variant),+];

            /// The word the database and the API use.
            pub fn as_str(self) -> &'static str {
                match self {
                    $($name::$variant => $word),+
                }
            }
        }

        impl std::str::FromStr for $name {
            type Err = String;

            fn from_str(s: &str) -> Result<$name, String> {
                match s {
                    $($word => Ok($name::$variant),)+
                    _ => Err(format!(
                        "must be one of {}",
                        [$($word),+].join(", ")
                    )),
                }
            }
        }

        impl std::fmt::Display for $name {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.as_str())
            }
        }
    };
}

words! {
    /// A match's life: queued → running → done | failed | cancelled; a running match whose lease ran
    /// out goes back to queued.
    MatchStatus {
        /// Waiting for a worker.
        Queued = "queued",
        /// A worker holds its lease and plays it.
        Running = "running",
        /// Played and stored.
        Done = "done",
        /// Could not be played (the reason is stored).
        Failed = "failed",
        /// Cancelled before it was stored.
        Cancelled = "cancelled",
    }
}

impl MatchStatus {
    /// Whether nothing will change it any more.
    pub fn is_final(self) -> bool {
        matches!(
            self,
            MatchStatus::Done | MatchStatus::Failed | MatchStatus::Cancelled
        )
    }
}

words! {
    /// What an agent is.
    AgentKind {
        /// One of the built-in scripted variants (its spec is the variant's name).
        Scripted = "scripted",
        /// A policy checkpoint (its spec is the checkpoint's JSON).
        Checkpoint = "checkpoint",
    }
}

words! {
    /// An SPRT's life: running → accepted_h1 | accepted_h0 | inconclusive | failed | cancelled.
    SprtStatus {
        /// Playing matches.
        Running = "running",
        /// The LLR crossed the upper bound.
        AcceptedH1 = "accepted_h1",
        /// The LLR crossed the lower bound.
        AcceptedH0 = "accepted_h0",
        /// `max_matches` played without a decision.
        Inconclusive = "inconclusive",
        /// One of its matches failed.
        Failed = "failed",
        /// Cancelled (or its match was).
        Cancelled = "cancelled",
    }
}

words! {
    /// A worker process's state as it last reported it.
    WorkerStatus {
        /// Playing (or waiting for) matches; a worker that died stays here with an old heartbeat.
        Running = "running",
        /// Stopped by itself (SIGTERM), its matches stored.
        Stopped = "stopped",
    }
}

words! {
    /// Kinds of tournament.
    TournamentKind {
        /// Every pair of agents.
        RoundRobin = "round_robin",
        /// The first agent against each of the others.
        Gauntlet = "gauntlet",
    }
}
