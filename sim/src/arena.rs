//! The arena's numbers, each named once with its unit and source (docs/design.md §3–4).
//!
//! The default arena is the MyoChallenge 2025 table-tennis scene (MyoSuite 3.0, compiled by MuJoCo
//! 4.0; `sim/tests/fixtures/myosuite_tt_ball_only.xml` holds the same numbers). Nothing here is
//! mutable: a [`Preset`] selects the contact laws and their coefficients.

use nalgebra::Vector3;

/// Physics timestep, s (MyoSuite `option timestep`).
pub const TIMESTEP: f64 = 0.002;
/// Physics substeps per control step (MyoSuite `frame_skip`), so control runs at 100 Hz.
pub const SUBSTEPS: usize = 5;
/// Control step, s.
pub const CONTROL_DT: f64 = TIMESTEP * SUBSTEPS as f64;
/// Control steps in a single-serve episode (3 s).
pub const EPISODE_STEPS: usize = 300;
/// Gravity, m/s² (MyoSuite `option gravity = 0 0 -9.81`).
pub const GRAVITY: f64 = 9.81;
/// A shot is over once the ball centre is below this height, m (MyoChallenge termination).
pub const BALL_LOW_Z: f64 = 0.3;

/// Ball radius, m (ITTF 40 mm ball; MyoSuite geom `pingpong` size 0.02).
pub const BALL_RADIUS: f64 = 0.02;
/// Ball mass, kg (ITTF 2.7 g; MyoSuite inertial mass 2.7e-3).
pub const BALL_MASS: f64 = 0.0027;
/// Ball moment of inertia about any axis, kg·m²: thin spherical shell `2/3·m·r²` = 7.2e-7,
/// the value MyoSuite states (`diaginertia 7.2e-7`).
pub const BALL_INERTIA: f64 = 2.0 / 3.0 * BALL_MASS * BALL_RADIUS * BALL_RADIUS;

/// Table top (playing surface) height, m (MyoSuite `coll_own_half` box half-height 0.795 at z = 0).
/// MyoSuite's opponent half is 1 mm taller (0.796); we keep both halves at 0.795 so that the two
/// robots of the dual arena see the same table.
pub const TABLE_TOP_Z: f64 = 0.795;
/// Table half-length along x, m (two 0.685-long halves: x ∈ [−1.37, 1.37]).
pub const TABLE_HALF_LENGTH: f64 = 1.37;
/// The table's centre line, m: MyoSuite's table is offset from y = 0 (docs/design.md §3).
pub const TABLE_CENTER_Y: f64 = 0.04;
/// Table half-width across, m (MyoSuite box half-width 0.76, centred at `TABLE_CENTER_Y`).
pub const TABLE_HALF_WIDTH: f64 = 0.76;
/// Table extent across, m.
pub const TABLE_Y_MIN: f64 = TABLE_CENTER_Y - TABLE_HALF_WIDTH;
/// Table extent across, m.
pub const TABLE_Y_MAX: f64 = TABLE_CENTER_Y + TABLE_HALF_WIDTH;

/// Net box centre, m (MyoSuite `coll_net` pos: over the table's centre line, at its top).
pub const NET_CENTER: [f64; 3] = [0.0, TABLE_CENTER_Y, TABLE_TOP_Z];
/// Net box half-sizes, m (MyoSuite `coll_net` size): top at z = 0.9475.
pub const NET_HALF_SIZE: [f64; 3] = [0.005, 0.9125, 0.1525];
/// Height of the net's top, m.
pub const NET_TOP_Z: f64 = NET_CENTER[2] + NET_HALF_SIZE[2];

/// Floor height, m.
pub const FLOOR_Z: f64 = 0.0;

// The paddle (blade, handle, mass) is the robot model's: its `paddle` body's `blade` and `handle`
// geoms (`geometry::PaddleShape::from_model`). The MJCF is its one source.

/// Virtual hitting plane of side A (it receives there), m (paper §IV-B, official `hit_plane_x`).
pub const STRIKE_PLANE_X: f64 = 1.8;
/// Serve box on the hitting plane (official code): `z ∈ (1.1, 1.35)`, m.
pub const SERVE_BOX_Z: (f64, f64) = (1.1, 1.35);
/// Serve box on the hitting plane: `|y_r| < 0.7`, m, in the receiver frame.
pub const SERVE_BOX_HALF_WIDTH: f64 = 0.7;

