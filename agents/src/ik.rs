//! Inverse kinematics for the paddle: damped least squares on the blade centre's position and the
//! blade normal's direction, over the robot's independent joints (couplings followed), weighted so
//! that cheap joints (the pelvis slides) move first, within the joint limits. Either face of the
//! blade may meet the target normal; roll about the normal is left free.

use nalgebra::{DMatrix, DVector, Matrix3, Vector3};
use sim::geometry::Pose;
use sim::kinematics::{body_last_dofs, dof_chain, Kinematics};
use sim::model::{JointKind, Model};

type V3 = Vector3<f64>;

/// Where the blade should be, in the robot's model frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BladeTarget {
    /// Blade centre, m.
    pub pos: V3,
    /// Unit normal of the hitting face.
    pub normal: V3,
}

/// An IK answer.
#[derive(Debug, Clone, PartialEq)]
pub struct IkSolution {
    /// Joint positions (all joints, couplings applied).
    pub qpos: Vec<f64>,
    /// Distance of the blade centre from its target, m.
    pub position_error: f64,
    /// Angle between the blade normal (either face) and its target, rad.
    pub normal_error: f64,
}

/// What the independent joints do in a stroke, read from the model's tree so that any robot whose
/// paddle is welded to a hand gets the same treatment.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct JointRoles {
    /// The fingers: joints of the bodies below the hand (the paddle's parent), the paddle's own
    /// subtree excepted. They hold the handle, so they take no part in placing the blade.
    pub hand: Vec<usize>,
    /// The torso: hinges on the way to the hand that carry more than a fifth of the robot's mass (the
    /// lumbar spine, not the shoulder).
    pub torso: Vec<usize>,
    /// The forearm's rotation and the wrist: the last three hinges on the way to the hand.
    pub distal: Vec<usize>,
}

/// Share of the robot's mass above which a joint counts as the torso's.
const TORSO_MASS_SHARE: f64 = 0.2;

impl JointRoles {
    /// The roles in `model` whose paddle is `paddle_body`.
    pub fn of(model: &Model, paddle_body: usize) -> JointRoles {
        let nb = model.bodies.len();
        let below = |b: usize, top: usize| {
            let mut x = Some(b);
            while let Some(c) = x {
                if c == top {
                    return true;
                }
                x = model.bodies[c].parent;
            }
            false
        };
        let hand_body = model.bodies[paddle_body].parent.unwrap_or(0);
        let joints_of = |b: usize| {
            let body = &model.bodies[b];
            body.first_joint..body.first_joint + body.joint_count
        };
        let hand = (0..nb)
            .filter(|&b| b != hand_body && below(b, hand_body) && !below(b, paddle_body))
            .flat_map(joints_of)
            .filter(|&j| !model.is_dependent(j))
            .collect();
        // Mass carried by each body's joints: its subtree's.
        let mut carried = vec![0.0; nb];
        for b in (0..nb).rev() {
            carried[b] += model.bodies[b].mass;
            if let Some(p) = model.bodies[b].parent {
                carried[p] += carried[b];
            }
        }
        let total = carried[0];
        let mut path = Vec::new();
        let mut x = Some(hand_body);
        while let Some(b) = x {
            path.push(b);
            x = model.bodies[b].parent;
        }
        path.reverse();
        let chain: Vec<usize> = path
            .iter()
            .flat_map(|&b| joints_of(b))
            .filter(|&j| model.joints[j].kind == JointKind::Hinge && !model.is_dependent(j))
            .collect();
        let torso = chain
            .iter()
            .copied()
            .filter(|&j| carried[model.joints[j].body] > TORSO_MASS_SHARE * total)
            .collect();
        let distal = chain[chain.len().saturating_sub(3)..].to_vec();
        JointRoles {
            hand,
            torso,
            distal,
        }
    }
}

/// The solver for one model.
#[derive(Debug, Clone)]
pub struct PaddleIk {
    /// Independent joints it moves.
    pub joints: Vec<usize>,
    /// Mobility of each (larger moves more).
    pub mobility: Vec<f64>,
    paddle_body: usize,
    blade_local: V3,
    chain: Vec<usize>,
    kin: Kinematics,
    rest: Option<Vec<f64>>,
    /// Fraction of each joint's range kept clear at both ends (more for the torso, whose soft limits
    /// a strong swing would overrun).
    margin: Vec<f64>,
}

