//! K-MAC, the paper's Kinematics-based Muscle Actuation Controller (docs/design.md §6): target joint
//! positions → muscle lengths by forward kinematics → length PD → activation → control; and the
//! gravity feed-forward for callers that hold postures.

use nalgebra::DVector;
use sim::dynamics::State;
use sim::model::{Dynamics, JointKind, Model, Transmission};
use sim::muscle;

use super::*;

/// Steps 2–4 of K-MAC for one muscle (docs/design.md §6): PD force on length, clipped to pulling, and
/// the activation that produces it with the simulator's own gain and bias (gain limited to ≤ −1 N),
/// in [0, 1]. `None` for an actuator that is not a muscle.
pub fn activation_target(
    model: &Model,
    a: usize,
    l_target: f64,
    now: &MuscleNow,
    gains: &PdGains,
) -> Option<f64> {
    let (l, l_dot) = (now.length, now.velocity);
    let actuator = &model.actuators[a];
    let p = actuator.muscle()?;
    let lr = actuator.lengthrange;
    let f_max = p.peak_force(0.0);
    let dl = (lr[1] - lr[0]).max(1e-9);
    let f = f_max * (gains.kp * (l_target - l) - gains.kd * l_dot) / dl;
    let f_star = f.clamp(-f_max, 0.0);
    let gain = muscle::gain(p, l, l_dot, lr, 0.0).min(-1.0);
    let bias = muscle::bias(p, l, lr, 0.0);
    Some(((f_star - bias) / gain).clamp(0.0, 1.0))
}

/// Steps 2–5 of K-MAC for one muscle: [`activation_target`], then the control that reaches that
/// activation in one control step `dt` by inverting the activation dynamics.
pub fn muscle_pd_control(
    model: &Model,
    a: usize,
    l_target: f64,
    now: &MuscleNow,
    gains: &PdGains,
    dt: f64,
) -> f64 {
    let Some(act_star) = activation_target(model, a, l_target, now, gains) else {
        return 0.0;
    };
    let tau = match model.actuators[a].dynamics {
        Dynamics::Muscle(d) => muscle::time_constant(act_star, now.act, &d),
        Dynamics::None => return act_star,
    };
    (now.act + (act_star - now.act) * tau / dt).clamp(0.0, 1.0)
}

/// The official code's activation clamp, [σ(−7.5), σ(2.5)] ≈ [0.00055, 0.924]: its K-MAC sends the
/// activation target itself as the control, within these bounds.
pub fn official_activation_clamp() -> [f64; 2] {
    let sigmoid = |x: f64| 1.0 / (1.0 + sim::math::exp(-x));
    [sigmoid(-7.5), sigmoid(2.5)]
}

/// `E[clamp(mu + sigma·Z, lo, hi)]` for a standard normal `Z`: the mean control that Gaussian noise
/// of `sigma` on `mu` gives once clamped (the noise is rectified at the bounds, so the mean moves
/// towards the interval's inside: `mu = lo` becomes about `lo + sigma/√(2π)`). `sigma` not a
/// positive finite number: the clamp itself.
pub fn clamped_normal_mean(mu: f64, sigma: f64, lo: f64, hi: f64) -> f64 {
    if !(sigma > 0.0 && sigma.is_finite()) {
        return mu.clamp(lo, hi);
    }
    let cdf = |x: f64| 0.5 * libm::erfc(-x * std::f64::consts::FRAC_1_SQRT_2);
    let pdf = |x: f64| sim::math::exp(-0.5 * x * x) / (2.0 * std::f64::consts::PI).sqrt();
    let (alpha, beta) = ((lo - mu) / sigma, (hi - mu) / sigma);
    let (below, above) = (cdf(alpha), cdf(-beta));
    let mean =
        lo * below + hi * above + mu * (1.0 - below - above) + sigma * (pdf(alpha) - pdf(beta));
    mean.clamp(lo, hi)
}

