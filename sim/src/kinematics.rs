//! Forward kinematics (MuJoCo's `mj_kinematics`), point Jacobians, and the lengths and moment arms
//! of spatial tendons (`mj_tendon`): everything that depends on positions only.
//!
//! Reads a [`Model`] and a `qpos`; writes a [`Kinematics`] workspace. No allocation after `new`.

use nalgebra::{DMatrix, Matrix3, Quaternion, UnitQuaternion, Vector3};

use crate::model::{GeomKind, JointKind, Model, PathPoint, Transmission};
use crate::wrap::{self, WrapShape};

type V3 = Vector3<f64>;

/// Position-dependent quantities of a configuration (MuJoCo's `xpos`, `xmat`, `xipos`, `xanchor`,
/// `xaxis`, `site_xpos`), all in the world frame.
#[derive(Debug, Clone)]
pub struct Kinematics {
    /// Body frame origins.
    pub xpos: Vec<V3>,
    /// Body frame orientations.
    pub xquat: Vec<UnitQuaternion<f64>>,
    /// Body rotation matrices.
    pub xrot: Vec<Matrix3<f64>>,
    /// Body centres of mass.
    pub xipos: Vec<V3>,
    /// Per degree of freedom: its unit axis (rotation axis, or translation direction).
    pub dof_axis: Vec<V3>,
    /// Per degree of freedom: a point on its rotation axis (unused for translations).
    pub dof_anchor: Vec<V3>,
    /// Per degree of freedom: whether it rotates (hinge, free rotation) or translates.
    pub dof_rotates: Vec<bool>,
    /// Site positions.
    pub site_pos: Vec<V3>,
    /// For each body, the last degree of freedom on its path to the root (walk `dof_parent` from it).
    pub body_last_dof: Vec<Option<usize>>,
}

impl Kinematics {
    /// A workspace for `model`, at its reference configuration.
    pub fn new(model: &Model) -> Kinematics {
        let nb = model.bodies.len();
        let body_last_dof = body_last_dofs(model);
        let mut k = Kinematics {
            xpos: vec![V3::zeros(); nb],
            xquat: vec![UnitQuaternion::identity(); nb],
            xrot: vec![Matrix3::identity(); nb],
            xipos: vec![V3::zeros(); nb],
            dof_axis: vec![V3::zeros(); model.nv],
            dof_anchor: vec![V3::zeros(); model.nv],
            dof_rotates: vec![false; model.nv],
            site_pos: vec![V3::zeros(); model.sites.len()],
            body_last_dof,
        };
        let mut q = model.qpos0.clone();
        model.apply_couplings(&mut q);
        k.update(model, &q);
        k
    }

    /// Recomputes every frame for `qpos` (taken as is: apply couplings first if needed).
    pub fn update(&mut self, model: &Model, qpos: &[f64]) {
        for b in 1..model.bodies.len() {
            let body = &model.bodies[b];
            let p = body.parent.expect("non-world body");
            let joints = body.first_joint..body.first_joint + body.joint_count;
            let free = joints
                .clone()
                .next()
                .filter(|&j| model.joints[j].kind == JointKind::Free);
            let (mut pos, mut quat) = if let Some(j) = free {
                let a = model.joints[j].qpos_adr;
                let q = UnitQuaternion::from_quaternion(Quaternion::new(
                    qpos[a + 3],
                    qpos[a + 4],
                    qpos[a + 5],
                    qpos[a + 6],
                ));
                (V3::new(qpos[a], qpos[a + 1], qpos[a + 2]), q)
            } else {
                (
                    self.xpos[p] + self.xrot[p] * body.pos,
                    self.xquat[p] * body.quat,
                )
            };
            for j in joints {
                let joint = &model.joints[j];
                let rot = quat.to_rotation_matrix();
                match joint.kind {
                    JointKind::Free => {
                        let d = joint.dof_adr;
                        for i in 0..3 {
                            self.dof_axis[d + i] = V3::ith(i, 1.0);
                            self.dof_rotates[d + i] = false;
                            self.dof_axis[d + 3 + i] = rot.matrix().column(i).into();
                            self.dof_anchor[d + 3 + i] = pos;
                            self.dof_rotates[d + 3 + i] = true;
                        }
                    }
                    JointKind::Hinge => {
                        let anchor = pos + rot * joint.pos;
                        let axis = rot * joint.axis;
                        self.dof_axis[joint.dof_adr] = axis;
                        self.dof_anchor[joint.dof_adr] = anchor;
                        self.dof_rotates[joint.dof_adr] = true;
                        let angle = qpos[joint.qpos_adr] - joint.reference;
                        quat *= crate::math::quat_from_scaled_axis(joint.axis * angle);
                        pos = anchor - quat * joint.pos;
                    }
                    JointKind::Slide => {
                        let axis = rot * joint.axis;
                        self.dof_axis[joint.dof_adr] = axis;
                        self.dof_anchor[joint.dof_adr] = pos + rot * joint.pos;
                        self.dof_rotates[joint.dof_adr] = false;
                        pos += axis * (qpos[joint.qpos_adr] - joint.reference);
                    }
                }
            }
            self.xpos[b] = pos;
            self.xquat[b] = quat;
            self.xrot[b] = *quat.to_rotation_matrix().matrix();
            self.xipos[b] = pos + self.xrot[b] * body.com;
        }
        for (i, s) in model.sites.iter().enumerate() {
            self.site_pos[i] = self.xpos[s.body] + self.xrot[s.body] * s.pos;
        }
    }

