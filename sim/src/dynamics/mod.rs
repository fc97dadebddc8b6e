//! Rigid-body dynamics of a musculoskeletal model: the joint-space mass matrix (composite rigid body
//! algorithm), the bias force (recursive Newton–Euler: Coriolis, centrifugal, gravity), passive joint
//! forces, actuator and muscle forces, exact joint couplings, soft joint limits, and MuJoCo's Euler
//! step (semi-implicit, joint damping implicit, armature on the mass matrix diagonal).
//!
//! Spatial vectors are 6-vectors `[angular; linear]` expressed in the world frame at the world origin,
//! as MuJoCo's `cdof`/`cinert` are at a common point. Reads a [`Model`]; writes a [`State`] and the
//! [`Data`] workspace. No allocation in the step after the workspace is built.

use nalgebra::{DMatrix, DVector, Matrix3, Matrix6, UnitQuaternion, Vector3, Vector6};

use crate::kinematics::{Kinematics, TendonKinematics};
use crate::model::{Bias, Dynamics as ActDynamics, Gain, JointKind, Model, Transmission};
use crate::muscle;

mod limits;
use limits::limit_forces;
pub use limits::{LIMIT_SOLIMP, LIMIT_SOLREF};

type V3 = Vector3<f64>;
type V6 = Vector6<f64>;

/// The mutable state of one robot (MuJoCo's `mjData` state part): small and cheap to clone.
#[derive(Debug, Clone, PartialEq)]
pub struct State {
    /// Simulated time, s.
    pub time: f64,
    /// Joint positions (`nq`).
    pub qpos: Vec<f64>,
    /// Joint velocities (`nv`).
    pub qvel: Vec<f64>,
    /// Actuator activations, one per actuator (zero and unused for actuators without dynamics).
    pub act: Vec<f64>,
    /// Actuator controls, one per actuator.
    pub ctrl: Vec<f64>,
}

impl State {
    /// The reference configuration at rest, couplings applied.
    pub fn new(model: &Model) -> State {
        let mut qpos = model.qpos0.clone();
        model.apply_couplings(&mut qpos);
        State {
            time: 0.0,
            qpos,
            qvel: vec![0.0; model.nv],
            act: vec![0.0; model.actuators.len()],
            ctrl: vec![0.0; model.actuators.len()],
        }
    }

    /// Sets positions (couplings applied) and zero velocities.
    pub fn set_qpos(&mut self, model: &Model, qpos: &[f64]) {
        self.qpos.copy_from_slice(qpos);
        model.apply_couplings(&mut self.qpos);
        self.qvel.iter_mut().for_each(|v| *v = 0.0);
    }
}

/// Everything a step computes (MuJoCo's `mjData` derived part). Build once per model and reuse.
#[derive(Debug, Clone)]
pub struct Data {
    /// Frames, sites.
    pub kin: Kinematics,
    /// Tendon lengths and moment arms.
    pub ten: TendonKinematics,
    /// Joint-space mass matrix with armature (nv × nv).
    pub mass: DMatrix<f64>,
    /// Bias force: Coriolis, centrifugal and gravity (MuJoCo's `qfrc_bias`), nv.
    pub bias: DVector<f64>,
    /// Passive joint force: springs and damping (MuJoCo's `qfrc_passive`), nv.
    pub passive: DVector<f64>,
    /// Generalised actuator force, nv.
    pub actuation: DVector<f64>,
    /// Joint-limit force, nv.
    pub limit: DVector<f64>,
    /// Actuator lengths.
    pub actuator_length: Vec<f64>,
    /// Actuator velocities.
    pub actuator_velocity: Vec<f64>,
    /// Actuator forces (muscles: negative when pulling).
    pub actuator_force: Vec<f64>,
    /// Joint accelerations of the last step, nv.
    pub qacc: DVector<f64>,
    /// The map `T` from independent to all velocities (`q̇ = T·q̇_r`), by column: for each independent
    /// degree of freedom, the dofs it moves and by how much (1 for itself, `p'(q)` for its dependents).
    pub coupling_columns: Vec<Vec<(usize, f64)>>,
    /// Independent degrees of freedom (the columns of `T`).
    pub independent_dofs: Vec<usize>,
    /// `Ṫ·q̇_r`: the dependents' acceleration at zero independent acceleration (nv).
    tdot_v: DVector<f64>,
    /// Generalised force before projection (nv).
    force: DVector<f64>,
    /// `Tᵀ(M + h·D)T` (nr × nr).
    lhs: DMatrix<f64>,
    /// `Tᵀ·force` (nr).
    rhs: DVector<f64>,
    /// Joint damping per dof.
    damping: Vec<f64>,
    // Scratch.
    body_inertia: Vec<Matrix6<f64>>,
    composite: Vec<Matrix6<f64>>,
    cdof: Vec<V6>,
    cdof_dot: Vec<V6>,
    body_vel: Vec<V6>,
    body_acc: Vec<V6>,
    body_force: Vec<V6>,
}

