//! The rules of a legal return (docs/design.md §4; MyoChallenge's `evaluate_pingpong_trajectory`, extended
//! to rallies of any length). A [`Referee`] follows one rally from the serve: it is fed the contact
//! events in time order, the ball's height, and failures reported from outside (a dropped paddle, an
//! invalid action), and it calls hits, legal returns and the end of the rally.
//!
//! A return by the receiver is legal iff its paddle touches the ball exactly once, after exactly one
//! bounce on its own half, and the ball's next table contact is on the other half (the net may be
//! touched on the way). Pure state machine: no physics, no clock.

use crate::arena::{self, Side};
use crate::events::{ContactEvent, ContactKind};

/// Why a shot failed. Events are judged in time order, so a rally ends with the first failure that
/// happens; where two could apply to one event, the order below decides (NO_BOUNCE first).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "SCREAMING_SNAKE_CASE")]
pub enum Failure {
    /// The receiver hit the ball before it bounced on the receiver's half.
    NoBounce,
    /// The receiver never touched the ball (it bounced twice, left the table, or fell).
    Miss,
    /// The side that last hit touched the ball again before the other side returned it.
    DoubleTouch,
    /// After the hit, the ball touched the hitter's own half again.
    OwnHalf,
    /// After the hit, the ball touched the net and never reached the other half.
    Net,
    /// After the hit, the ball missed the table: it reached the floor, or fell below 0.3 m, without a
    /// table contact.
    Out,
    /// The receiver lost its paddle (reported by the arena).
    DroppedPaddle,
    /// The receiver's policy produced NaN or infinite actions (reported by the match runner).
    InvalidAction,
}

impl Failure {
    /// Every failure, in precedence order.
    pub const ALL: [Failure; 8] = [
        Failure::NoBounce,
        Failure::Miss,
        Failure::DoubleTouch,
        Failure::OwnHalf,
        Failure::Net,
        Failure::Out,
        Failure::DroppedPaddle,
        Failure::InvalidAction,
    ];

    /// The name used in records and APIs, e.g. "NO_BOUNCE".
    pub fn name(self) -> &'static str {
        match self {
            Failure::NoBounce => "NO_BOUNCE",
            Failure::Miss => "MISS",
            Failure::DoubleTouch => "DOUBLE_TOUCH",
            Failure::OwnHalf => "OWN_HALF",
            Failure::Net => "NET",
            Failure::Out => "OUT",
            Failure::DroppedPaddle => "DROPPED_PADDLE",
            Failure::InvalidAction => "INVALID_ACTION",
        }
    }
}

/// How a rally ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "SCREAMING_SNAKE_CASE")]
pub enum EndReason {
    /// A side failed.
    Failure(Failure),
    /// The rally reached its configured cap; no side loses.
    Capped,
}

impl EndReason {
    /// The name used in records: a failure's name, or "CAPPED".
    pub fn name(self) -> &'static str {
        match self {
            EndReason::Failure(f) => f.name(),
            EndReason::Capped => "CAPPED",
        }
    }
}

/// The end of a rally.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RallyEnd {
    /// Why it ended.
    pub reason: EndReason,
    /// The side that failed (`None` when capped).
    pub failing_side: Option<Side>,
    /// When, s.
    pub t: f64,
}

/// What the referee calls as play goes on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Call {
    /// The receiver touched the ball once, legally so far (counts for the hit rate).
    Hit {
        /// Who hit.
        side: Side,
        /// When, s.
        t: f64,
    },
    /// The serve landed on the receiver's half.
    ServeIn {
        /// When, s.
        t: f64,
    },
    /// A legal return by `hitter`: the ball's next table contact after its hit is on the other half.
    LegalReturn {
        /// Who returned it.
        hitter: Side,
        /// When it landed, s.
        t: f64,
    },
    /// The rally is over.
    End(RallyEnd),
}

/// Where the ball is in the cycle of a rally.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    /// The ball left `hitter` (its paddle, or the serve) and must land on the other half.
    Outgoing {
        hitter: Side,
        serve: bool,
        net: bool,
    },
    /// The ball bounced once on `receiver`'s half; `receiver` must touch it once.
    Incoming { receiver: Side },
    /// The rally is over.
    Over(RallyEnd),
}

/// Judges one rally, from its serve to its end.
#[derive(Debug, Clone, PartialEq)]
pub struct Referee {
    phase: Phase,
    returns: u32,
    server: Side,
}

impl Referee {
    /// A rally whose serve comes from `server` (launcher serves come from B).
    pub fn new(server: Side) -> Referee {
        Referee {
            phase: Phase::Outgoing {
                hitter: server,
                serve: true,
                net: false,
            },
            returns: 0,
            server,
        }
    }

