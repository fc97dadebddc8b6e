//! MuJoCo's Hill-type muscle (docs/design.md §5): the active force–length and force–velocity curves, the
//! passive force, and the activation dynamics, as `mju_muscleGain`, `mju_muscleBias` and
//! `mju_muscleDynamics` in MuJoCo's `engine_util_misc.c` define them. Pure functions of their
//! arguments.
//!
//! Packed parameters, as MuJoCo's `gainprm`/`biasprm` for a muscle:
//! `[range0, range1, force, scale, lmin, lmax, vmax, fpmax, fvmax]`, and `dynprm = [tau_act,
//! tau_deact, tausmooth]`. Forces are negative when pulling (MuJoCo's sign).

/// MuJoCo's `mjMINVAL`, the floor of every divisor in these curves.
const MINVAL: f64 = 1e-15;

/// A muscle's parameters, unpacked from MuJoCo's `gainprm` (which `biasprm` repeats).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MuscleParams {
    /// Operating range of normalised length `[range0, range1]` mapped onto `lengthrange`.
    pub range: [f64; 2],
    /// Peak active force at rest length, N. Negative means "scale / acc0" (MuJoCo); our models state it.
    pub force: f64,
    /// Force scale used when `force < 0`.
    pub scale: f64,
    /// Lower bound of the normalised length where active force is non-zero.
    pub lmin: f64,
    /// Upper bound of the normalised length where active force is non-zero.
    pub lmax: f64,
    /// Shortening speed at which force drops to zero, in optimal lengths per second.
    pub vmax: f64,
    /// Passive force at `lmax`, relative to `force`.
    pub fpmax: f64,
    /// Active force when lengthening fast, relative to `force`.
    pub fvmax: f64,
}

impl MuscleParams {
    /// MuJoCo's `<muscle>` defaults.
    pub const DEFAULT: MuscleParams = MuscleParams {
        range: [0.75, 1.05],
        force: -1.0,
        scale: 200.0,
        lmin: 0.5,
        lmax: 1.6,
        vmax: 1.5,
        fpmax: 1.3,
        fvmax: 1.2,
    };

    /// Unpacks MuJoCo's `gainprm` layout.
    pub fn from_prm(p: &[f64; 10]) -> MuscleParams {
        MuscleParams {
            range: [p[0], p[1]],
            force: p[2],
            scale: p[3],
            lmin: p[4],
            lmax: p[5],
            vmax: p[6],
            fpmax: p[7],
            fvmax: p[8],
        }
    }

    /// Packs into MuJoCo's `gainprm` layout.
    pub fn to_prm(&self) -> [f64; 10] {
        [
            self.range[0],
            self.range[1],
            self.force,
            self.scale,
            self.lmin,
            self.lmax,
            self.vmax,
            self.fpmax,
            self.fvmax,
            0.0,
        ]
    }

    /// Peak force, N: `force`, or `scale / acc0` when `force` is negative (MuJoCo).
    pub fn peak_force(&self, acc0: f64) -> f64 {
        if self.force < 0.0 {
            self.scale / acc0.max(MINVAL)
        } else {
            self.force
        }
    }

    /// Optimal fibre length L0 implied by the length range: `(lr1 − lr0) / (range1 − range0)`.
    pub fn optimal_length(&self, lengthrange: [f64; 2]) -> f64 {
        (lengthrange[1] - lengthrange[0]) / (self.range[1] - self.range[0]).max(MINVAL)
    }

    /// Normalised length `L = range0 + (len − lr0) / L0`.
    pub fn normalized_length(&self, len: f64, lengthrange: [f64; 2]) -> f64 {
        self.range[0] + (len - lengthrange[0]) / self.optimal_length(lengthrange).max(MINVAL)
    }
}

