//! # agents — the paper's controllers and everything that plays the game
//!
//! The physics-based planner ([`planner`], on `sim::predict`), K-MAC and the baselines
//! ([`controller`]: joint targets or muscle lengths or raw controls → muscle controls), inverse
//! kinematics for the paddle ([`ik`]), the scripted house agent ([`scripted`]), what a policy sees
//! ([`observation`]), the RL environments ([`env`]), checkpoints ([`checkpoint`]), who plays
//! ([`player`]: the trait; [`factory`]: building one from a name or a checkpoint), PPO ([`ppo`]),
//! evaluation ([`eval`]), admission ([`admit`]: a checkpoint's text validated and qualified), the
//! match runner ([`matchrun`]), the seeds they share ([`seeds`]) and the training environments
//! stepped together for callers outside `rally train` ([`vecenv`]).
//!
//! Modules import each other in one direction only: `seeds`, `planner`, `ik` and `controller` on
//! `sim`; `observation` on those; `player` on `sim`; `checkpoint` and `scripted` on those;
//! `factory` on `checkpoint` and `scripted`; `env`, `eval`, `admit`, `matchrun` and `ppo` on top;
//! `vecenv` on `ppo`.
//!
//! Must never: speak HTTP or SQL (that is `server`), or change the physics (that is `sim`).
//! Depends on `sim` only.
#![forbid(unsafe_code)]

pub mod admit;
pub mod builtins;
pub mod checkpoint;
pub mod controller;
pub mod env;
pub mod eval;
pub mod factory;
pub mod ik;
pub mod matchrun;
pub mod observation;
pub mod planner;
pub mod player;
#[cfg(feature = "train")]
pub mod ppo;
pub mod scripted;
pub mod seeds;
#[cfg(feature = "train")]
pub mod vecenv;

/// The simulator this crate drives, re-exported so that callers name one version of it.
pub use sim;
