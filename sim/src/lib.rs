//! # sim — the muscle-rally simulator
//!
//! Physics only: the ball world (flight, table, net and paddle contacts), the rules of a legal
//! return, ballistic prediction and the serve generators; the musculoskeletal robot (MJCF loader,
//! kinematics, rigid-body dynamics, MuJoCo's muscles, the grip), the dual arena, and the episodes
//! played on them ([`episode`]: a single serve, a rally).
//!
//! **Must never**: do I/O, spawn threads, read the clock, or draw a random number the caller did not
//! seed. Same inputs give bit-identical outputs. Policies, rewards and observations live in `agents`.
//!
//! Laid out by stage, as MuJoCo's engine is: [`arena`] (every constant, the presets), [`geometry`]
//! (signed distances), [`ball`] (flight), [`contact`] (contact laws), [`world`] (the stepper),
//! [`events`] and [`rules`] (the referee), [`predict`] (drag-free prediction, the return sampler)
//! and [`serve`] (serve generators on a portable ChaCha RNG); for the robot [`mjcf`] (loader) →
//! [`model`] (immutable description) → [`kinematics`] (frames, tendons) → [`dynamics`] (mass matrix,
//! bias, actuation, Euler step) with [`muscle`] (MuJoCo's curves), then [`robot`] (grip, side frame),
//! [`dual`] (two robots and the ball), [`episode`] (the single-serve and rally state machines) and
//! [`config`] (`config/arena.toml`).
#![forbid(unsafe_code)]
#![warn(missing_docs)]

pub mod arena;
pub mod ball;
pub mod config;
pub mod contact;
pub mod dual;
pub mod dynamics;
pub mod episode;
pub mod events;
pub mod geometry;
pub mod kinematics;
pub mod math;
pub mod mjcf;
pub mod model;
pub mod muscle;
pub mod predict;
pub mod rng;
pub mod robot;
pub mod rules;
pub mod serve;
pub mod world;
pub mod wrap;

pub use arena::{Preset, Side};
pub use ball::BallState;
pub use events::{ContactEvent, ContactKind};
pub use world::{BallWorld, Paddle};

/// Version of the simulator's physics and players, recorded with every match so it can be
/// re-simulated. A change that alters any trajectory must bump it: `agents/tests/goldens.rs` fails
/// when a served ball, a scripted episode or a 10-rally match changes while it stays the same
/// (0.2.0: the first version its goldens pin; 0.1.0 covered several dynamics; 0.3.0: replay frames
/// carry both robots' activations; 0.4.0: elementary functions from [`math`] and IK products
/// written out, so that every machine gives the same bits; 0.5.0: a K-MAC checkpoint trained with
/// noise on its activations draws that noise in play, as training did, instead of playing its
/// expectation).
pub const SIM_VERSION: &str = "0.5.0";