/// Active force–length curve (`mju_muscleGainLength`): two pairs of half-quadratics, 1 at L = 1,
/// zero outside `[lmin, lmax]`.
pub fn force_length(l: f64, lmin: f64, lmax: f64) -> f64 {
    if l < lmin || l > lmax {
        return 0.0;
    }
    let a = 0.5 * (lmin + 1.0);
    let b = 0.5 * (1.0 + lmax);
    if l <= a {
        let x = (l - lmin) / (a - lmin).max(MINVAL);
        0.5 * x * x
    } else if l <= 1.0 {
        let x = (1.0 - l) / (1.0 - a).max(MINVAL);
        1.0 - 0.5 * x * x
    } else if l <= b {
        let x = (l - 1.0) / (b - 1.0).max(MINVAL);
        1.0 - 0.5 * x * x
    } else {
        let x = (lmax - l) / (lmax - b).max(MINVAL);
        0.5 * x * x
    }
}

/// Force–velocity curve on the normalised velocity `v = vel / (L0·vmax)`: 0 below −1, quadratic
/// rise to 1 at rest, quadratic to `fvmax` when lengthening.
pub fn force_velocity(v: f64, fvmax: f64) -> f64 {
    let y = fvmax - 1.0;
    if v <= -1.0 {
        0.0
    } else if v <= 0.0 {
        (v + 1.0) * (v + 1.0)
    } else if v <= y {
        fvmax - (y - v) * (y - v) / y.max(MINVAL)
    } else {
        fvmax
    }
}

/// Passive force–length curve (relative): zero up to L = 1, half-quadratic to `fpmax/2` at
/// `b = (1 + lmax)/2`, linear beyond.
pub fn force_passive(l: f64, lmax: f64, fpmax: f64) -> f64 {
    let b = 0.5 * (1.0 + lmax);
    if l <= 1.0 {
        0.0
    } else if l <= b {
        let x = (l - 1.0) / (b - 1.0).max(MINVAL);
        fpmax * 0.5 * x * x
    } else {
        let x = (l - b) / (b - 1.0).max(MINVAL);
        fpmax * (0.5 + x)
    }
}

/// MuJoCo's muscle gain `−F·FL(L)·FV(V)` (N per unit activation) at tendon length `len` and
/// velocity `vel`.
pub fn gain(p: &MuscleParams, len: f64, vel: f64, lengthrange: [f64; 2], acc0: f64) -> f64 {
    let f = p.peak_force(acc0);
    let l0 = p.optimal_length(lengthrange);
    let l = p.range[0] + (len - lengthrange[0]) / l0.max(MINVAL);
    let v = vel / (l0 * p.vmax).max(MINVAL);
    -f * force_length(l, p.lmin, p.lmax) * force_velocity(v, p.fvmax)
}

/// MuJoCo's muscle bias `−F·FP(L)` (N), the passive force.
pub fn bias(p: &MuscleParams, len: f64, lengthrange: [f64; 2], acc0: f64) -> f64 {
    let f = p.peak_force(acc0);
    let l = p.normalized_length(len, lengthrange);
    -f * force_passive(l, p.lmax, p.fpmax)
}

/// Activation time constants and smoothing, MuJoCo's `dynprm` for a muscle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActivationParams {
    /// Activation time constant, s (default 0.01).
    pub tau_act: f64,
    /// Deactivation time constant, s (default 0.04).
    pub tau_deact: f64,
    /// Width of the smooth switch between the two, in control units (0: hard switch).
    pub smoothing: f64,
}

impl ActivationParams {
    /// MuJoCo's defaults: 0.01 s, 0.04 s, hard switch.
    pub const DEFAULT: ActivationParams = ActivationParams {
        tau_act: 0.01,
        tau_deact: 0.04,
        smoothing: 0.0,
    };
}

/// `d act / dt` (`mju_muscleDynamics`): `(u − act)/τ` with `τ = τ_act·(0.5 + 1.5·act)` when
/// activating and `τ_deact/(0.5 + 1.5·act)` when not, control and activation clamped to [0, 1] for τ.
pub fn activation_rate(ctrl: f64, act: f64, p: &ActivationParams) -> f64 {
    (ctrl.clamp(0.0, 1.0) - act) / time_constant(ctrl, act, p)
}