    /// Who served.
    pub fn server(&self) -> Side {
        self.server
    }

    /// Legal returns so far: the rally length (the serve is not a return).
    pub fn rally_length(&self) -> u32 {
        self.returns
    }

    /// The end of the rally, once called.
    pub fn end(&self) -> Option<RallyEnd> {
        match self.phase {
            Phase::Over(end) => Some(end),
            _ => None,
        }
    }

    /// The side expected to touch the ball next, while the rally goes on.
    pub fn receiver(&self) -> Option<Side> {
        match self.phase {
            Phase::Outgoing { hitter, .. } => Some(hitter.other()),
            Phase::Incoming { receiver } => Some(receiver),
            Phase::Over(_) => None,
        }
    }

    fn finish(&mut self, side: Option<Side>, reason: EndReason, t: f64) -> Option<Call> {
        let end = RallyEnd {
            reason,
            failing_side: side,
            t,
        };
        self.phase = Phase::Over(end);
        Some(Call::End(end))
    }

    fn fail(&mut self, side: Side, failure: Failure, t: f64) -> Option<Call> {
        self.finish(Some(side), EndReason::Failure(failure), t)
    }

    /// Judges one contact event. Events must come in time order.
    pub fn on_contact(&mut self, e: &ContactEvent) -> Option<Call> {
        match self.phase {
            Phase::Over(_) => None,
            Phase::Outgoing { hitter, serve, net } => match e.kind {
                ContactKind::Paddle { owner } if owner == hitter => {
                    self.fail(hitter, Failure::DoubleTouch, e.t)
                }
                ContactKind::Paddle { owner } => self.fail(owner, Failure::NoBounce, e.t),
                ContactKind::Net => {
                    self.phase = Phase::Outgoing {
                        hitter,
                        serve,
                        net: true,
                    };
                    None
                }
                ContactKind::Floor => self.ball_lost(hitter, net, e.t),
                ContactKind::Table { .. } if !e.is_bounce() => None,
                ContactKind::Table { .. } => {
                    if Side::of_x(e.pos.x) == hitter {
                        return self.fail(hitter, Failure::OwnHalf, e.t);
                    }
                    self.phase = Phase::Incoming {
                        receiver: hitter.other(),
                    };
                    if serve {
                        Some(Call::ServeIn { t: e.t })
                    } else {
                        self.returns += 1;
                        Some(Call::LegalReturn { hitter, t: e.t })
                    }
                }
            },
            Phase::Incoming { receiver } => match e.kind {
                ContactKind::Paddle { owner } if owner == receiver => {
                    self.phase = Phase::Outgoing {
                        hitter: receiver,
                        serve: false,
                        net: false,
                    };
                    Some(Call::Hit {
                        side: owner,
                        t: e.t,
                    })
                }
                // The side that sent the ball touched it again before the receiver returned it.
                ContactKind::Paddle { owner } => self.fail(owner, Failure::DoubleTouch, e.t),
                ContactKind::Net => None,
                ContactKind::Table { .. } if !e.is_bounce() => None,
                ContactKind::Table { .. } | ContactKind::Floor => {
                    self.fail(receiver, Failure::Miss, e.t)
                }
            },
        }
    }

    /// Judges the ball's height: below `BALL_LOW_Z` the shot is over.
    pub fn on_ball_height(&mut self, t: f64, z: f64) -> Option<Call> {
        if z >= arena::BALL_LOW_Z {
            return None;
        }
        match self.phase {
            Phase::Outgoing { hitter, net, .. } => self.ball_lost(hitter, net, t),
            Phase::Incoming { receiver } => self.fail(receiver, Failure::Miss, t),
            Phase::Over(_) => None,
        }
    }

    fn ball_lost(&mut self, hitter: Side, net: bool, t: f64) -> Option<Call> {
        let failure = if net { Failure::Net } else { Failure::Out };
        self.fail(hitter, failure, t)
    }

    /// A failure found outside the ball world (DROPPED_PADDLE, INVALID_ACTION) ends the rally now.
    pub fn report(&mut self, side: Side, failure: Failure, t: f64) -> Option<Call> {
        match self.phase {
            Phase::Over(_) => None,
            _ => self.fail(side, failure, t),
        }
    }

    /// The rally reached its cap: it ends with no loser.
    pub fn cap(&mut self, t: f64) -> Option<Call> {
        match self.phase {
            Phase::Over(_) => None,
            _ => self.finish(None, EndReason::Capped, t),
        }
    }
}
