//! From a policy's action to muscle controls (DESIGN §6): K-MAC (the paper's Diff-Muscle: target
//! joint positions), Muscle-PD (MuscleVAE-style: target muscle lengths), Direct (Muscle-PPO: the
//! controls themselves) and DynSyn (synergy groups plus per-muscle weights). Every controller also
//! sets the two pelvis position servos.
//!
//! Actions here are in physical units (rad, m, activations); a policy's normalisation lives in its
//! checkpoint. Controllers keep their own kinematics workspaces; they read the robot's state, never
//! write it.

use nalgebra::DVector;
use serde::{Deserialize, Serialize};
use sim::dynamics::State;
use sim::kinematics::{Kinematics, TendonKinematics};
use sim::model::{Dynamics, JointKind, Model, Transmission};
use sim::muscle;

/// Which controller a checkpoint drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ControllerKind {
    /// The paper's Kinematics-based Muscle Actuation Controller: target joint positions.
    Kmac,
    /// MuscleVAE-style PD on muscle length: target muscle lengths.
    MusclePd,
    /// Muscle-PPO: every muscle's control directly.
    Direct,
    /// DynSyn: one value per synergy group plus a weight per muscle.
    Dynsyn,
}

/// PD gains on muscle length in the paper's form: `f = F·(K_p·(l* − l) − K_d·l̇)/Δl`. (The official
/// code multiplies K_d by K_p; converting is one multiplication.)
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PdGains {
    /// Proportional gain (per length range).
    pub kp: f64,
    /// Derivative gain, s (per length range).
    pub kd: f64,
}

impl PdGains {
    /// Muscle-PD's official defaults.
    pub const MUSCLE_PD: PdGains = PdGains { kp: 10.0, kd: 1.0 };
}

/// The robot's action layout: the independent joints a joint-space action targets, the muscles, and
/// the pelvis servos.
#[derive(Debug, Clone, PartialEq)]
pub struct ActionSpace {
    /// Independent hinge and slide joints, in model order.
    pub joints: Vec<usize>,
    /// For each of `joints`, the position servo that drives it directly (the pelvis), if any.
    pub servos: Vec<Option<usize>>,
    /// Muscles (actuators with muscle gain), in model order.
    pub muscles: Vec<usize>,
}

impl ActionSpace {
    /// The action space of `model`.
    pub fn new(model: &Model) -> ActionSpace {
        let joints: Vec<usize> = (0..model.joints.len())
            .filter(|&j| model.joints[j].kind != JointKind::Free && !model.is_dependent(j))
            .collect();
        let servos = joints
            .iter()
            .map(|&j| {
                model
                    .actuators
                    .iter()
                    .position(|a| a.transmission == Transmission::Joint(j) && a.muscle().is_none())
            })
            .collect();
        let muscles = model.muscles().map(|(i, _)| i).collect();
        ActionSpace {
            joints,
            servos,
            muscles,
        }
    }

    /// The servo-driven joints (the pelvis): (joint, servo actuator).
    pub fn servo_joints(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        self.joints
            .iter()
            .zip(&self.servos)
            .filter_map(|(&j, s)| s.map(|s| (j, s)))
    }
}

/// Muscle lengths and velocities at a state.
#[derive(Debug, Clone)]
struct MuscleGeometry {
    kin: Kinematics,
    ten: TendonKinematics,
}

impl MuscleGeometry {
    fn new(model: &Model) -> MuscleGeometry {
        MuscleGeometry {
            kin: Kinematics::new(model),
            ten: TendonKinematics::new(model),
        }
    }

    fn update(&mut self, model: &Model, qpos: &[f64]) {
        self.kin.update(model, qpos);
        self.ten.update(model, &self.kin);
    }

    fn length(&self, model: &Model, a: usize, qpos: &[f64]) -> f64 {
        sim::kinematics::actuator_length(model, model.actuators[a].transmission, &self.ten, qpos)
    }

    fn velocity(&self, model: &Model, a: usize, qvel: &[f64]) -> f64 {
        match model.actuators[a].transmission {
            Transmission::Tendon(t) => self.ten.velocity(t, qvel),
            Transmission::Joint(j) => qvel[model.joints[j].dof_adr],
        }
    }

