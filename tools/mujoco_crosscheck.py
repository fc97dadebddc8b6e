#!/usr/bin/env python3
"""Writes MuJoCo's view of a model to a JSON fixture, for muscle-rally's Rust tests to compare against.

    python tools/mujoco_crosscheck.py MODEL.xml OUT.json [--configs 24] [--seed 0] [--steps 250]

For `--configs` joint configurations sampled within the joint limits (independent joints uniform in
the middle 90% of their range, dependent joints set by their equality polynomials, free joints at a
random pose), it records MuJoCo's actuator lengths, moment arms (`actuator_moment`, dense nu x nv),
site positions, body poses, the joint-space mass matrix and the bias force (Coriolis + gravity +
passive). It then records two 0.5 s motions from the model's first keyframe (or qpos0): "passive"
(all controls zero) and "actuated" (constant controls 0.2..0.8 per actuator), each step's qpos,
qvel and activation. Needs `pip install mujoco numpy`.
"""
import argparse
import json
import os
import sys

try:
    import mujoco
    import numpy as np
except ImportError as e:  # pragma: no cover
    sys.exit(f"mujoco_crosscheck.py needs mujoco and numpy (pip install mujoco numpy): {e}")


def dense_moment(m, d):
    out = np.zeros((m.nu, m.nv))
    mujoco.mju_sparse2dense(out, d.actuator_moment, d.moment_rownnz, d.moment_rowadr, d.moment_colind)
    return out


def couplings(m):
    """(dependent qpos adr, independent qpos adr, polycoef) for active joint equalities."""
    out = []
    for i in range(m.neq):
        if m.eq_type[i] != mujoco.mjtEq.mjEQ_JOINT or not m.eq_active0[i]:
            continue
        j1, j2 = m.eq_obj1id[i], m.eq_obj2id[i]
        out.append((m.jnt_qposadr[j1], m.jnt_qposadr[j2], m.eq_data[i][:5].copy()))
    return out


def apply_couplings(m, qpos, coup, qvel=None):
    for dep, ind, c in coup:
        x = qpos[ind] - m.qpos0[ind]
        qpos[dep] = m.qpos0[dep] + c[0] + c[1] * x + c[2] * x**2 + c[3] * x**3 + c[4] * x**4
        if qvel is not None:
            dv = c[1] + 2 * c[2] * x + 3 * c[3] * x**2 + 4 * c[4] * x**3
            # qvel and qpos share addresses for hinge/slide joints only; map through the joint.
            jd = list(m.jnt_qposadr).index(dep)
            ji = list(m.jnt_qposadr).index(ind)
            qvel[m.jnt_dofadr[jd]] = dv * qvel[m.jnt_dofadr[ji]]


def sample_config(m, rng, coup):
    qpos = m.qpos0.copy()
    dependents = {dep for dep, _, _ in coup}
    for j in range(m.njnt):
        adr = m.jnt_qposadr[j]
        t = m.jnt_type[j]
        if t == mujoco.mjtJoint.mjJNT_FREE:
            qpos[adr:adr + 3] = m.qpos0[adr:adr + 3] + rng.uniform(-0.2, 0.2, 3)
            q = rng.normal(size=4)
            qpos[adr + 3:adr + 7] = q / np.linalg.norm(q)
            continue
        if adr in dependents:
            continue
        if m.jnt_limited[j]:
            lo, hi = m.jnt_range[j]
            mid, half = 0.5 * (lo + hi), 0.45 * (hi - lo)
            qpos[adr] = rng.uniform(mid - half, mid + half)
        else:
            qpos[adr] = m.qpos0[adr] + rng.uniform(-1.0, 1.0)
    apply_couplings(m, qpos, coup)
    return qpos


def position_record(m, d):
    mujoco.mj_forward(m, d)
    M = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M)
    return {
        "qpos": d.qpos.tolist(),
        "qvel": d.qvel.tolist(),
        "actuator_length": d.actuator_length.tolist(),
        "actuator_velocity": d.actuator_velocity.tolist(),
        "actuator_moment": dense_moment(m, d).tolist(),
        "site_xpos": d.site_xpos.tolist(),
        "body_xpos": d.xpos.tolist(),
        "body_xquat": d.xquat.tolist(),
        "mass_matrix": M.tolist(),
        "qfrc_bias": d.qfrc_bias.tolist(),
        "qfrc_passive": d.qfrc_passive.tolist(),
    }


def motion(m, d, start_qpos, ctrl, steps):
    mujoco.mj_resetData(m, d)
    d.qpos[:] = start_qpos
    d.ctrl[:] = ctrl
    qpos, qvel, act = [], [], []
    for _ in range(steps):
        mujoco.mj_step(m, d)
        qpos.append(d.qpos.tolist())
        qvel.append(d.qvel.tolist())
        act.append(d.act.tolist())
    return {"start_qpos": list(map(float, start_qpos)), "ctrl": list(map(float, ctrl)), "qpos": qpos, "qvel": qvel, "act": act}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("model")
    ap.add_argument("out")
    ap.add_argument("--configs", type=int, default=24)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--steps", type=int, default=250)
    args = ap.parse_args()

    m = mujoco.MjModel.from_xml_path(args.model)
    d = mujoco.MjData(m)
    rng = np.random.default_rng(args.seed)
    coup = couplings(m)

    configs = []
    for _ in range(args.configs):
        mujoco.mj_resetData(m, d)
        d.qpos[:] = sample_config(m, rng, coup)
        # A velocity too, for actuator velocities and the Coriolis terms.
        qvel = rng.uniform(-1.0, 1.0, m.nv)
        apply_couplings(m, d.qpos.copy(), coup, qvel)
        d.qvel[:] = qvel
        configs.append(position_record(m, d))

    start = m.key_qpos[0].copy() if m.nkey > 0 else m.qpos0.copy()
    apply_couplings(m, start, coup)
    ctrl_rng = np.random.default_rng(args.seed + 1)
    actuated = np.zeros(m.nu)
    for i in range(m.nu):
        lo, hi = m.actuator_ctrlrange[i] if m.actuator_ctrllimited[i] else (0.0, 1.0)
        if m.actuator_dyntype[i] == mujoco.mjtDyn.mjDYN_MUSCLE:
            actuated[i] = ctrl_rng.uniform(0.2, 0.8)
        else:  # position servos hold their start position
            j = m.actuator_trnid[i][0]
            actuated[i] = np.clip(start[m.jnt_qposadr[j]], lo, hi)
    passive = np.zeros(m.nu)
    for i in range(m.nu):
        if m.actuator_dyntype[i] != mujoco.mjtDyn.mjDYN_MUSCLE:
            passive[i] = actuated[i]

    fixture = {
        "mujoco_version": mujoco.__version__,
        "model": os.path.basename(args.model),
        "nq": int(m.nq),
        "nv": int(m.nv),
        "nu": int(m.nu),
        "joint_names": [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) for j in range(m.njnt)],
        "actuator_names": [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, i) for i in range(m.nu)],
        "body_mass": m.body_mass.tolist(),
        "body_inertia": m.body_inertia.tolist(),
        "body_ipos": m.body_ipos.tolist(),
        "actuator_lengthrange": m.actuator_lengthrange.tolist(),
        "configs": configs,
        "motions": {
            "passive": motion(m, d, start, passive, args.steps),
            "actuated": motion(m, d, start, actuated, args.steps),
        },
    }
    with open(args.out, "w") as f:
        json.dump(fixture, f)
    print(f"wrote {args.out}: {len(configs)} configurations, 2 motions of {args.steps} steps (MuJoCo {mujoco.__version__})")


if __name__ == "__main__":
    main()