/// K-MAC: target joint positions → muscle controls.
#[derive(Debug, Clone)]
pub struct Kmac {
    /// Action layout.
    pub space: ActionSpace,
    /// Length PD gains.
    pub gains: PdGains,
    /// The official code's form: the activation target is the control, clamped to these bounds
    /// (see [`official_activation_clamp`]); `None`: ours, the control that reaches the target in
    /// one control step (the activation dynamics inverted), in [0, 1].
    pub activation_clamp: Option<[f64; 2]>,
    /// Training noise on the activations: σ and its seeded stream (the official code's 0.1).
    activation_noise: Option<(f64, sim::rng::Rng)>,
    /// Play without draws (a checkpoint's mean action): the σ of the activation noise the policy
    /// was trained with, played as its expectation (each control is [`clamped_normal_mean`] of the
    /// noiseless one: the mean control of training, only a first-order match of its activations,
    /// whose dynamics rise faster than they fall); ignored while the noise is drawn.
    pub expected_activation_noise: Option<f64>,
    /// The official code's form: a coupled joint's target, its equality's polynomial of the
    /// independent joint's target, is clamped to the coupled joint's range (on MyoSuite's robot the
    /// lumbar flexion couplings leave their ranges over 12–31% of the flexion range); `false`: the
    /// polynomial's value as it is (the checkpoints trained before the setting).
    pub clamp_coupled: bool,
    target: MuscleGeometry,
    current: MuscleGeometry,
    qpos_target: Vec<f64>,
}

impl Kmac {
    /// K-MAC for `model`.
    pub fn new(model: &Model, gains: PdGains) -> Kmac {
        Kmac {
            space: ActionSpace::new(model),
            gains,
            activation_clamp: None,
            activation_noise: None,
            expected_activation_noise: None,
            clamp_coupled: false,
            target: MuscleGeometry::new(model),
            current: MuscleGeometry::new(model),
            qpos_target: model.qpos0.clone(),
        }
    }

    /// K-MAC in the official code's form when `clamp` is given (see [`Kmac::activation_clamp`]).
    pub fn with_activation_clamp(mut self, clamp: Option<[f64; 2]>) -> Kmac {
        self.activation_clamp = clamp;
        self
    }

    /// Clamps coupled joints' targets to their ranges when `clamp` (see [`Kmac::clamp_coupled`]).
    pub fn with_clamp_coupled(mut self, clamp: bool) -> Kmac {
        self.clamp_coupled = clamp;
        self
    }

    /// Plays the expectation of activation noise of `sigma` (see [`Kmac::expected_activation_noise`]).
    pub fn with_expected_activation_noise(mut self, sigma: Option<f64>) -> Kmac {
        self.expected_activation_noise = sigma.filter(|&s| s > 0.0 && s.is_finite());
        self
    }

    /// Adds Gaussian noise of `sigma` to every muscle's activation target (before the clamp), drawn
    /// from a stream seeded with `seed` (training only; `sigma = 0` removes it).
    pub fn set_activation_noise(&mut self, sigma: f64, seed: u64) {
        self.activation_noise = (sigma > 0.0).then(|| (sigma, sim::rng::Rng::seeded(seed)));
    }

    /// The full target configuration K-MAC's lengths come from: `state`'s positions with the
    /// targets of `space.joints` set, the couplings applied (each coupled joint's target clamped to
    /// its range when [`Kmac::clamp_coupled`]).
    pub fn target_configuration(
        &mut self,
        model: &Model,
        state: &State,
        targets: &[f64],
    ) -> &[f64] {
        self.qpos_target.copy_from_slice(&state.qpos);
        for (&j, &z) in self.space.joints.iter().zip(targets) {
            self.qpos_target[model.joints[j].qpos_adr] = z;
        }
        model.apply_couplings(&mut self.qpos_target);
        if self.clamp_coupled {
            for c in &model.couplings {
                let joint = &model.joints[c.dependent];
                if let Some([lo, hi]) = joint.range {
                    let q = &mut self.qpos_target[joint.qpos_adr];
                    *q = q.clamp(lo, hi);
                }
            }
        }
        &self.qpos_target
    }

    /// Writes controls for every actuator into `ctrl`, given target positions of `space.joints`.
    pub fn controls(
        &mut self,
        model: &Model,
        state: &State,
        targets: &[f64],
        dt: f64,
        ctrl: &mut [f64],
    ) {
        // 1. The full target configuration (couplings applied) and its muscle lengths.
        self.target_configuration(model, state, targets);
        self.target.update_lengths(model, &self.qpos_target);
        self.current.update(model, &state.qpos);
        // 2–5 per muscle.
        for &a in &self.space.muscles {
            let l_star = self.target.length(model, a, &self.qpos_target);
            let now = self.current.now(model, a, state);
            let noise = match &mut self.activation_noise {
                Some((sigma, rng)) => *sigma * rng.normal(),
                None => 0.0,
            };
            let (target, [lo, hi]) = match self.activation_clamp {
                None => (
                    Some(muscle_pd_control(model, a, l_star, &now, &self.gains, dt)),
                    [0.0, 1.0],
                ),
                Some(bounds) => (
                    activation_target(model, a, l_star, &now, &self.gains),
                    bounds,
                ),
            };
            ctrl[a] = match (target, self.expected_activation_noise) {
                (None, _) => 0.0,
                (Some(u), _) if self.activation_noise.is_some() => (u + noise).clamp(lo, hi),
                (Some(u), Some(sigma)) => clamped_normal_mean(u, sigma, lo, hi),
                (Some(u), None) => u.clamp(lo, hi),
            };
        }
        // The pelvis follows its servos.
        for (servo, &z) in self.space.servos.iter().zip(targets) {
            if let Some(s) = servo {
                ctrl[*s] = z;
            }
        }
    }
}