fn skew(v: &V3) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// Spatial motion cross product `v × m`.
fn cross_motion(v: &V6, m: &V6) -> V6 {
    let (w, u) = (v.fixed_rows::<3>(0), v.fixed_rows::<3>(3));
    let (w2, u2) = (m.fixed_rows::<3>(0), m.fixed_rows::<3>(3));
    let a = w.cross(&w2);
    let b = w.cross(&u2) + u.cross(&w2);
    V6::new(a.x, a.y, a.z, b.x, b.y, b.z)
}

/// Spatial force cross product `v ×* f`.
fn cross_force(v: &V6, f: &V6) -> V6 {
    let (w, u) = (v.fixed_rows::<3>(0), v.fixed_rows::<3>(3));
    let (n, fl) = (f.fixed_rows::<3>(0), f.fixed_rows::<3>(3));
    let a = w.cross(&n) + u.cross(&fl);
    let b = w.cross(&fl);
    V6::new(a.x, a.y, a.z, b.x, b.y, b.z)
}

impl Data {
    /// A workspace for `model`.
    pub fn new(model: &Model) -> Data {
        let (nv, nb, nu) = (model.nv, model.bodies.len(), model.actuators.len());
        let independent_dofs: Vec<usize> = (0..nv)
            .filter(|&d| !model.is_dependent(model.dof_joint[d]))
            .collect();
        let nr = independent_dofs.len();
        let mut coupling_columns: Vec<Vec<(usize, f64)>> =
            independent_dofs.iter().map(|&d| vec![(d, 1.0)]).collect();
        for c in &model.couplings {
            // A locked joint is in no column: it never moves.
            let Some(i) = c.independent else { continue };
            let ind = model.joints[i].dof_adr;
            let r = independent_dofs
                .iter()
                .position(|&d| d == ind)
                .expect("independent dof");
            coupling_columns[r].push((model.joints[c.dependent].dof_adr, 0.0));
        }
        let damping = (0..nv)
            .map(|d| {
                let j = &model.joints[model.dof_joint[d]];
                if j.kind == JointKind::Free {
                    0.0
                } else {
                    j.damping
                }
            })
            .collect();
        Data {
            kin: Kinematics::new(model),
            ten: TendonKinematics::new(model),
            mass: DMatrix::zeros(nv, nv),
            bias: DVector::zeros(nv),
            passive: DVector::zeros(nv),
            actuation: DVector::zeros(nv),
            limit: DVector::zeros(nv),
            actuator_length: vec![0.0; nu],
            actuator_velocity: vec![0.0; nu],
            actuator_force: vec![0.0; nu],
            qacc: DVector::zeros(nv),
            coupling_columns,
            independent_dofs,
            tdot_v: DVector::zeros(nv),
            force: DVector::zeros(nv),
            lhs: DMatrix::zeros(nr, nr),
            rhs: DVector::zeros(nr),
            damping,
            body_inertia: vec![Matrix6::zeros(); nb],
            composite: vec![Matrix6::zeros(); nb],
            cdof: vec![V6::zeros(); nv],
            cdof_dot: vec![V6::zeros(); nv],
            body_vel: vec![V6::zeros(); nb],
            body_acc: vec![V6::zeros(); nb],
            body_force: vec![V6::zeros(); nb],
        }
    }