/// Gain of the null-space drift towards the rest posture, per iteration.
const REST_GAIN: f64 = 0.02;

impl PaddleIk {
    /// A solver moving every independent hinge and slide joint except `exclude` (e.g. the grip), the
    /// paddle being `paddle_body` with its blade centre at `blade_local` in the paddle frame.
    pub fn new(model: &Model, paddle_body: usize, blade_local: V3, exclude: &[usize]) -> PaddleIk {
        let joints: Vec<usize> = (0..model.joints.len())
            .filter(|&j| {
                model.joints[j].kind != JointKind::Free
                    && !model.is_dependent(j)
                    && !exclude.contains(&j)
            })
            .collect();
        let roles = JointRoles::of(model, paddle_body);
        let torso = |j: usize| roles.torso.contains(&j);
        // Light distal joints (the wrist) are easily shaken by the grip and the swing: they move least.
        let distal = |j: usize| roles.distal.contains(&j);
        let mobility = joints
            .iter()
            .map(|&j| match model.joints[j].kind {
                JointKind::Slide => 10.0,
                // The torso holds the ready posture: a heavy chain on weak muscles that the footwork
                // shakes; the pelvis and the arm place the paddle.
                _ if torso(j) => 0.0,
                _ if distal(j) => 0.2,
                _ => 1.0,
            })
            .collect();
        let margin = joints
            .iter()
            .map(|&j| if torso(j) { 0.15 } else { 0.03 })
            .collect();
        let last = body_last_dofs(model);
        PaddleIk {
            joints,
            mobility,
            paddle_body,
            blade_local,
            chain: dof_chain(model, &last, paddle_body),
            kin: Kinematics::new(model),
            rest: None,
            margin,
        }
    }

    fn blade(&self) -> (V3, V3) {
        let pose = Pose {
            pos: self.kin.xpos[self.paddle_body],
            rot: self.kin.xquat[self.paddle_body],
        };
        (pose.to_world(&self.blade_local), pose.rot * V3::z())
    }

    /// Solves from `seed` (a full qpos) in at most `iterations` steps, drifting in the task's null
    /// space towards `rest` (a full qpos) when one is given.
    pub fn solve_near(
        &mut self,
        model: &Model,
        seed: &[f64],
        rest: Option<&[f64]>,
        target: &BladeTarget,
        iterations: usize,
    ) -> IkSolution {
        self.rest = rest.map(|r| r.to_vec());
        let out = self.solve(model, seed, target, iterations);
        self.rest = None;
        out
    }

