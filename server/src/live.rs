//! What the server tells watchers: the event stream (`GET /api/v1/events`) and each running
//! match's live feed.

use std::sync::Arc;

pub use wire::{EventKind, ServerEvent};

/// Events kept for a slow subscriber before it starts missing some (it is told, and refreshes).
pub const EVENT_BUFFER: usize = 256;

/// One message of a running match's live feed: an SSE event name (`frames` or `rally`) and its JSON.
#[derive(Debug)]
pub struct LiveMsg {
    /// The event's name.
    pub event: &'static str,
    /// Its JSON data.
    pub data: String,
}

/// A running match's live feed: the frames of the rally being played, [`LIVE_CHUNK`] at a time as
/// they are recorded, and each rally's record as it ends.
pub type LiveChannel = tokio::sync::broadcast::Sender<Arc<LiveMsg>>;

/// Frames per `frames` message of a live feed: 0.2 s of play at the replay's 50 Hz.
pub const LIVE_CHUNK: usize = 10;

/// Messages a live viewer may fall behind (about 13 s of play: a few rallies) before it skips to
/// the newest (the worker never waits).
pub const LIVE_BUFFER: usize = 64;
