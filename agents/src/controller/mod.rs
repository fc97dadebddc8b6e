//! From a policy's action to muscle controls (docs/design.md §6): K-MAC (the paper's Diff-Muscle: target
//! joint positions), Muscle-PD (MuscleVAE-style: target muscle lengths), Direct (Muscle-PPO: the
//! controls themselves) and DynSyn (synergy groups plus per-muscle weights). Every controller also
//! sets the two pelvis position servos.
//!
//! Actions here are in physical units (rad, m, activations); a policy's normalisation lives in its
//! checkpoint. Controllers keep their own kinematics workspaces; they read the robot's state, never
//! write it.
//!
//! One file per controller: [`kmac`], [`muscle_pd`], [`direct`], [`dynsyn`]; here the action
//! layout, the checkpoint's controller spec and the mapping from a policy's action.

mod direct;
mod dynsyn;
mod kmac;
mod muscle_pd;

pub use direct::{direct_control, direct_controls};
pub use dynsyn::Synergies;
pub use kmac::{
    activation_target, clamped_normal_mean, gravity_offset, muscle_pd_control,
    official_activation_clamp, Kmac,
};
pub use muscle_pd::MusclePd;

use serde::{Deserialize, Serialize};
use sim::dynamics::State;
use sim::kinematics::{Kinematics, TendonKinematics};
use sim::model::{JointKind, Model, Transmission};

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
pub(crate) struct MuscleGeometry {
    kin: Kinematics,
    ten: TendonKinematics,
}

impl MuscleGeometry {
    pub(crate) fn new(model: &Model) -> MuscleGeometry {
        MuscleGeometry {
            kin: Kinematics::new(model),
            ten: TendonKinematics::new(model),
        }
    }

    fn update(&mut self, model: &Model, qpos: &[f64]) {
        self.kin.update(model, qpos);
        self.ten.update(model, &self.kin);
    }