    /// The chain of degrees of freedom that move `body`, from the body towards the root.
    pub fn chain<'a>(&self, model: &'a Model, body: usize) -> impl Iterator<Item = usize> + 'a {
        std::iter::successors(self.body_last_dof[body], move |&d| model.dof_parent[d])
    }

    /// Velocity of the world point `p` (attached to the body the dof moves) per unit speed of `dof`.
    pub fn point_velocity(&self, dof: usize, p: &V3) -> V3 {
        if self.dof_rotates[dof] {
            self.dof_axis[dof].cross(&(p - self.dof_anchor[dof]))
        } else {
            self.dof_axis[dof]
        }
    }

    /// Translational Jacobian of the world point `p` fixed to `body`: 3 × nv.
    pub fn point_jacobian(&self, model: &Model, body: usize, p: &V3) -> DMatrix<f64> {
        let mut j = DMatrix::zeros(3, model.nv);
        for d in self.chain(model, body) {
            j.set_column(d, &self.point_velocity(d, p));
        }
        j
    }
}

/// For each body, the last degree of freedom on its path to the root (`None` for the world and bodies
/// welded to it).
pub fn body_last_dofs(model: &Model) -> Vec<Option<usize>> {
    let mut out = vec![None; model.bodies.len()];
    for b in 1..model.bodies.len() {
        let body = &model.bodies[b];
        let own = (body.first_joint..body.first_joint + body.joint_count)
            .last()
            .map(|j| model.joints[j].dof_adr + model.joints[j].kind.nv() - 1);
        out[b] = own.or(out[body.parent.expect("non-world body")]);
    }
    out
}

/// The degrees of freedom that move `body`, from the body towards the root.
pub fn dof_chain(model: &Model, last: &[Option<usize>], body: usize) -> Vec<usize> {
    std::iter::successors(last[body], |&d| model.dof_parent[d]).collect()
}

/// The degrees of freedom that change the distance between a point on `b0` and a point on `b1`:
/// those that move one body and not the other (a dof moving both moves the pair rigidly).
#[derive(Debug, Clone)]
struct Link {
    dofs0: Vec<usize>,
    dofs1: Vec<usize>,
    /// Both ends on one body: the piece never changes length.
    rigid: bool,
}

impl Link {
    fn new(model: &Model, last: &[Option<usize>], b0: usize, b1: usize) -> Link {
        let c0 = dof_chain(model, last, b0);
        let c1 = dof_chain(model, last, b1);
        Link {
            dofs0: c0.iter().copied().filter(|d| !c1.contains(d)).collect(),
            dofs1: c1.iter().copied().filter(|d| !c0.contains(d)).collect(),
            rigid: b0 == b1,
        }
    }
}

