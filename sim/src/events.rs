//! Contact events: what the ball touched, where and when the touch began. The ball world emits
//! them; the rules engine judges shots from them; the CLI prints them.

use nalgebra::Vector3;

use crate::arena::Side;
use crate::geometry::Feature;

/// What the ball touched.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ContactKind {
    /// The table; `feature` says whether the playing surface (`Top`), its border (`Edge`, an edge
    /// ball, which counts as on the table) or a side face (`Side`, which does not).
    Table {
        /// Which part of the table box.
        feature: Feature,
    },
    /// The net (either face, or its top).
    Net,
    /// The floor.
    Floor,
    /// A paddle, with the side of the robot that holds it.
    Paddle {
        /// Whose paddle.
        owner: Side,
    },
}

impl ContactKind {
    /// The name printed in event streams: "table", "net", "floor" or "paddle".
    pub fn name(&self) -> &'static str {
        match self {
            ContactKind::Table { .. } => "table",
            ContactKind::Net => "net",
            ContactKind::Floor => "floor",
            ContactKind::Paddle { .. } => "paddle",
        }
    }
}

/// The beginning of one contact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactEvent {
    /// What was touched.
    pub kind: ContactKind,
    /// Time of first contact, s: for soft contacts the moment the ball centre came within one radius
    /// of the surface, interpolated inside the physics step; for impulses the time of impact.
    pub t: f64,
    /// Ball centre at that moment, m.
    pub pos: Vector3<f64>,
}

impl ContactEvent {
    /// Side of the table where it happened, by the sign of x; `None` for the net.
    pub fn side(&self) -> Option<Side> {
        match self.kind {
            ContactKind::Net => None,
            _ => Some(Side::of_x(self.pos.x)),
        }
    }

    /// A touch of the playing surface (top face or its edge): a bounce in the sense of the rules.
    pub fn is_bounce(&self) -> bool {
        matches!(
            self.kind,
            ContactKind::Table {
                feature: Feature::Top | Feature::Edge
            }
        )
    }
}