    /// Position stage: kinematics, tendons, spatial inertias, motion subspaces, mass matrix.
    pub fn positions(&mut self, model: &Model, qpos: &[f64]) {
        self.kin.update(model, qpos);
        self.ten.update(model, &self.kin);
        for b in 1..model.bodies.len() {
            let body = &model.bodies[b];
            let r = &self.kin.xrot[b];
            let ic = r * body.inertia * r.transpose();
            let c = skew(&self.kin.xipos[b]);
            let m = body.mass;
            let mut i6 = Matrix6::zeros();
            i6.fixed_view_mut::<3, 3>(0, 0)
                .copy_from(&(ic + m * c * c.transpose()));
            i6.fixed_view_mut::<3, 3>(0, 3).copy_from(&(m * c));
            i6.fixed_view_mut::<3, 3>(3, 0)
                .copy_from(&(m * c.transpose()));
            i6.fixed_view_mut::<3, 3>(3, 3)
                .copy_from(&(Matrix3::identity() * m));
            self.body_inertia[b] = i6;
        }
        for d in 0..model.nv {
            let a = self.kin.dof_axis[d];
            self.cdof[d] = if self.kin.dof_rotates[d] {
                let l = self.kin.dof_anchor[d].cross(&a);
                V6::new(a.x, a.y, a.z, l.x, l.y, l.z)
            } else {
                V6::new(0.0, 0.0, 0.0, a.x, a.y, a.z)
            };
        }
        // Composite rigid body algorithm.
        self.composite.clone_from(&self.body_inertia);
        for b in (1..model.bodies.len()).rev() {
            if let Some(p) = model.bodies[b].parent.filter(|&p| p > 0) {
                let child = self.composite[b];
                self.composite[p] += child;
            }
        }
        self.mass.fill(0.0);
        for i in 0..model.nv {
            let f = self.composite[model.dof_body[i]] * self.cdof[i];
            let mut j = Some(i);
            while let Some(jj) = j {
                let v = self.cdof[jj].dot(&f);
                self.mass[(i, jj)] = v;
                self.mass[(jj, i)] = v;
                j = model.dof_parent[jj];
            }
            self.mass[(i, i)] += model.joints[model.dof_joint[i]].armature;
        }
        for (i, act) in model.actuators.iter().enumerate() {
            self.actuator_length[i] =
                crate::kinematics::actuator_length(model, act.transmission, &self.ten, qpos);
        }
    }