/// Where a wrap happens: the geom, its shape, radius and pose on its body, the side site.
#[derive(Debug, Clone)]
struct WrapGeom {
    body: usize,
    shape: WrapShape,
    radius: f64,
    pos: V3,
    rot: Matrix3<f64>,
    sidesite: Option<usize>,
}

/// One piece of a tendon's path: from a site to the next, straight or over a wrapping geom.
#[derive(Debug, Clone)]
struct Piece {
    tendon: usize,
    s0: usize,
    s1: usize,
    /// The straight path `s0 → s1`.
    direct: Link,
    /// Over a geom: the geom, and the links `s0 → geom body` and `geom body → s1`.
    wrap: Option<(WrapGeom, Link, Link)>,
}

/// Length of every tendon and its moment arms `∂l/∂q` per degree of freedom (MuJoCo's `ten_J`).
///
/// As MuJoCo's `mj_tendon`: each straight piece between consecutive points on different bodies
/// adds `u·(J(p1) − J(p0))` with `u` its direction; wrap tangent points count as fixed to the
/// geom's body and the arc between them adds length only (the tangent conditions make the arc's own
/// derivative vanish).
#[derive(Debug, Clone)]
pub struct TendonKinematics {
    /// Lengths, m.
    pub length: Vec<f64>,
    /// Moment arms, ntendon × nv, stored by tendon ([`TendonKinematics::moment_arms`]), m or m/m.
    moment: Vec<f64>,
    nv: usize,
    /// For each tendon, the degrees of freedom where its moment arm can be non-zero.
    pub dofs: Vec<Vec<usize>>,
    pieces: Vec<Piece>,
}

/// One piece's path at a configuration: its points (site, site when straight; site, tangent,
/// tangent, site over a geom), its length, and the lengths of its straight parts (site → site;
/// or site → tangent and tangent → site).
struct PiecePath {
    points: [V3; 4],
    length: f64,
    straight: [f64; 2],
}

impl TendonKinematics {
    /// Zeroed storage for `model`, and each piece's degrees of freedom.
    pub fn new(model: &Model) -> TendonKinematics {
        let last = body_last_dofs(model);
        let mut pieces = Vec::new();
        let mut dofs = vec![Vec::new(); model.tendons.len()];
        let site_body = |s: usize| model.sites[s].body;
        for (t, tendon) in model.tendons.iter().enumerate() {
            let mut i = 0;
            while i + 1 < tendon.path.len() {
                let PathPoint::Site(s0) = tendon.path[i] else {
                    unreachable!("the loader checks that a wrap sits between two sites")
                };
                let (wrap, s1, step) = match tendon.path[i + 1] {
                    PathPoint::Site(s1) => (None, s1, 1),
                    PathPoint::Wrap { geom, sidesite } => {
                        let PathPoint::Site(s1) = tendon.path[i + 2] else {
                            unreachable!("the loader checks that a wrap sits between two sites")
                        };
                        let g = &model.geoms[geom];
                        let shape = match g.kind {
                            GeomKind::Sphere => WrapShape::Sphere,
                            GeomKind::Cylinder => WrapShape::Cylinder,
                            k => unreachable!("the loader refuses wrapping over a {k:?}"),
                        };
                        let w = WrapGeom {
                            body: g.body,
                            shape,
                            radius: g.size[0],
                            pos: g.pos,
                            rot: *g.quat.to_rotation_matrix().matrix(),
                            sidesite,
                        };
                        let to = Link::new(model, &last, site_body(s0), g.body);
                        let from = Link::new(model, &last, g.body, site_body(s1));
                        (Some((w, to, from)), s1, 2)
                    }
                };
                let direct = Link::new(model, &last, site_body(s0), site_body(s1));
                let links =
                    std::iter::once(&direct).chain(wrap.iter().flat_map(|(_, a, b)| [a, b]));
                for l in links {
                    for d in l.dofs0.iter().chain(&l.dofs1) {
                        if !dofs[t].contains(d) {
                            dofs[t].push(*d);
                        }
                    }
                }
                pieces.push(Piece {
                    tendon: t,
                    s0,
                    s1,
                    direct,
                    wrap,
                });
                i += step;
            }
            dofs[t].sort_unstable();
        }
        TendonKinematics {
            length: vec![0.0; model.tendons.len()],
            moment: vec![0.0; model.tendons.len() * model.nv],
            nv: model.nv,
            dofs,
            pieces,
        }
    }

