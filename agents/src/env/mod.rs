//! The RL environments (paper §IV-B and §IV-C, docs/design.md §6): the single-serve episode and the
//! self-play rally, with the reward `w_g·r_g + w_c·r_c + w_s·r_s` and a reset/step API on actions in
//! [−1, 1], observing through [`crate::observation`]. Deterministic per seed.
//!
//! By part: [`reward`] (the terms and the stroke reward), [`single`] (the single-serve `Env`),
//! [`rally`] (the self-play `RallyEnv`), [`bank`] (balls recorded from rallies).

pub mod bank;
pub mod rally;
pub mod reward;
pub mod single;

pub use bank::*;
pub use rally::*;
pub use reward::*;
pub use single::*;
