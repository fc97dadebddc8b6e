//! Direct control (Muscle-PPO): the action is every muscle's control.

use super::*;

/// Muscle-PPO's control for an action entry, as the official code maps it: `sigmoid(5·(a − 0.5))`
/// (a ∈ [−1, 1] → u ∈ [0.0006, 0.92]; a = 0 asks for 0.08).
pub fn direct_control(a: f64) -> f64 {
    1.0 / (1.0 + sim::math::exp(-5.0 * (a.clamp(-1.0, 1.0) - 0.5)))
}

/// Direct (Muscle-PPO): the action is every muscle's control (clipped to [0, 1]) plus pelvis targets.
pub fn direct_controls(space: &ActionSpace, muscles: &[f64], pelvis: &[f64], ctrl: &mut [f64]) {
    for (&a, &u) in space.muscles.iter().zip(muscles) {
        ctrl[a] = u.clamp(0.0, 1.0);
    }
    for ((_, s), &t) in space.servo_joints().zip(pelvis) {
        ctrl[s] = t;
    }
}