    /// A piece's path at the frames in `kin`.
    fn path<'p>(
        piece: &'p Piece,
        kin: &Kinematics,
    ) -> (PiecePath, Option<&'p (WrapGeom, Link, Link)>) {
        let (p0, p1) = (kin.site_pos[piece.s0], kin.site_pos[piece.s1]);
        if let Some(w) = &piece.wrap {
            let g = &w.0;
            let rot = kin.xrot[g.body] * g.rot;
            let center = kin.xpos[g.body] + kin.xrot[g.body] * g.pos;
            let side = g.sidesite.map(|s| kin.site_pos[s]);
            if let Some(wr) = wrap::wrap(&p0, &p1, &center, &rot, g.radius, g.shape, side.as_ref())
            {
                let [t0, t1] = wr.points;
                let straight = [(t0 - p0).norm(), (p1 - t1).norm()];
                let path = PiecePath {
                    points: [p0, t0, t1, p1],
                    length: straight[0] + wr.length + straight[1],
                    straight,
                };
                return (path, Some(w));
            }
        }
        let length = (p1 - p0).norm();
        let path = PiecePath {
            points: [p0, p1, p1, p1],
            length,
            straight: [length, 0.0],
        };
        (path, None)
    }

    /// Recomputes the lengths alone from the frames in `kin` (the same sums as
    /// [`TendonKinematics::update`]; the moment arms are left as they were).
    pub fn update_lengths(&mut self, kin: &Kinematics) {
        self.length.fill(0.0);
        for piece in &self.pieces {
            self.length[piece.tendon] += Self::path(piece, kin).0.length;
        }
    }

    /// Recomputes lengths and moment arms from the frames in `kin`.
    pub fn update(&mut self, _model: &Model, kin: &Kinematics) {
        let nv = self.nv;
        for (t, dofs) in self.dofs.iter().enumerate() {
            self.length[t] = 0.0;
            let row = &mut self.moment[t * nv..(t + 1) * nv];
            for &d in dofs {
                row[d] = 0.0;
            }
        }
        for piece in &self.pieces {
            let (path, wrapped) = Self::path(piece, kin);
            let t = piece.tendon;
            self.length[t] += path.length;
            let row = &mut self.moment[t * nv..(t + 1) * nv];
            let p = &path.points;
            // The straight pieces: site → site, or site → tangent and tangent → site (the arc
            // between the tangents lies on one body).
            let straight = match wrapped {
                None => [Some((&piece.direct, 0)), None],
                Some((_, to, from)) => [Some((to, 0)), Some((from, 2))],
            };
            for (link, k) in straight.into_iter().flatten() {
                if link.rigid {
                    continue;
                }
                let (a, b) = (p[k], p[k + 1]);
                // The piece's direction; (1, 0, 0) for a piece of no length, as MuJoCo.
                let l = path.straight[k / 2];
                let u = if l < wrap::MINVAL {
                    V3::x()
                } else {
                    (b - a) / l
                };
                for &d in &link.dofs1 {
                    row[d] += u.dot(&kin.point_velocity(d, &b));
                }
                for &d in &link.dofs0 {
                    row[d] -= u.dot(&kin.point_velocity(d, &a));
                }
            }
        }
    }

    /// Tendon `t`'s moment arms, one per degree of freedom (nv; zero outside
    /// `dofs[t]`).
    pub fn moment_arms(&self, t: usize) -> &[f64] {
        &self.moment[t * self.nv..(t + 1) * self.nv]
    }

    /// Velocity of tendon `t` for joint velocities `qvel`.
    pub fn velocity(&self, t: usize, qvel: &[f64]) -> f64 {
        let moment = self.moment_arms(t);
        self.dofs[t].iter().map(|&d| moment[d] * qvel[d]).sum()
    }
}

/// Actuator length for a transmission, given tendon lengths and `qpos`.
pub fn actuator_length(
    model: &Model,
    trn: Transmission,
    tendons: &TendonKinematics,
    qpos: &[f64],
) -> f64 {
    match trn {
        Transmission::Tendon(t) => tendons.length[t],
        Transmission::Joint(j) => qpos[model.joints[j].qpos_adr],
    }
}

