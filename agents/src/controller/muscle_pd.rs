//! Muscle-PD (MuscleVAE-style): target muscle lengths → K-MAC's steps 2–5.

use sim::dynamics::State;
use sim::model::Model;

use super::*;

/// Muscle-PD: target muscle lengths (plus pelvis targets) → muscle controls.
#[derive(Debug, Clone)]
pub struct MusclePd {
    /// Action layout.
    pub space: ActionSpace,
    /// Length PD gains.
    pub gains: PdGains,
    current: MuscleGeometry,
}

impl MusclePd {
    /// Muscle-PD for `model`.
    pub fn new(model: &Model, gains: PdGains) -> MusclePd {
        MusclePd {
            space: ActionSpace::new(model),
            gains,
            current: MuscleGeometry::new(model),
        }
    }

    /// `lengths`: one target length per muscle (m); `pelvis`: one target per servo joint.
    pub fn controls(
        &mut self,
        model: &Model,
        state: &State,
        lengths: &[f64],
        pelvis: &[f64],
        dt: f64,
        ctrl: &mut [f64],
    ) {
        self.current.update(model, &state.qpos);
        for (&a, &l_star) in self.space.muscles.iter().zip(lengths) {
            let now = self.current.now(model, a, state);
            ctrl[a] = muscle_pd_control(model, a, l_star, &now, &self.gains, dt);
        }
        for ((_, s), &t) in self.space.servo_joints().zip(pelvis) {
            ctrl[s] = t;
        }
    }
}