    /// Velocity stage: the bias force by recursive Newton–Euler with zero joint acceleration and
    /// gravity as a base acceleration.
    pub fn velocities(&mut self, model: &Model, qvel: &[f64]) {
        let g = model.gravity;
        let base_acc = V6::new(0.0, 0.0, 0.0, -g.x, -g.y, -g.z);
        for b in 1..model.bodies.len() {
            let body = &model.bodies[b];
            let p = body.parent.expect("non-world body");
            let (mut v, mut a) = if p == 0 {
                (V6::zeros(), base_acc)
            } else {
                (self.body_vel[p], self.body_acc[p])
            };
            for j in body.first_joint..body.first_joint + body.joint_count {
                let joint = &model.joints[j];
                let dofs = joint.dof_adr..joint.dof_adr + joint.kind.nv();
                if joint.kind == JointKind::Free {
                    // As MuJoCo: the translations move the frame without turning it (no ċdof), and the
                    // three rotations are one angular velocity, so each sees the same velocity.
                    let d0 = joint.dof_adr;
                    for (d, &qd) in (d0..d0 + 3).zip(&qvel[d0..d0 + 3]) {
                        self.cdof_dot[d] = V6::zeros();
                        v += self.cdof[d] * qd;
                    }
                    let v_rot = v;
                    for (d, &qd) in (d0 + 3..d0 + 6).zip(&qvel[d0 + 3..d0 + 6]) {
                        self.cdof_dot[d] = cross_motion(&v_rot, &self.cdof[d]);
                        a += self.cdof_dot[d] * qd;
                        v += self.cdof[d] * qd;
                    }
                    continue;
                }
                for (d, &qd) in dofs.clone().zip(&qvel[dofs]) {
                    self.cdof_dot[d] = cross_motion(&v, &self.cdof[d]);
                    a += self.cdof_dot[d] * qd;
                    v += self.cdof[d] * qd;
                }
            }
            self.body_vel[b] = v;
            self.body_acc[b] = a;
            let iv = self.body_inertia[b] * v;
            self.body_force[b] = self.body_inertia[b] * a + cross_force(&v, &iv);
        }
        for b in (1..model.bodies.len()).rev() {
            if let Some(p) = model.bodies[b].parent.filter(|&p| p > 0) {
                let f = self.body_force[b];
                self.body_force[p] += f;
            }
        }
        for d in 0..model.nv {
            self.bias[d] = self.cdof[d].dot(&self.body_force[model.dof_body[d]]);
        }
        for (i, act) in model.actuators.iter().enumerate() {
            self.actuator_velocity[i] = match act.transmission {
                Transmission::Tendon(t) => self.ten.velocity(t, qvel),
                Transmission::Joint(j) => qvel[model.joints[j].dof_adr],
            };
        }
    }

    /// Angular velocity of `body` (world frame) at the state of the last [`Data::velocities`].
    pub fn angular_velocity(&self, body: usize) -> V3 {
        if body == 0 {
            return V3::zeros();
        }
        self.body_vel[body].fixed_rows::<3>(0).into()
    }

    /// Velocity of the world point `p` moving with `body`, at the state of the last
    /// [`Data::velocities`].
    pub fn point_velocity(&self, body: usize, p: &V3) -> V3 {
        if body == 0 {
            return V3::zeros();
        }
        let w: V3 = self.body_vel[body].fixed_rows::<3>(0).into();
        let v: V3 = self.body_vel[body].fixed_rows::<3>(3).into();
        v + w.cross(p)
    }

    /// Refreshes the coupling columns of `T` at `qpos` and `Ṫ·q̇_r` at `qvel`.
    pub fn update_couplings(&mut self, model: &Model, qpos: &[f64], qvel: &[f64]) {
        self.tdot_v.fill(0.0);
        for c in &model.couplings {
            let Some(i) = c.independent else { continue };
            let ind = &model.joints[i];
            let dep = &model.joints[c.dependent];
            let (_, d1, d2) = c.at(model, qpos);
            let r = self
                .independent_dofs
                .iter()
                .position(|&d| d == ind.dof_adr)
                .expect("independent dof");
            if let Some(entry) = self.coupling_columns[r]
                .iter_mut()
                .find(|(d, _)| *d == dep.dof_adr)
            {
                entry.1 = d1;
            }
            self.tdot_v[dep.dof_adr] = d2 * qvel[ind.dof_adr] * qvel[ind.dof_adr];
        }
    }
}