/// Number of quasi-random configurations sampled per muscle when its `lengthrange` is not given.
pub const LENGTHRANGE_SAMPLES: usize = 1024;

/// The k-th element of the van der Corput sequence in `base` (for Halton points).
fn radical_inverse(mut k: usize, base: usize) -> f64 {
    let mut f = 1.0;
    let mut r = 0.0;
    while k > 0 {
        f /= base as f64;
        r += f * (k % base) as f64;
        k /= base;
    }
    r
}

/// Fills `lengthrange` of every muscle that does not state it: the minimum and maximum tendon length
/// over the joint ranges, estimated by [`LENGTHRANGE_SAMPLES`] Halton-sequence configurations of the
/// independent joints (unlimited hinges over ±π; unlimited slides and free joints held at their
/// reference; couplings applied), each extreme then refined by coordinate search over the joint limits.
/// MuJoCo estimates it by simulation instead, so the two can differ slightly; shipped models state
/// `lengthrange` for every muscle.
pub fn fill_lengthranges(model: &mut Model) {
    let needed: Vec<usize> = (0..model.actuators.len())
        .filter(|&a| model.actuators[a].muscle().is_some() && !model.actuators[a].lengthrange_given)
        .collect();
    if needed.is_empty() {
        return;
    }
    let free_joints: Vec<(usize, [f64; 2])> = (0..model.joints.len())
        .filter(|&j| model.joints[j].kind != JointKind::Free && !model.is_dependent(j))
        .filter_map(|j| {
            let joint = &model.joints[j];
            match (joint.range, joint.kind) {
                (Some(r), _) => Some((j, r)),
                (None, JointKind::Hinge) => {
                    Some((j, [-std::f64::consts::PI, std::f64::consts::PI]))
                }
                _ => None,
            }
        })
        .collect();
    const PRIMES: [usize; 24] = [
        2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37, 41, 43, 47, 53, 59, 61, 67, 71, 73, 79, 83, 89,
    ];
    let mut kin = Kinematics::new(model);
    let mut ten = TendonKinematics::new(model);
    let mut lengths_at = |q: &[f64], model: &Model| -> Vec<f64> {
        let mut q = q.to_vec();
        model.apply_couplings(&mut q);
        kin.update(model, &q);
        ten.update(model, &kin);
        needed
            .iter()
            .map(|&a| actuator_length(model, model.actuators[a].transmission, &ten, &q))
            .collect()
    };
    let n = needed.len();
    let mut lo = vec![(f64::INFINITY, model.qpos0.clone()); n];
    let mut hi = vec![(f64::NEG_INFINITY, model.qpos0.clone()); n];
    for k in 1..=LENGTHRANGE_SAMPLES {
        let mut q = model.qpos0.clone();
        for (i, (j, r)) in free_joints.iter().enumerate() {
            // Beyond 24 joints, fall back to a scrambled index so every joint still varies.
            let u = radical_inverse(k + i * 7919, PRIMES[i % PRIMES.len()]);
            q[model.joints[*j].qpos_adr] = r[0] + u * (r[1] - r[0]);
        }
        let l = lengths_at(&q, model);
        for i in 0..n {
            if l[i] < lo[i].0 {
                lo[i] = (l[i], q.clone());
            }
            if l[i] > hi[i].0 {
                hi[i] = (l[i], q.clone());
            }
        }
    }
    // Coordinate search from each extreme over the joint limits and midpoints.
    for i in 0..n {
        for (best, sign) in [(&mut lo[i], 1.0), (&mut hi[i], -1.0)] {
            for _ in 0..3 {
                for (j, r) in &free_joints {
                    let adr = model.joints[*j].qpos_adr;
                    for v in [r[0], r[1], 0.5 * (r[0] + r[1])] {
                        let mut q = best.1.clone();
                        q[adr] = v;
                        let l = lengths_at(&q, model)[i];
                        if sign * l < sign * best.0 {
                            *best = (l, q);
                        }
                    }
                }
            }
        }
    }
    for (i, &a) in needed.iter().enumerate() {
        model.actuators[a].lengthrange = [lo[i].0, hi[i].0];
    }
}