    /// [`MuscleGeometry::update`] for [`MuscleGeometry::length`] alone (no moment arms, so no
    /// velocities).
    fn update_lengths(&mut self, model: &Model, qpos: &[f64]) {
        self.kin.update(model, qpos);
        self.ten.update_lengths(&self.kin);
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

    pub(crate) fn now(&self, model: &Model, a: usize, state: &State) -> MuscleNow {
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

/// A controller as a checkpoint names it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum ControllerSpec {
    /// K-MAC with its gains in the paper's form.
    Kmac {
        /// Length PD gains.
        gains: PdGains,
        /// The official code's form: the joint targets span each joint's range exactly and the
        /// activation target is the control, clamped to these bounds (its [σ(−7.5), σ(2.5)]);
        /// absent: ours, targets over the range widened by [`TARGET_MARGIN`] and the control that
        /// reaches the activation target in one control step, in [0, 1] (the default robot's
        /// checkpoints).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        activation_clamp: Option<[f64; 2]>,
        /// The σ of the Gaussian noise on the activation targets the policy was trained with
        /// (`activation_noise` of the training configuration). Before the clamp that noise is
        /// rectified at the lower bound, so a muscle K-MAC leaves relaxed trains at a mean control
        /// of about σ/√(2π). A checkpoint player draws it as training did, from a seeded stream of
        /// its own; its mean action plays the expectation (see [`clamped_normal_mean`]). Absent:
        /// the controls as computed.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        activation_noise: Option<f64>,
        /// The official code's form: coupled joints' targets clamped to their ranges (see
        /// [`Kmac::clamp_coupled`]); absent: `false`, the checkpoints trained before the setting.
        #[serde(default, skip_serializing_if = "std::ops::Not::not")]
        clamp_coupled: bool,
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

/// The joint targets a K-MAC action spans: the range widened by `margin` of it at both ends.
fn target_range(model: &Model, j: usize, margin: f64) -> [f64; 2] {
    let [lo, hi] = joint_range(model, j);
    let m = margin * (hi - lo);
    [lo - m, hi + m]
}

fn servo_range(model: &Model, s: usize, j: usize) -> [f64; 2] {
    model.actuators[s]
        .ctrlrange
        .unwrap_or_else(|| joint_range(model, j))
}

impl ActionSpace {
    /// The range a K-MAC action entry `k` spans: the servo's control range for a servo joint, the
    /// joint's range widened by [`TARGET_MARGIN`] otherwise.
    pub fn kmac_target_range(&self, model: &Model, k: usize) -> [f64; 2] {
        self.target_range_with(model, k, TARGET_MARGIN)
    }

    fn target_range_with(&self, model: &Model, k: usize, margin: f64) -> [f64; 2] {
        let j = self.joints[k];
        match self.servos[k] {
            Some(s) => servo_range(model, s, j),
            None => target_range(model, j, margin),
        }
    }

    /// The joint targets a K-MAC action asks for, one per entry of `joints` (entries clipped to
    /// [−1, 1]), over [`ActionSpace::kmac_target_range`].
    pub fn kmac_targets(&self, model: &Model, action: &[f64]) -> Vec<f64> {
        self.targets_with(model, action, TARGET_MARGIN)
    }

    fn targets_with(&self, model: &Model, action: &[f64], margin: f64) -> Vec<f64> {
        action
            .iter()
            .take(self.joints.len())
            .enumerate()
            .map(|(k, &a)| {
                let r = self.target_range_with(model, k, margin);
                scale(a, r[0], r[1])
            })
            .collect()
    }
}

impl ActionMapper {
    /// The mapper for `spec` on `model`.
    pub fn new(model: &Model, spec: &ControllerSpec) -> ActionMapper {
        match spec {
            ControllerSpec::Kmac {
                gains,
                activation_clamp,
                activation_noise,
                clamp_coupled,
            } => ActionMapper::Kmac(Box::new(
                Kmac::new(model, *gains)
                    .with_activation_clamp(*activation_clamp)
                    .with_clamp_coupled(*clamp_coupled)
                    .with_expected_activation_noise(*activation_noise),
            )),
            ControllerSpec::MusclePd { gains } => {
                ActionMapper::MusclePd(Box::new(MusclePd::new(model, *gains)))
            }
            ControllerSpec::Direct => ActionMapper::Direct(ActionSpace::new(model)),
            ControllerSpec::Dynsyn { synergies } => {
                ActionMapper::Dynsyn(ActionSpace::new(model), synergies.clone())
            }
        }
    }

    /// Training noise on K-MAC's activations (σ, seeded stream; see [`Kmac::set_activation_noise`]);
    /// the other controllers have no activation of their own to perturb.
    pub fn set_activation_noise(&mut self, sigma: f64, seed: u64) {
        if let ActionMapper::Kmac(k) = self {
            k.set_activation_noise(sigma, seed);
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

    /// Names of the action's entries on `model`: `target.JOINT` (K-MAC's joint targets),
    /// `muscle.NAME` (a muscle's control, or its length target under Muscle-PD), `synergy.K` and
    /// `weight.NAME` (DynSyn), `servo.JOINT` (a pelvis servo's position target).
    pub fn action_names(&self, model: &Model) -> Vec<String> {
        let s = self.space();
        let muscles = |prefix: &str| -> Vec<String> {
            s.muscles
                .iter()
                .map(|&a| format!("{prefix}.{}", model.actuators[a].name))
                .collect()
        };
        let servos: Vec<String> = s
            .servo_joints()
            .map(|(j, _)| format!("servo.{}", model.joints[j].name))
            .collect();
        match self {
            ActionMapper::Kmac(_) => s
                .joints
                .iter()
                .map(|&j| format!("target.{}", model.joints[j].name))
                .collect(),
            ActionMapper::MusclePd(_) | ActionMapper::Direct(_) => {
                [muscles("muscle"), servos].concat()
            }
            ActionMapper::Dynsyn(_, syn) => [
                (0..syn.groups).map(|g| format!("synergy.{g}")).collect(),
                muscles("weight"),
                servos,
            ]
            .concat(),
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
                // The official form spans each joint's range exactly (`lo + (a + 1)/2·(hi − lo)`);
                // ours widens it (see TARGET_MARGIN).
                let margin = if k.activation_clamp.is_some() {
                    0.0
                } else {
                    TARGET_MARGIN
                };
                let targets = k.space.targets_with(model, action, margin);
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