    fn now(&self, model: &Model, a: usize, state: &State) -> MuscleNow {
        MuscleNow {
            length: self.length(model, a, &state.qpos),
            velocity: self.velocity(model, a, &state.qvel),
            act: state.act[a],
        }
    }
}

/// A muscle's present length (m), lengthening speed (m/s) and activation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MuscleNow {
    /// Length, m.
    pub length: f64,
    /// Lengthening speed, m/s.
    pub velocity: f64,
    /// Activation.
    pub act: f64,
}

/// Steps 2–5 of K-MAC for one muscle (DESIGN §6): PD force on length, clipped to pulling, the
/// activation that produces it with the simulator's own gain and bias (gain limited to ≤ −1 N), and
/// the control that reaches that activation in one control step `dt` by inverting the activation
/// dynamics.
pub fn muscle_pd_control(
    model: &Model,
    a: usize,
    l_target: f64,
    now: &MuscleNow,
    gains: &PdGains,
    dt: f64,
) -> f64 {
    let (l, l_dot, act) = (now.length, now.velocity, now.act);
    let actuator = &model.actuators[a];
    let Some(p) = actuator.muscle() else {
        return 0.0;
    };
    let lr = actuator.lengthrange;
    let f_max = p.peak_force(0.0);
    let dl = (lr[1] - lr[0]).max(1e-9);
    let f = f_max * (gains.kp * (l_target - l) - gains.kd * l_dot) / dl;
    let f_star = f.clamp(-f_max, 0.0);
    let gain = muscle::gain(p, l, l_dot, lr, 0.0).min(-1.0);
    let bias = muscle::bias(p, l, lr, 0.0);
    let act_star = ((f_star - bias) / gain).clamp(0.0, 1.0);
    let tau = match actuator.dynamics {
        Dynamics::Muscle(d) => muscle::time_constant(act_star, act, &d),
        Dynamics::None => return act_star,
    };
    (act + (act_star - act) * tau / dt).clamp(0.0, 1.0)
}

/// K-MAC: target joint positions → muscle controls.
#[derive(Debug, Clone)]
pub struct Kmac {
    /// Action layout.
    pub space: ActionSpace,
    /// Length PD gains.
    pub gains: PdGains,
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
            target: MuscleGeometry::new(model),
            current: MuscleGeometry::new(model),
            qpos_target: model.qpos0.clone(),
        }
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
        self.qpos_target.copy_from_slice(&state.qpos);
        for (&j, &z) in self.space.joints.iter().zip(targets) {
            self.qpos_target[model.joints[j].qpos_adr] = z;
        }
        model.apply_couplings(&mut self.qpos_target);
        self.target.update(model, &self.qpos_target);
        self.current.update(model, &state.qpos);
        // 2–5 per muscle.
        for &a in &self.space.muscles {
            let l_star = self.target.length(model, a, &self.qpos_target);
            let now = self.current.now(model, a, state);
            ctrl[a] = muscle_pd_control(model, a, l_star, &now, &self.gains, dt);
        }
        // The pelvis follows its servos.
        for (servo, &z) in self.space.servos.iter().zip(targets) {
            if let Some(s) = servo {
                ctrl[*s] = z;
            }
        }
    }
}

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

/// Muscle-PPO's control for an action entry, as the official code maps it: `sigmoid(5·(a − 0.5))`
/// (a ∈ [−1, 1] → u ∈ [0.0006, 0.92]; a = 0 asks for 0.08).
pub fn direct_control(a: f64) -> f64 {
    1.0 / (1.0 + (-5.0 * (a.clamp(-1.0, 1.0) - 0.5)).exp())
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

/// DynSyn's synergy groups: which group each muscle belongs to.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Synergies {
    /// Group index of each muscle (in `ActionSpace::muscles` order).
    pub group_of: Vec<usize>,
    /// Number of groups.
    pub groups: usize,
}

impl Synergies {
    /// DynSyn controls: muscle `i` gets `clip(group_value[g(i)] · weight[i], 0, 1)`, the weights being
    /// the policy's state-dependent per-muscle outputs (1 = the group's value as is).
    pub fn controls(
        &self,
        space: &ActionSpace,
        group_values: &[f64],
        weights: &[f64],
        pelvis: &[f64],
        ctrl: &mut [f64],
    ) {
        for (k, &a) in space.muscles.iter().enumerate() {
            let g = self.group_of[k];
            ctrl[a] = (group_values[g] * weights[k]).clamp(0.0, 1.0);
        }
        for ((_, s), &t) in space.servo_joints().zip(pelvis) {
            ctrl[s] = t;
        }
    }