    /// Solves from `seed` (a full qpos) in at most `iterations` steps.
    pub fn solve(
        &mut self,
        model: &Model,
        seed: &[f64],
        target: &BladeTarget,
        iterations: usize,
    ) -> IkSolution {
        let mut q = seed.to_vec();
        model.apply_couplings(&mut q);
        let n = self.joints.len();
        let lambda2 = 1e-4;
        let w_rot = 0.3;
        let t_normal = target.normal.normalize();
        // Step first (slides only, as footwork before the stroke), then use everything.
        let all = self.mobility.clone();
        let slides: Vec<f64> = self
            .joints
            .iter()
            .zip(&all)
            .map(|(&j, &m)| {
                if model.joints[j].kind == JointKind::Slide {
                    m
                } else {
                    0.0
                }
            })
            .collect();
        let footwork = if slides.iter().any(|&m| m > 0.0) {
            15
        } else {
            0
        };
        for it in 0..iterations + footwork {
            let mobility = if it < footwork { &slides } else { &all };
            self.kin.update(model, &q);
            let (p, nrm) = self.blade();
            // Either face: aim the one already closer.
            let n_face = if nrm.dot(&t_normal) >= 0.0 { nrm } else { -nrm };
            let proj = Matrix3::identity() - n_face * n_face.transpose();
            let e_pos = target.pos - p;
            let e_rot = proj * n_face.cross(&t_normal);
            let mut e = DVector::zeros(6);
            e.fixed_rows_mut::<3>(0).copy_from(&e_pos);
            e.fixed_rows_mut::<3>(3).copy_from(&(w_rot * e_rot));
            if it >= footwork && e_pos.norm() < 1e-4 && e_rot.norm() < 1e-3 {
                break;
            }
            let mut jac = DMatrix::zeros(6, n);
            for (c, &j) in self.joints.iter().enumerate() {
                let joint = &model.joints[j];
                let mut cols = vec![(joint.dof_adr, 1.0)];
                for cp in model
                    .couplings
                    .iter()
                    .filter(|cp| cp.independent == Some(j))
                {
                    let (_, d1, _) = cp.at(model, &q);
                    cols.push((model.joints[cp.dependent].dof_adr, d1));
                }
                let mut jp = V3::zeros();
                let mut jw = V3::zeros();
                for (d, a) in cols {
                    if !self.chain.contains(&d) {
                        continue;
                    }
                    jp += a * self.kin.point_velocity(d, &p);
                    if self.kin.dof_rotates[d] {
                        jw += a * self.kin.dof_axis[d];
                    }
                }
                jac.fixed_view_mut::<3, 1>(0, c).copy_from(&jp);
                jac.fixed_view_mut::<3, 1>(3, c)
                    .copy_from(&(w_rot * proj * jw));
            }
            // W = diag(mobility). The products are written out: nalgebra hands matrix products
            // over 5×5 to matrixmultiply, whose kernel (FMA or not) is picked from the CPU at run
            // time, and an IK step must be the same bits on every machine.
            let wjt = |y: &DVector<f64>| {
                DVector::from_fn(n, |c, _| {
                    mobility[c] * (0..6).map(|r| jac[(r, c)] * y[r]).sum::<f64>()
                })
            };
            let jwjt = DMatrix::from_fn(6, 6, |r, k| {
                let jwj: f64 = (0..n)
                    .map(|c| jac[(r, c)] * mobility[c] * jac[(k, c)])
                    .sum();
                jwj + if r == k { lambda2 } else { 0.0 }
            });
            let Some(ch) = jwjt.cholesky() else {
                break;
            };
            let mut step = wjt(&ch.solve(&e));
            if let Some(rest) = &self.rest {
                // Null-space drift towards the rest posture: (I − W Jᵀ (J W Jᵀ)⁻¹ J) · W · (rest − q).
                let wp = DVector::from_fn(n, |c, _| {
                    let qa = model.joints[self.joints[c]].qpos_adr;
                    mobility[c] * REST_GAIN * (rest[qa] - q[qa])
                });
                let projected = &wp - wjt(&ch.solve(&(&jac * &wp)));
                step += projected;
            }
            let scale = (0.25 / step.amax().max(1e-12)).min(1.0);
            for (c, &j) in self.joints.iter().enumerate() {
                let joint = &model.joints[j];
                let mut x = q[joint.qpos_adr] + scale * step[c];
                if let Some([lo, hi]) = joint.range {
                    let margin = self.margin[c] * (hi - lo);
                    x = x.clamp(lo + margin, hi - margin);
                }
                q[joint.qpos_adr] = x;
            }
            model.apply_couplings(&mut q);
        }
        self.kin.update(model, &q);
        let (p, nrm) = self.blade();
        IkSolution {
            position_error: (target.pos - p).norm(),
            normal_error: sim::math::acos(nrm.dot(&t_normal).abs().clamp(-1.0, 1.0)),
            qpos: q,
        }
    }

    /// Blade centre and normal at `qpos` (model frame).
    pub fn blade_at(&mut self, model: &Model, qpos: &[f64]) -> (V3, V3) {
        self.kin.update(model, qpos);
        self.blade()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_built_in_body_has_a_lumbar_torso_a_wrist_and_one_grip_joint() {
        let model = sim::config::default_model();
        let roles = JointRoles::of(&model, model.body("paddle").unwrap());
        let names = |js: &[usize]| -> Vec<String> {
            js.iter().map(|&j| model.joints[j].name.clone()).collect()
        };
        assert_eq!(names(&roles.hand), ["grip"]);
        assert_eq!(names(&roles.torso), ["L5S1_flex", "L5S1_lat", "L5S1_rot"]);
        assert_eq!(
            names(&roles.distal),
            ["pronation", "wrist_flex", "wrist_dev"]
        );
    }
}