/// The two sides of the table. A is x > 0, B is x < 0 (docs/design.md §3), absolute in the world frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Side {
    /// x > 0: the single-serve robot's side.
    A,
    /// x < 0.
    B,
}

impl Side {
    /// The side across the net.
    pub fn other(self) -> Side {
        match self {
            Side::A => Side::B,
            Side::B => Side::A,
        }
    }

    /// +1 for A, −1 for B: the sign of x on this side.
    pub fn sign(self) -> f64 {
        match self {
            Side::A => 1.0,
            Side::B => -1.0,
        }
    }

    /// The side a world x coordinate lies on (x = 0 counts as A; it is under the net).
    pub fn of_x(x: f64) -> Side {
        if x >= 0.0 {
            Side::A
        } else {
            Side::B
        }
    }

    /// x of this side's hitting plane.
    pub fn strike_plane_x(self) -> f64 {
        self.sign() * STRIKE_PLANE_X
    }

    /// Lower-case name, "a" or "b".
    pub fn name(self) -> &'static str {
        match self {
            Side::A => "a",
            Side::B => "b",
        }
    }

    /// `(y_r, z)` of a world point in this receiver's frame (docs/design.md §3): `y_r = ±(y − 0.04)`.
    pub fn receiver_frame(self, p: &Vector3<f64>) -> (f64, f64) {
        (self.sign() * (p.y - TABLE_CENTER_Y), p.z)
    }

    /// World y of a receiver-frame `y_r` on this side.
    pub fn world_y(self, y_r: f64) -> f64 {
        TABLE_CENTER_Y + self.sign() * y_r
    }
}

/// Whether `(y_r, z)` in the receiver frame lies inside the serve box (open bounds, official code).
pub fn in_serve_box(y_r: f64, z: f64) -> bool {
    z > SERVE_BOX_Z.0 && z < SERVE_BOX_Z.1 && y_r.abs() < SERVE_BOX_HALF_WIDTH
}

/// How the ball meets the table and the floor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SurfaceLaw {
    /// MuJoCo's soft contact, force-based, active while the ball penetrates (`contact` applies it).
    Soft(SoftContact),
    /// Instantaneous impulse, event-accurate (see `contact::impulse`).
    Impulse(ImpulseCoeffs),
}

/// Parameters of MuJoCo's soft contact in direct form. The force law is in `contact`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SoftContact {
    /// Stiffness, s⁻² (MuJoCo `−solref[0]`).
    pub stiffness: f64,
    /// Damping, s⁻¹ (MuJoCo `−solref[1]`).
    pub damping: f64,
    /// MuJoCo `solimp = (d0, dwidth, width)`; midpoint 0.5 and power 2 as MuJoCo's defaults.
    pub solimp: [f64; 3],
    /// Damping rate of the contact point's tangential velocity, s⁻¹ (our stand-in for MuJoCo's
    /// regularised pyramidal friction, fitted to the reference bounce).
    pub tangential_damping: f64,
}

/// Restitution and Coulomb friction of an impulsive contact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImpulseCoeffs {
    /// Normal restitution coefficient, `v_n⁺ = −e·v_n⁻`, in [0, 1].
    pub restitution: f64,
    /// Coulomb friction coefficient bounding the tangential impulse.
    pub friction: f64,
}

/// Air model: quadratic drag and Magnus lift, as accelerations.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AirModel {
    /// `a_drag = −k_d·|v|·v`, k_d in 1/m: `½·ρ·C_D·A/m`.
    pub drag: f64,
    /// `a_magnus = k_m·(ω × v)`, k_m dimensionless: `½·ρ·C_M·A·r/m`.
    pub magnus: f64,
}

/// Air density at sea level and 20 °C, kg/m³.
pub const AIR_DENSITY: f64 = 1.204;
/// Drag coefficient of a table-tennis ball (about 0.5 in wind-tunnel measurements of 40 mm balls).
pub const BALL_DRAG_COEFF: f64 = 0.5;
/// Magnus (lift) coefficient in `F = ½·ρ·C_M·A·r·(ω × v)`; with C_M ≈ 1 the lift matches the
/// spin-parameter-linear fits reported for table-tennis balls at moderate spin (≈ 0.2–0.3 lift
/// coefficient at spin parameter rω/v ≈ 0.2–0.3).
pub const BALL_MAGNUS_COEFF: f64 = 1.0;