    /// DynSyn's grouping from the dynamics (He et al. 2024): drive the joints at random velocities with
    /// zero muscle action, record every muscle's length, correlate the length signals over windows, and
    /// cluster the muscles by k-medoids on `1 − |correlation|`. Deterministic in `seed`.
    pub fn derive(model: &Model, groups: usize, seed: u64) -> Synergies {
        let space = ActionSpace::new(model);
        let m = space.muscles.len();
        let groups = groups.clamp(1, m.max(1));
        let mut rng = sim::rng::Rng::seeded(seed);
        let mut geometry = MuscleGeometry::new(model);
        let mut q = model.qpos0.clone();
        model.apply_couplings(&mut q);
        // Random joint-velocity drive: every 0.1 s a new velocity within the joint ranges' scale.
        let steps = 600;
        let h = sim::arena::CONTROL_DT;
        let mut samples = vec![Vec::with_capacity(steps); m];
        let mut vel = vec![0.0; space.joints.len()];
        for k in 0..steps {
            if k % 10 == 0 {
                for v in vel.iter_mut() {
                    *v = rng.uniform(-1.5, 1.5);
                }
            }
            for (i, &j) in space.joints.iter().enumerate() {
                let joint = &model.joints[j];
                let adr = joint.qpos_adr;
                let mut x = q[adr] + vel[i] * h;
                if let Some([lo, hi]) = joint.range {
                    if x < lo || x > hi {
                        vel[i] = -vel[i];
                        x = x.clamp(lo, hi);
                    }
                }
                q[adr] = x;
            }
            model.apply_couplings(&mut q);
            geometry.update(model, &q);
            for (i, &a) in space.muscles.iter().enumerate() {
                samples[i].push(geometry.length(model, a, &q));
            }
        }
        // Correlation of length changes over windows of 100 samples, averaged.
        let window = 100;
        let mut distance = vec![vec![0.0; m]; m];
        let windows = steps / window;
        for w in 0..windows {
            let seg: Vec<DVector<f64>> = samples
                .iter()
                .map(|s| {
                    let x = DVector::from_iterator(
                        window - 1,
                        (w * window..(w + 1) * window - 1).map(|t| s[t + 1] - s[t]),
                    );
                    let mean = x.mean();
                    let c = x.add_scalar(-mean);
                    let n = c.norm();
                    if n > 1e-15 {
                        c / n
                    } else {
                        c
                    }
                })
                .collect();
            for i in 0..m {
                for j in 0..m {
                    distance[i][j] += (1.0 - seg[i].dot(&seg[j]).abs()) / windows as f64;
                }
            }
        }
        Synergies {
            group_of: k_medoids(&distance, groups),
            groups,
        }
    }
}