/// Actuator force for actuator `i` given length, velocity, activation and control (MuJoCo's
/// `mj_fwdActuation`: `gain·(act or ctrl) + bias`).
fn actuator_force(model: &Model, i: usize, len: f64, vel: f64, act: f64, ctrl: f64) -> f64 {
    let a = &model.actuators[i];
    let input = match a.dynamics {
        ActDynamics::None => ctrl,
        ActDynamics::Muscle(_) => act,
    };
    let gain = match &a.gain {
        Gain::Fixed(g) => *g,
        Gain::Muscle(p) => muscle::gain(p, len, vel, a.lengthrange, 0.0),
    };
    let bias = match &a.bias {
        Bias::None => 0.0,
        Bias::Affine(b) => b[0] + b[1] * len + b[2] * vel,
        Bias::Muscle(p) => muscle::bias(p, len, a.lengthrange, 0.0),
    };
    gain * input + bias
}

/// Actuator `i`'s force at the actuator length and velocity in `data` and the activation and
/// control in `state` (the control clamped to its range): what [`actuate`] writes to
/// `data.actuator_force[i]`.
pub fn actuator_force_now(model: &Model, data: &Data, state: &State, i: usize) -> f64 {
    let ctrl = match model.actuators[i].ctrlrange {
        Some([lo, hi]) => state.ctrl[i].clamp(lo, hi),
        None => state.ctrl[i],
    };
    actuator_force(
        model,
        i,
        data.actuator_length[i],
        data.actuator_velocity[i],
        state.act[i],
        ctrl,
    )
}

/// Actuator forces (`data.actuator_force`) and their generalised force (`data.actuation`) from the
/// actuator lengths and velocities in `data` and the activations and controls in `state` (MuJoCo's
/// `mj_fwdActuation`; controls clamped to their ranges).
pub fn actuate(model: &Model, data: &mut Data, state: &State) {
    data.actuation.fill(0.0);
    for i in 0..model.actuators.len() {
        let f = actuator_force_now(model, data, state, i);
        data.actuator_force[i] = f;
        match model.actuators[i].transmission {
            Transmission::Tendon(t) => {
                let moment = data.ten.moment_arms(t);
                for &d in &data.ten.dofs[t] {
                    data.actuation[d] += moment[d] * f;
                }
            }
            Transmission::Joint(j) => data.actuation[model.joints[j].dof_adr] += f,
        }
    }
}

/// One MuJoCo-style Euler step of `model.timestep`: forces from the current state, joint
/// accelerations from `(M + h·D)·q̈ = τ − c` in independent coordinates, then `q̇ += h·q̈`,
/// `q += h·q̇` (quaternions integrated on the manifold), dependent joints set by their couplings, and
/// activations `act += h·ȧct`.
pub fn step(model: &Model, data: &mut Data, state: &mut State) {
    step_with_force(model, data, state, None);
}

