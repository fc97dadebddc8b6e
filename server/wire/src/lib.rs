//! # wire — the API's types
//!
//! What a client of muscle-rally's server sends and what it answers, as types: the request bodies,
//! the store's rows as the answers show them, the answers built on them, the leaderboard, the event
//! stream's messages and the words (statuses, kinds) they use. The server's handlers answer with
//! these, its store decodes its rows into them, and `rally batch`, the benchmarks and the tests read
//! them, so none of them can drift from the others; the OpenAPI document describes the same shapes
//! for everyone else.
//!
//! Must never: depend on the database or the HTTP stack (a client needs neither), or hold logic
//! beyond a word's spelling and a record's arithmetic.
#![forbid(unsafe_code)]
#![warn(missing_docs)]

mod board;
mod bodies;
mod contests;
mod events;
mod queries;
mod rows;
mod words;

pub use board::*;
pub use bodies::*;
pub use contests::*;
pub use events::*;
pub use queries::*;
pub use rows::*;
pub use words::*;

/// The JSON schemas of the API's answers, as the OpenAPI document's `components.schemas` holds
/// them (OpenAPI 3.0; what the server writes: a field it leaves out when empty is not required),
/// by type name. `server/src/openapi.json` is held to them by a test.
pub fn answer_schemas() -> serde_json::Map<String, serde_json::Value> {
    use schemars::generate::{Contract, SchemaSettings};
    let mut g = SchemaSettings::openapi3()
        .with(|s| s.contract = Contract::Serialize)
        .into_generator();
    macro_rules! answers {
        ($($t:ty),* $(,)?) => { $( g.subschema_for::<$t>(); )* };
    }
    answers!(
        Health,
        AgentList,
        Agent,
        AgentDetail,
        Submitted,
        RatingHistory,
        AgentCrossings,
        MatchList,
        Match,
        MatchDetail,
        Leaderboard,
        IssuedToken,
        TournamentList,
        TournamentView,
        SprtList,
        SprtView,
        WorkerList,
        ErrorBody,
        ServerEvent,
    );
    g.take_definitions(true)
}