/// A named arena variant: which contact laws and coefficients the ball world uses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Preset {
    /// Name used on the command line and in match records.
    pub name: &'static str,
    /// Table and floor contact.
    pub table: SurfaceLaw,
    /// Paddle contact (always impulsive: never tunnels, never adds energy).
    pub paddle: ImpulseCoeffs,
    /// Net contact (always impulsive).
    pub net: ImpulseCoeffs,
    /// Air drag and Magnus lift; `None` is vacuum flight.
    pub air: Option<AirModel>,
}

/// MuJoCo's soft contact of the reference scene: ball `solref = (−80000, −1)`,
/// `solimp = (0.9, 0.95, 0.001)` (the ball geom has priority 2, so its parameters win).
pub const MYOCHALLENGE_SOFT: SurfaceLaw = SurfaceLaw::Soft(SoftContact {
    stiffness: 80_000.0,
    damping: 1.0,
    solimp: [0.9, 0.95, 0.001],
    // Fitted to the 30 reference serves: MuJoCo's pyramidal friction in that scene keeps ≈ 0.994 of
    // the horizontal velocity through a bounce, about what a 0.55 s⁻¹ damping of the contact
    // point's tangential velocity over the 10–12 ms contact gives.
    tangential_damping: 0.55,
});

/// The default preset: the MyoChallenge 2025 scene, vacuum flight, MuJoCo's soft table.
pub const MYOCHALLENGE: Preset = Preset {
    name: "myochallenge",
    table: MYOCHALLENGE_SOFT,
    // The scene's paddle and net contacts use the same soft ball contact, which returns ≈ 0.99 of
    // the normal speed at any impact speed (a linear spring-damper with damping ratio 0.002) and,
    // through its regularised friction, loses ≈ 0.5% of the tangential speed on a 6 m/s normal
    // impulse: an effective Coulomb coefficient of ≈ 0.005.
    paddle: ImpulseCoeffs {
        restitution: 0.99,
        friction: 0.005,
    },
    net: ImpulseCoeffs {
        restitution: 0.99,
        friction: 0.005,
    },
    air: None,
};

/// A more physical table: ITTF bounce, rubber paddle, slack net, air drag and Magnus lift.
pub const REALISTIC: Preset = Preset {
    name: "realistic",
    // ITTF 2.03.01: dropped from 30.5 cm the ball bounces to about 23 cm: e = √(23/30.5) ≈ 0.87.
    // Ball–table Coulomb friction ≈ 0.25 (values of 0.1–0.3 are reported for ball-on-table).
    table: SurfaceLaw::Impulse(ImpulseCoeffs {
        restitution: 0.87,
        friction: 0.25,
    }),
    // Inverted rubber on a blade: normal restitution ≈ 0.8, high friction ≈ 0.6 (literature range
    // 0.7–0.9 and 0.4–0.8; a named approximation, not a measurement of ours).
    paddle: ImpulseCoeffs {
        restitution: 0.8,
        friction: 0.6,
    },
    // A real net is a slack mesh that absorbs most of the ball's energy.
    net: ImpulseCoeffs {
        restitution: 0.15,
        friction: 0.3,
    },
    air: Some(AirModel {
        drag: 0.5
            * AIR_DENSITY
            * BALL_DRAG_COEFF
            * std::f64::consts::PI
            * BALL_RADIUS
            * BALL_RADIUS
            / BALL_MASS,
        magnus: 0.5
            * AIR_DENSITY
            * BALL_MAGNUS_COEFF
            * std::f64::consts::PI
            * BALL_RADIUS
            * BALL_RADIUS
            * BALL_RADIUS
            / BALL_MASS,
    }),
};

/// Every preset, for look-up by name.
pub const PRESETS: [Preset; 2] = [MYOCHALLENGE, REALISTIC];

impl Preset {
    /// The preset called `name`, if any.
    pub fn by_name(name: &str) -> Option<Preset> {
        PRESETS.iter().copied().find(|p| p.name == name)
    }

    /// Names of all presets, for messages.
    pub fn names() -> Vec<&'static str> {
        PRESETS.iter().map(|p| p.name).collect()
    }
}

impl Default for Preset {
    fn default() -> Self {
        MYOCHALLENGE
    }
}