/// k-medoids (PAM-style swaps from a greedy start) on a distance matrix; returns each item's cluster.
fn k_medoids(distance: &[Vec<f64>], k: usize) -> Vec<usize> {
    let n = distance.len();
    // Greedy start: the most central item, then repeatedly the item farthest from the chosen ones.
    let mut medoids = vec![(0..n)
        .min_by(|&a, &b| {
            distance[a]
                .iter()
                .sum::<f64>()
                .total_cmp(&distance[b].iter().sum::<f64>())
        })
        .unwrap_or(0)];
    while medoids.len() < k {
        let next = (0..n)
            .filter(|i| !medoids.contains(i))
            .max_by(|&a, &b| {
                let da = medoids
                    .iter()
                    .map(|&m| distance[a][m])
                    .fold(f64::INFINITY, f64::min);
                let db = medoids
                    .iter()
                    .map(|&m| distance[b][m])
                    .fold(f64::INFINITY, f64::min);
                da.total_cmp(&db)
            })
            .expect("k ≤ n");
        medoids.push(next);
    }
    let cost = |med: &[usize]| -> f64 {
        (0..n)
            .map(|i| {
                med.iter()
                    .map(|&m| distance[i][m])
                    .fold(f64::INFINITY, f64::min)
            })
            .sum()
    };
    let mut best = cost(&medoids);
    loop {
        let mut improved = false;
        for slot in 0..medoids.len() {
            for cand in 0..n {
                if medoids.contains(&cand) {
                    continue;
                }
                let old = medoids[slot];
                medoids[slot] = cand;
                let c = cost(&medoids);
                if c + 1e-12 < best {
                    best = c;
                    improved = true;
                } else {
                    medoids[slot] = old;
                }
            }
        }
        if !improved {
            break;
        }
    }
    (0..n)
        .map(|i| {
            (0..medoids.len())
                .min_by(|&a, &b| distance[i][medoids[a]].total_cmp(&distance[i][medoids[b]]))
                .expect("k ≥ 1")
        })
        .collect()
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
        let dofs = &data.ten.dofs[t];
        for &i in dofs {
            for &j in dofs {
                k[(i, j)] += c * data.ten.moment[(t, i)] * data.ten.moment[(t, j)];
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

/// A controller as a checkpoint names it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum ControllerSpec {
    /// K-MAC with its gains in the paper's form.
    Kmac {
        /// Length PD gains.
        gains: PdGains,
    },
    /// Muscle-PD.
    MusclePd {
        /// Length PD gains.
        gains: PdGains,
    },
    /// Muscle-PPO's direct controls.
    Direct,
    /// DynSyn with its synergy groups.
    Dynsyn {
        /// The grouping.
        synergies: Synergies,
    },
}

impl ControllerSpec {
    /// Its kind.
    pub fn kind(&self) -> ControllerKind {
        match self {
            ControllerSpec::Kmac { .. } => ControllerKind::Kmac,
            ControllerSpec::MusclePd { .. } => ControllerKind::MusclePd,
            ControllerSpec::Direct => ControllerKind::Direct,
            ControllerSpec::Dynsyn { .. } => ControllerKind::Dynsyn,
        }
    }
}

/// Turns a policy's action in [−1, 1]ⁿ into muscle and servo controls through a controller:
/// joint targets `mid + a·half-range` over the range widened by [`TARGET_MARGIN`] (±π for
/// unlimited hinges), lengths `lr0 + (a+1)/2·Δl`,
/// Muscle-PPO controls `sigmoid(5(a − 0.5))`, DynSyn values `(a+1)/2` and weights `1 + a`, servo targets over their control ranges.
#[derive(Debug, Clone)]
pub enum ActionMapper {
    /// K-MAC: one target per independent joint.
    Kmac(Box<Kmac>),
    /// Muscle-PD: one length per muscle, then one target per servo.
    MusclePd(Box<MusclePd>),
    /// Direct: one control per muscle, then one target per servo.
    Direct(ActionSpace),
    /// DynSyn: one value per group, one weight per muscle, one target per servo.
    Dynsyn(ActionSpace, Synergies),
}

fn scale(a: f64, lo: f64, hi: f64) -> f64 {
    let a = a.clamp(-1.0, 1.0);
    0.5 * (lo + hi) + a * 0.5 * (hi - lo)
}

fn joint_range(model: &Model, j: usize) -> [f64; 2] {
    model.joints[j]
        .range
        .unwrap_or([-std::f64::consts::PI, std::f64::consts::PI])
}

/// How far past each end of a joint's range a K-MAC target may lie, as a fraction of the range: a
/// target past a stop makes the muscles press against it, as the official model's fingers press on
/// the handle before their joint limit (ours has the handle as the grip joint's stop at 1.0, so
/// without the margin no action could squeeze the paddle).
pub const TARGET_MARGIN: f64 = 0.05;

/// The joint targets a K-MAC action spans: the range widened by [`TARGET_MARGIN`] at both ends.
fn target_range(model: &Model, j: usize) -> [f64; 2] {
    let [lo, hi] = joint_range(model, j);
    let m = TARGET_MARGIN * (hi - lo);
    [lo - m, hi + m]
}

fn servo_range(model: &Model, s: usize, j: usize) -> [f64; 2] {
    model.actuators[s]
        .ctrlrange
        .unwrap_or_else(|| joint_range(model, j))
}

impl ActionMapper {
    /// The mapper for `spec` on `model`.
    pub fn new(model: &Model, spec: &ControllerSpec) -> ActionMapper {
        match spec {
            ControllerSpec::Kmac { gains } => {
                ActionMapper::Kmac(Box::new(Kmac::new(model, *gains)))
            }
            ControllerSpec::MusclePd { gains } => {
                ActionMapper::MusclePd(Box::new(MusclePd::new(model, *gains)))
            }
            ControllerSpec::Direct => ActionMapper::Direct(ActionSpace::new(model)),
            ControllerSpec::Dynsyn { synergies } => {
                ActionMapper::Dynsyn(ActionSpace::new(model), synergies.clone())
            }
        }
    }

    fn space(&self) -> &ActionSpace {
        match self {
            ActionMapper::Kmac(k) => &k.space,
            ActionMapper::MusclePd(m) => &m.space,
            ActionMapper::Direct(s) | ActionMapper::Dynsyn(s, _) => s,
        }
    }

    /// Entries of the action vector.
    pub fn action_dim(&self) -> usize {
        let s = self.space();
        let servos = s.servo_joints().count();
        match self {
            ActionMapper::Kmac(_) => s.joints.len(),
            ActionMapper::MusclePd(_) | ActionMapper::Direct(_) => s.muscles.len() + servos,
            ActionMapper::Dynsyn(_, syn) => syn.groups + s.muscles.len() + servos,
        }
    }

    /// Controls for `action` (length [`ActionMapper::action_dim`], entries in [−1, 1]).
    pub fn controls(
        &mut self,
        model: &Model,
        state: &State,
        action: &[f64],
        dt: f64,
        ctrl: &mut [f64],
    ) {
        let servo_targets = |space: &ActionSpace, a: &[f64]| -> Vec<f64> {
            space
                .servo_joints()
                .zip(a)
                .map(|((j, s), &x)| {
                    let r = servo_range(model, s, j);
                    scale(x, r[0], r[1])
                })
                .collect()
        };
        match self {
            ActionMapper::Kmac(k) => {
                let targets: Vec<f64> = k
                    .space
                    .joints
                    .iter()
                    .zip(&k.space.servos)
                    .zip(action)
                    .map(|((&j, servo), &a)| {
                        let r = match servo {
                            Some(s) => servo_range(model, *s, j),
                            None => target_range(model, j),
                        };
                        scale(a, r[0], r[1])
                    })
                    .collect();
                k.controls(model, state, &targets, dt, ctrl);
            }
            ActionMapper::MusclePd(m) => {
                let n = m.space.muscles.len();
                let lengths: Vec<f64> = m
                    .space
                    .muscles
                    .iter()
                    .zip(&action[..n])
                    .map(|(&a, &x)| {
                        let lr = model.actuators[a].lengthrange;
                        lr[0] + 0.5 * (x.clamp(-1.0, 1.0) + 1.0) * (lr[1] - lr[0])
                    })
                    .collect();
                let pelvis = servo_targets(&m.space, &action[n..]);
                m.controls(model, state, &lengths, &pelvis, dt, ctrl);
            }
            ActionMapper::Direct(space) => {
                let n = space.muscles.len();
                let u: Vec<f64> = action[..n].iter().map(|&x| direct_control(x)).collect();
                let pelvis = servo_targets(space, &action[n..]);
                direct_controls(space, &u, &pelvis, ctrl);
            }
            ActionMapper::Dynsyn(space, syn) => {
                let (g, n) = (syn.groups, space.muscles.len());
                let values: Vec<f64> = action[..g]
                    .iter()
                    .map(|x| 0.5 * (x.clamp(-1.0, 1.0) + 1.0))
                    .collect();
                let weights: Vec<f64> = action[g..g + n]
                    .iter()
                    .map(|x| 1.0 + x.clamp(-1.0, 1.0))
                    .collect();
                let pelvis = servo_targets(space, &action[g + n..]);
                syn.controls(space, &values, &weights, &pelvis, ctrl);
            }
        }
    }
}

/// Keeps the grip muscles' controls at `floor` or above, whatever the controller asked: a trained
/// checkpoint's `grip_floor` (the house agent does the same with its `grip_activation`). Our grip
/// holds by the squeeze of three flexors; a policy trained with exploration noise gets that squeeze
/// from the noise itself (muscles only pull, so jittered targets co-contract), and its noise-free
/// mean action then lets the paddle slip — the floor keeps evaluation what training saw.
pub fn apply_grip_floor(robot: &sim::robot::Robot, floor: f64, ctrl: &mut [f64]) {
    if floor > 0.0 {
        for &m in robot.grip_muscles() {
            ctrl[m] = ctrl[m].max(floor);
        }
    }
}