/// [`step`] with an extra generalised force (nv) from outside the model, e.g. a ball's impulse on
/// the paddle spread over the step.
pub fn step_with_force(
    model: &Model,
    data: &mut Data,
    state: &mut State,
    external: Option<&DVector<f64>>,
) {
    let h = model.timestep;
    let nv = model.nv;
    data.positions(model, &state.qpos);
    data.velocities(model, &state.qvel);

    actuate(model, data, state);
    // Passive springs and damping.
    for joint in &model.joints {
        if joint.kind == JointKind::Free {
            continue;
        }
        let d = joint.dof_adr;
        data.passive[d] = -joint.damping * state.qvel[d]
            - joint.stiffness * (state.qpos[joint.qpos_adr] - joint.springref);
    }

    // Reduced (independent) coordinates: (Tᵀ(M + h·D)T)·q̈_r = Tᵀ(τ − c − M·Ṫq̇_r), T sparse.
    data.update_couplings(model, &state.qpos, &state.qvel);
    data.force.copy_from(&data.actuation);
    data.force += &data.passive;
    data.force -= &data.bias;
    for c in &model.couplings {
        let dep = model.joints[c.dependent].dof_adr;
        let tv = data.tdot_v[dep];
        if tv != 0.0 {
            for i in 0..nv {
                data.force[i] -= data.mass[(i, dep)] * tv;
            }
        }
    }
    if let Some(ext) = external {
        data.force += ext;
    }
    let nr = data.independent_dofs.len();
    for r in 0..nr {
        data.rhs[r] = data.coupling_columns[r]
            .iter()
            .map(|&(i, a)| a * data.force[i])
            .sum();
        for c in 0..=r {
            let mut v = 0.0;
            for &(i, a) in &data.coupling_columns[r] {
                for &(j, b) in &data.coupling_columns[c] {
                    let damp = if i == j { h * data.damping[i] } else { 0.0 };
                    v += a * b * (data.mass[(i, j)] + damp);
                }
            }
            data.lhs[(r, c)] = v;
            data.lhs[(c, r)] = v;
        }
    }

    // One factorisation serves the unconstrained solve and the soft joint limits.
    let qacc_r = match data.lhs.clone().cholesky() {
        Some(ch) => {
            let mut qacc_r = ch.solve(&data.rhs);
            let limit_r = limit_forces(model, data, state, &ch, &qacc_r);
            data.limit.fill(0.0);
            if limit_r.iter().any(|f| *f != 0.0) {
                for (r, &d) in data.independent_dofs.iter().enumerate() {
                    data.limit[d] = limit_r[r];
                }
                qacc_r += ch.solve(&limit_r);
            }
            qacc_r
        }
        // Not positive definite (a massless moving body): no motion rather than nonsense.
        None => DVector::zeros(data.independent_dofs.len()),
    };
    data.qacc.copy_from(&data.tdot_v);
    for (r, col) in data.coupling_columns.iter().enumerate() {
        for &(i, a) in col {
            data.qacc[i] += a * qacc_r[r];
        }
    }

    // Integrate independent velocities and positions; dependents follow.
    for (r, &d) in data.independent_dofs.iter().enumerate() {
        state.qvel[d] += h * qacc_r[r];
    }
    integrate_positions(model, state, h);
    set_dependents(model, state);

    // Activation dynamics.
    for (i, a) in model.actuators.iter().enumerate() {
        if let ActDynamics::Muscle(p) = &a.dynamics {
            state.act[i] += h * muscle::activation_rate(state.ctrl[i], state.act[i], p);
        }
    }
    state.time += h;
}

/// Positions from velocities: `q += h·q̇` for hinges and slides, free joints translate and rotate
/// their quaternion by the body-frame angular velocity (MuJoCo's `mj_integratePos`).
fn integrate_positions(model: &Model, state: &mut State, h: f64) {
    for joint in &model.joints {
        let (qa, da) = (joint.qpos_adr, joint.dof_adr);
        match joint.kind {
            JointKind::Hinge | JointKind::Slide => state.qpos[qa] += h * state.qvel[da],
            JointKind::Free => {
                for i in 0..3 {
                    state.qpos[qa + i] += h * state.qvel[da + i];
                }
                let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                    state.qpos[qa + 3],
                    state.qpos[qa + 4],
                    state.qpos[qa + 5],
                    state.qpos[qa + 6],
                ));
                let w = V3::new(state.qvel[da + 3], state.qvel[da + 4], state.qvel[da + 5]);
                let q = q * crate::math::quat_from_scaled_axis(w * h);
                let c = q.quaternion();
                state.qpos[qa + 3..qa + 7].copy_from_slice(&[c.w, c.i, c.j, c.k]);
            }
        }
    }
}

/// Dependent joints take their couplings' positions and velocities.
pub fn set_dependents(model: &Model, state: &mut State) {
    for c in &model.couplings {
        let dep = &model.joints[c.dependent];
        let (q, d1, _) = c.at(model, &state.qpos);
        state.qpos[dep.qpos_adr] = q;
        state.qvel[dep.dof_adr] = match c.independent {
            Some(i) => d1 * state.qvel[model.joints[i].dof_adr],
            None => 0.0,
        };
    }
}
