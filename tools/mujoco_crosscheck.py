#!/usr/bin/env python3
"""Writes MuJoCo's view of a model to a JSON fixture, for muscle-rally's Rust tests to compare against.

    python tools/mujoco_crosscheck.py MODEL.xml OUT.json [--configs 24] [--seed 0] [--steps 250]
        [--keyframe-config] [--no-contacts]

For `--configs` joint configurations sampled within the joint limits (independent joints uniform in
the middle 90% of their range, dependent joints set by their equality polynomials, free joints at a
random pose), it records MuJoCo's actuator lengths, moment arms (`actuator_moment`, dense nu x nv),
site positions, body poses, the joint-space mass matrix and the bias force (Coriolis + gravity +
passive). It then records two 0.5 s motions from the model's first keyframe (or qpos0): "passive"
(muscle controls zero; from the keyframe named "hang" if there is one) and "actuated" (constant muscle
controls drawn in --ctrl-range; from the first keyframe), each step's qpos,
qvel and activation. Both motions must stay clear of the joint limits (where MuJoCo's constraint solver
and ours differ by design): starting from that posture, the tool perturbs the start (and, for the
actuated motion, redraws the controls) until the whole 0.5 s stays at least --clearance from every
limit, and records the clearance it found. `--keyframe-config` records the first keyframe (with a random
velocity) before the sampled configurations; `--no-contacts` turns MuJoCo's contacts off for the motions
(muscle-rally does not simulate contacts between body parts); `--fd-moments` also records the moment arms
as five-point differences of MuJoCo's lengths (null where two step sizes disagree). Needs `pip install mujoco numpy`.
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
    """(dependent qpos adr, independent qpos adr or None for a locked joint, polycoef) for active
    joint equalities."""
    out = []
    for i in range(m.neq):
        if m.eq_type[i] != mujoco.mjtEq.mjEQ_JOINT or not m.eq_active0[i]:
            continue
        j1, j2 = m.eq_obj1id[i], m.eq_obj2id[i]
        out.append((m.jnt_qposadr[j1], m.jnt_qposadr[j2] if j2 >= 0 else None, m.eq_data[i][:5].copy()))
    return out


def apply_couplings(m, qpos, coup, qvel=None):
    for dep, ind, c in coup:
        if ind is None:
            qpos[dep] = m.qpos0[dep] + c[0]
            if qvel is not None:
                qvel[m.jnt_dofadr[list(m.jnt_qposadr).index(dep)]] = 0.0
            continue
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


def mid_range(m, coup):
    """qpos0 with every independent limited hinge or slide at the middle of its range."""
    qpos = m.qpos0.copy()
    dependents = {dep for dep, _, _ in coup}
    for j in range(m.njnt):
        adr = m.jnt_qposadr[j]
        if m.jnt_limited[j] and adr not in dependents and m.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE:
            qpos[adr] = 0.5 * (m.jnt_range[j][0] + m.jnt_range[j][1])
    apply_couplings(m, qpos, coup)
    return qpos


def fd_moments(m, d, h):
    """Moment arms as MuJoCo's lengths' derivatives: a five-point central difference of
    `actuator_length` in each hinge and slide joint alone (dependent joints too: a moment arm is the
    partial derivative per degree of freedom), error O(h^4). Columns of other joints are NaN."""
    q0 = d.qpos.copy()
    out = np.full((m.nu, m.nv), np.nan)
    for j in range(m.njnt):
        if int(m.jnt_type[j]) not in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)):
            continue
        adr, dof = m.jnt_qposadr[j], m.jnt_dofadr[j]
        lengths = []
        for k in (-2, -1, 1, 2):
            d.qpos[:] = q0
            d.qpos[adr] += k * h
            mujoco.mj_fwdPosition(m, d)
            lengths.append(d.actuator_length.copy())
        out[:, dof] = (lengths[0] - 8 * lengths[1] + 8 * lengths[2] - lengths[3]) / (12 * h)
    d.qpos[:] = q0
    return out


def smooth_fd_moments(m, d):
    """`fd_moments` at h = 1e-3 where a second step, 2e-3, agrees with it to 1e-10 of the row's
    largest entry; None where it does not (the length has a kink that close: a wrap changing side or
    starting) or where the joint is not a hinge or slide."""
    a, b = fd_moments(m, d, 1e-3), fd_moments(m, d, 2e-3)
    scale = np.maximum(np.nanmax(np.abs(a), axis=1, initial=0.0), 1e-3)[:, None]
    ok = np.abs(a - b) <= 1e-10 * scale
    return [[float(x) if good else None for x, good in zip(row, oks)] for row, oks in zip(a, ok)]


def position_record(m, d, fd=False):
    fd_rows = smooth_fd_moments(m, d) if fd else None
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
        **({"actuator_moment_fd": fd_rows} if fd else {}),
    }


def motion(m, d, start_qpos, ctrl, steps, start_qvel=None):
    mujoco.mj_resetData(m, d)
    d.qpos[:] = start_qpos
    if start_qvel is not None:
        d.qvel[:] = start_qvel
    d.ctrl[:] = ctrl
    qpos, qvel, act = [], [], []
    for _ in range(steps):
        mujoco.mj_step(m, d)
        qpos.append(d.qpos.tolist())
        qvel.append(d.qvel.tolist())
        act.append(d.act.tolist())
    start_qvel = np.zeros(m.nv) if start_qvel is None else start_qvel
    return {"start_qpos": list(map(float, start_qpos)), "start_qvel": list(map(float, start_qvel)),
            "ctrl": list(map(float, ctrl)), "qpos": qpos, "qvel": qvel, "act": act}


def locked_joints(m):
    """Joints an equality locks in place (joint1 without joint2): they never approach their limits."""
    return {m.eq_obj1id[i] for i in range(m.neq)
            if m.eq_type[i] == mujoco.mjtEq.mjEQ_JOINT and m.eq_active0[i] and m.eq_obj2id[i] < 0}


def limit_clearance(m, qpos_rows):
    """Smallest distance of any limited hinge/slide joint (locked ones aside) from its limits over a
    trajectory."""
    worst = np.inf
    q = np.asarray(qpos_rows)
    locked = locked_joints(m)
    for j in range(m.njnt):
        if not m.jnt_limited[j] or m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE or j in locked:
            continue
        lo, hi = m.jnt_range[j]
        col = q[:, m.jnt_qposadr[j]]
        worst = min(worst, float(np.min(col - lo)), float(np.min(hi - col)))
    return worst


def clear_motion(m, d, start, ctrl_for, steps, clearance, rng, coup, tries=300, start_qvel=None):
    """The first motion, from `start` perturbed, that stays `clearance` away from every joint limit."""
    best = None
    for attempt in range(tries):
        s = start.copy()
        if attempt > 0:
            for j in range(m.njnt):
                adr = m.jnt_qposadr[j]
                if m.jnt_type[j] in (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE):
                    s[adr] += rng.normal(0.0, 0.03)
                    if m.jnt_limited[j]:
                        lo, hi = m.jnt_range[j]
                        s[adr] = np.clip(s[adr], lo + 2 * clearance, hi - 2 * clearance)
            apply_couplings(m, s, coup)
        ctrl = ctrl_for(s, attempt)
        rec = motion(m, d, s, ctrl, steps, start_qvel)
        c = limit_clearance(m, [s] + rec["qpos"])
        rec["limit_clearance"] = c
        if c >= clearance:
            return rec
        if best is None or c > best["limit_clearance"]:
            best = rec
    sys.exit(f"no motion stayed {clearance} clear of the joint limits in {tries} tries (best {best['limit_clearance']:.4f})")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("model")
    ap.add_argument("out")
    ap.add_argument("--configs", type=int, default=24)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--steps", type=int, default=250)
    ap.add_argument("--clearance", type=float, default=0.02, help="rad or m from every joint limit")
    ap.add_argument("--ctrl-range", type=float, nargs=2, default=(0.05, 0.3), help="muscle controls of the actuated motion")
    ap.add_argument("--actuated-key", default=None, help="keyframe the actuated motion starts from (default: the first)")
    ap.add_argument("--quiet", default="", help="comma-separated muscles left at zero control in the actuated motion")
    ap.add_argument("--keyframe-config", action="store_true", help="record the first keyframe before the sampled configurations")
    ap.add_argument("--no-contacts", action="store_true", help="disable contacts (mjDSBL_CONTACT)")
    ap.add_argument("--fd-moments", action="store_true",
                    help="also record the moment arms as finite differences of MuJoCo's lengths "
                         "(actuator_moment_fd), a check independent of MuJoCo's own moment-arm solve")
    ap.add_argument("--motion-start", choices=["key", "mid"], default="key",
                    help="start the motions from the keyframes (default) or with every independent limited joint "
                         "at the middle of its range")
    args = ap.parse_args()

    m = mujoco.MjModel.from_xml_path(args.model)
    if args.no_contacts:
        m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    d = mujoco.MjData(m)
    rng = np.random.default_rng(args.seed)
    coup = couplings(m)

    configs = []
    starts = []
    if args.keyframe_config and m.nkey > 0:
        q = m.key_qpos[0].copy()
        apply_couplings(m, q, coup)
        starts.append(q)
    for _ in range(args.configs):
        starts.append(None)
    for fixed in starts:
        mujoco.mj_resetData(m, d)
        d.qpos[:] = sample_config(m, rng, coup) if fixed is None else fixed
        # A velocity too, for actuator velocities and the Coriolis terms.
        qvel = rng.uniform(-1.0, 1.0, m.nv)
        apply_couplings(m, d.qpos.copy(), coup, qvel)
        d.qvel[:] = qvel
        configs.append(position_record(m, d, args.fd_moments))

    start = m.key_qpos[0].copy() if m.nkey > 0 else m.qpos0.copy()
    start_qvel = m.key_qvel[0].copy() if m.nkey > 0 else np.zeros(m.nv)
    apply_couplings(m, start, coup)
    ctrl_rng = np.random.default_rng(args.seed + 1)
    motion_rng = np.random.default_rng(args.seed + 2)

    def servo_targets(s):
        ctrl = np.zeros(m.nu)
        for i in range(m.nu):
            if m.actuator_dyntype[i] != mujoco.mjtDyn.mjDYN_MUSCLE:  # position servos hold their start
                lo, hi = m.actuator_ctrlrange[i] if m.actuator_ctrllimited[i] else (-np.inf, np.inf)
                ctrl[i] = np.clip(s[m.jnt_qposadr[m.actuator_trnid[i][0]]], lo, hi)
        return ctrl

    def actuated_ctrl(s, attempt):
        ctrl = servo_targets(s)
        for i in range(m.nu):
            if m.actuator_dyntype[i] == mujoco.mjtDyn.mjDYN_MUSCLE and names[i] not in quiet:
                ctrl[i] = ctrl_rng.uniform(*args.ctrl_range)
        return ctrl

    names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, i) for i in range(m.nu)]
    quiet = set(filter(None, args.quiet.split(",")))
    unknown = quiet - set(names)
    if unknown:
        sys.exit(f"--quiet: no actuators named {sorted(unknown)}")

    def key(name, default):
        for k in range(m.nkey):
            if mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_KEY, k) == name:
                q = m.key_qpos[k].copy()
                apply_couplings(m, q, coup)
                return q
        if name is not None and name != "hang":
            sys.exit(f"no keyframe named {name}")
        return default

    if args.motion_start == "mid":
        start = mid_range(m, coup)
        start_qvel = np.zeros(m.nv)
        hang = act_start = start
    else:
        hang = key("hang", start)
        act_start = key(args.actuated_key, start)
    motions = {
        "passive": clear_motion(m, d, hang, lambda s, a: servo_targets(s), args.steps, args.clearance, motion_rng, coup,
                                start_qvel=start_qvel if hang is start else None),
        "actuated": clear_motion(m, d, act_start, actuated_ctrl, args.steps, args.clearance, motion_rng, coup,
                                 start_qvel=start_qvel if act_start is start else None),
    }

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
        "contacts": not args.no_contacts,
        "configs": configs,
        "motions": motions,
    }
    with open(args.out, "w") as f:
        json.dump(fixture, f)
    print(f"wrote {args.out}: {len(configs)} configurations, 2 motions of {args.steps} steps (MuJoCo {mujoco.__version__})")


if __name__ == "__main__":
    main()
