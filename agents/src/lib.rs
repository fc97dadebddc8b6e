//! # agents — the paper's controllers and everything that plays the game
//!
//! Will hold (issue 4): the physics-based planner (built on `sim::predict`), K-MAC (joint targets →
//! muscle activations), the baselines (Muscle-PPO, Muscle-PD, DynSyn), the RL environment wrapper
//! (observation and reward), policy checkpoints, PPO training, evaluation and the match runner.
//!
//! Must never: speak HTTP or SQL (that is `server`), or change the physics (that is `sim`).
//! Depends on `sim` only. Nothing is implemented here yet.
#![forbid(unsafe_code)]

/// The simulator this crate drives, re-exported so that callers name one version of it.
pub use sim;