/// The joint-target offset that lets K-MAC hold `qpos` still against gravity and the joints' passive
/// springs (a static feed-forward for callers that track postures, e.g. the scripted agent).
///
/// Near a target, K-MAC's muscle forces are `f_i = F_i·k_p·r_iᵀ(z* − z)/Δl_i` (moment arms `r_i`), a
/// joint stiffness `K = Σ F_i·k_p/Δl_i · r_i r_iᵀ`, of which about half acts (muscles only pull: one of
/// each antagonist pair). Holding `z` needs the muscle torque `τ = G(z) − τ_passive(z)`, so the target
/// must lead by `Δz = (K/2)⁻¹ τ`. Returned per `space.joints` entry (zero for servo joints and `skip`).
pub fn gravity_offset(
    model: &Model,
    data: &mut sim::dynamics::Data,
    space: &ActionSpace,
    gains: &PdGains,
    qpos: &[f64],
    skip: &[usize],
) -> Vec<f64> {
    let nv = model.nv;
    data.positions(model, qpos);
    data.velocities(model, &vec![0.0; nv]);
    data.update_couplings(model, qpos, &vec![0.0; nv]);
    // Torque the muscles must supply, in all dofs: gravity minus the passive springs' help.
    let mut tau = data.bias.clone();
    for j in &model.joints {
        if j.kind != JointKind::Free {
            tau[j.dof_adr] -= -j.stiffness * (qpos[j.qpos_adr] - j.springref);
        }
    }
    // Joint stiffness of the muscles under K-MAC, in all dofs.
    let mut k: nalgebra::DMatrix<f64> = nalgebra::DMatrix::zeros(nv, nv);
    for &a in &space.muscles {
        let act = &model.actuators[a];
        let (Some(p), Transmission::Tendon(t)) = (act.muscle(), act.transmission) else {
            continue;
        };
        let c = 0.5 * p.peak_force(0.0) * gains.kp
            / (act.lengthrange[1] - act.lengthrange[0]).max(1e-9);
        let (dofs, moment) = (&data.ten.dofs[t], data.ten.moment_arms(t));
        for &i in dofs {
            for &j in dofs {
                k[(i, j)] += c * moment[i] * moment[j];
            }
        }
    }
    // Reduce to the action joints that muscles drive.
    let chosen: Vec<usize> = (0..space.joints.len())
        .filter(|&i| space.servos[i].is_none() && !skip.contains(&space.joints[i]))
        .collect();
    let column = |i: usize| -> Vec<(usize, f64)> {
        let dof = model.joints[space.joints[i]].dof_adr;
        let r = data
            .independent_dofs
            .iter()
            .position(|&d| d == dof)
            .expect("independent joint");
        data.coupling_columns[r].clone()
    };
    let cols: Vec<Vec<(usize, f64)>> = chosen.iter().map(|&i| column(i)).collect();
    let n = chosen.len();
    let mut kr: nalgebra::DMatrix<f64> = nalgebra::DMatrix::zeros(n, n);
    let mut tr: DVector<f64> = DVector::zeros(n);
    for a in 0..n {
        tr[a] = cols[a].iter().map(|&(i, w)| w * tau[i]).sum::<f64>();
        for b in 0..n {
            let mut v = 0.0;
            for &(i, wa) in &cols[a] {
                for &(j, wb) in &cols[b] {
                    v += wa * wb * k[(i, j)];
                }
            }
            kr[(a, b)] = v;
        }
        kr[(a, a)] += 1e-3;
    }
    let dz = kr
        .cholesky()
        .map(|ch| ch.solve(&tr))
        .unwrap_or_else(|| DVector::zeros(n));
    let mut out = vec![0.0; space.joints.len()];
    for (a, &i) in chosen.iter().enumerate() {
        out[i] = dz[a].clamp(-0.5, 0.5);
    }
    out
}