/// The time constant τ of [`activation_rate`] for control `ctrl` at activation `act`, s (at least
/// `MINVAL`): the one place its formula is written (K-MAC inverts the dynamics with it).
pub fn time_constant(ctrl: f64, act: f64, p: &ActivationParams) -> f64 {
    let u = ctrl.clamp(0.0, 1.0);
    let a = act.clamp(0.0, 1.0);
    let tau_act = p.tau_act * (0.5 + 1.5 * a);
    let tau_deact = p.tau_deact / (0.5 + 1.5 * a);
    let d = u - act;
    let tau = if p.smoothing < MINVAL {
        if d > 0.0 {
            tau_act
        } else {
            tau_deact
        }
    } else {
        tau_deact + (tau_act - tau_deact) * sigmoid(d / p.smoothing + 0.5)
    };
    tau.max(MINVAL)
}

/// MuJoCo's `mju_sigmoid`: quintic smoothstep on [0, 1].
fn sigmoid(x: f64) -> f64 {
    if x <= 0.0 {
        0.0
    } else if x >= 1.0 {
        1.0
    } else {
        x * x * x * (3.0 * x * (2.0 * x - 5.0) + 10.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn force_length_peaks_at_one_and_vanishes_outside() {
        let (lmin, lmax) = (0.5, 1.6);
        assert_eq!(force_length(1.0, lmin, lmax), 1.0);
        assert_eq!(force_length(0.49, lmin, lmax), 0.0);
        assert_eq!(force_length(1.61, lmin, lmax), 0.0);
        // Half-way points of each quadratic piece: a = 0.75, b = 1.3.
        assert!((force_length(0.75, lmin, lmax) - 0.5).abs() < 1e-15);
        assert!((force_length(1.3, lmin, lmax) - 0.5).abs() < 1e-15);
        // Continuity at the joins.
        for x in [0.75, 1.0, 1.3] {
            assert!(
                (force_length(x - 1e-9, lmin, lmax) - force_length(x + 1e-9, lmin, lmax)).abs()
                    < 1e-7
            );
        }
    }

    #[test]
    fn force_velocity_and_passive_closed_forms() {
        assert_eq!(force_velocity(0.0, 1.2), 1.0);
        assert_eq!(force_velocity(-1.0, 1.2), 0.0);
        assert!((force_velocity(-0.5, 1.2) - 0.25).abs() < 1e-15);
        assert_eq!(force_velocity(5.0, 1.2), 1.2);
        assert!((force_velocity(0.1, 1.2) - (1.2 - 0.01 / 0.2)).abs() < 1e-12);
        assert_eq!(force_passive(1.0, 1.6, 1.3), 0.0);
        assert!((force_passive(1.3, 1.6, 1.3) - 0.65).abs() < 1e-12);
        assert!((force_passive(1.6, 1.6, 1.3) - 1.3 * 1.5).abs() < 1e-12);
    }

    #[test]
    fn gain_and_bias_at_rest_length() {
        let p = MuscleParams {
            force: 100.0,
            ..MuscleParams::DEFAULT
        };
        let lr = [0.2, 0.26];
        // L0 = 0.06 / 0.3 = 0.2; L = 1 at len = lr0 + 0.25·L0 = 0.25.
        assert!((p.optimal_length(lr) - 0.2).abs() < 1e-15);
        assert!((gain(&p, 0.25, 0.0, lr, 0.0) + 100.0).abs() < 1e-9);
        assert_eq!(bias(&p, 0.25, lr, 0.0), 0.0);
        // Shortening at vmax·L0 gives no active force.
        assert_eq!(gain(&p, 0.25, -1.5 * 0.2, lr, 0.0), 0.0);
        // force < 0 → scale / acc0.
        let q = MuscleParams::DEFAULT;
        assert!((q.peak_force(4.0) - 50.0).abs() < 1e-12);
    }

    #[test]
    fn activation_dynamics_matches_the_paper() {
        let p = ActivationParams::DEFAULT;
        // Activating from 0: τ = 0.01·0.5.
        assert!((activation_rate(1.0, 0.0, &p) - 1.0 / 0.005).abs() < 1e-9);
        // Deactivating from 1: τ = 0.04 / 2.
        assert!((activation_rate(0.0, 1.0, &p) + 1.0 / 0.02).abs() < 1e-9);
        // Controls outside [0, 1] are clamped.
        assert_eq!(activation_rate(2.0, 0.3, &p), activation_rate(1.0, 0.3, &p));
    }
}
