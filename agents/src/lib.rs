//! # agents — the paper's controllers and everything that plays the game
//!
//! The physics-based planner ([`planner`], on `sim::predict`), K-MAC and the baselines
//! ([`controller`]: joint targets or muscle lengths or raw controls → muscle controls), inverse
//! kinematics for the paddle ([`ik`]), the scripted house agent ([`scripted`]), and (to come in this
//! issue) the RL environment wrapper, checkpoints, PPO, evaluation and the match runner.
//!
//! Must never: speak HTTP or SQL (that is `server`), or change the physics (that is `sim`).
//! Depends on `sim` only.
#![forbid(unsafe_code)]

pub mod checkpoint;
pub mod controller;
pub mod env;
pub mod eval;
pub mod ik;
pub mod matchrun;
pub mod planner;
pub mod player;
pub mod ppo;
pub mod scripted;

/// The simulator this crate drives, re-exported so that callers name one version of it.
pub use sim;
