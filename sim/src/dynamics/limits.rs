//! Soft joint limits: MuJoCo's soft constraint on each violated limit, solved on its own in the
//! step's independent coordinates.

use nalgebra::DVector;

use super::{Data, State};
use crate::model::Model;

/// Soft joint limits: MuJoCo's default `solreflimit = (0.02, 1)` (time constant, damping ratio) and
/// `solimplimit = (0.9, 0.95, 0.001)`; a joint may set its own.
pub const LIMIT_SOLREF: [f64; 2] = [0.02, 1.0];
/// See [`LIMIT_SOLREF`].
pub const LIMIT_SOLIMP: [f64; 3] = [0.9, 0.95, 0.001];

/// Limit forces in independent coordinates: each violated limit is MuJoCo's soft constraint solved on
/// its own, with the effective inverse inertia `(lhs⁻¹)_rr` of its degree of freedom (from the
/// factorisation `ch` of `lhs`) and the unconstrained acceleration `a0`.
pub(super) fn limit_forces(
    model: &Model,
    data: &Data,
    state: &State,
    ch: &nalgebra::Cholesky<f64, nalgebra::Dyn>,
    a0: &DVector<f64>,
) -> DVector<f64> {
    let nr = data.independent_dofs.len();
    let mut out = DVector::zeros(nr);
    let violated: Vec<(usize, f64, f64)> = data
        .independent_dofs
        .iter()
        .enumerate()
        .filter_map(|(r, &d)| {
            let joint = &model.joints[model.dof_joint[d]];
            let [lo, hi] = joint.range?;
            let q = state.qpos[joint.qpos_adr];
            if q < lo {
                Some((r, q - lo, 1.0))
            } else if q > hi {
                Some((r, hi - q, -1.0))
            } else {
                None
            }
        })
        .collect();
    if violated.is_empty() {
        return out;
    }
    for (r, dist, sign) in violated {
        let d = data.independent_dofs[r];
        let joint = &model.joints[model.dof_joint[d]];
        let [timeconst, dampratio] = joint.limit_solref;
        // MuJoCo's "refsafe": the time constant is at least two timesteps.
        let timeconst = timeconst.max(2.0 * model.timestep);
        let dmax = joint.limit_solimp[1];
        let k = 1.0 / (dmax * dmax * timeconst * timeconst * dampratio * dampratio);
        let b = 2.0 / (dmax * timeconst);
        let imp = crate::contact::impedance(&joint.limit_solimp, -dist);
        let vel = sign * state.qvel[d];
        let a_ref = -b * vel - k * imp * dist;
        // (lhs⁻¹)_rr = |L⁻¹·e_r|².
        let mut e = DVector::zeros(a0.len());
        e[r] = 1.0;
        let a_inv = ch
            .l_dirty()
            .solve_lower_triangular(&e)
            .map_or(0.0, |x| x.norm_squared());
        let r_reg = (1.0 - imp) / imp * a_inv;
        let a_unc = sign * a0[r];
        if a_ref > a_unc {
            out[r] = sign * (a_ref - a_unc) / (a_inv + r_reg);
        }
    }
    out
}
