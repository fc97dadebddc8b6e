#!/usr/bin/env python3
"""Times MuJoCo on the same robot work as `rally bench robot`: mj_step(m, d, nstep=2000) from the
"ready" keyframe with every muscle at control and activation 0.1 (the pelvis servos holding still), for
  - one robot: config/models/upper_body.xml as it is;
  - the dual arena: two copies attached to the reference ball scene
    (sim/tests/fixtures/myosuite_tt_ball_only.xml) with MjSpec, the second turned 180 degrees about
    (0, 0.04), and the ball in flight.
Prints one JSON object: {"single_steps_per_second", "dual_steps_per_second", "mujoco_version"}.
With `--model FILE` (e.g. the MyoChallenge robot `rally model import myosuite` wrote) it times that file
alone, from its "ready" keyframe or else its first, muscles at 0.1, position servos holding their joint's
keyframe position, and prints no dual rate (`rally bench` compares the dual arena with two of these steps).
Needs `pip install mujoco numpy`.
"""
import argparse
import json
import os
import sys
import time

try:
    import mujoco
    import numpy as np
except ImportError as e:  # pragma: no cover
    sys.exit(f"bench_robot.py needs mujoco and numpy (pip install mujoco numpy): {e}")

HERE = os.path.dirname(os.path.abspath(__file__))
ROBOT = os.path.join(HERE, "..", "config", "models", "upper_body.xml")
BALL_SCENE = os.path.join(HERE, "..", "sim", "tests", "fixtures", "myosuite_tt_ball_only.xml")
NSTEP = 2000


def dual_model():
    scene = mujoco.MjSpec.from_file(BALL_SCENE)
    for prefix, pos, euler in (("a_", [0, 0, 0], [0, 0, 0]), ("b_", [0, 0.08, 0], [0, 0, np.pi])):
        robot = mujoco.MjSpec.from_file(ROBOT)
        frame = scene.worldbody.add_frame(pos=pos, euler=euler)
        frame.attach_body(robot.body("root"), prefix, "")
    return scene.compile()


def ready_state(m, d, robots, single, key):
    """Reset to each robot's "ready" keyframe, muscles at 0.1, servos at 0."""
    mujoco.mj_resetData(m, d)
    for r in range(robots):
        d.qpos[r * single.nq:(r + 1) * single.nq] = key
    for i in range(m.nu):
        d.ctrl[i] = 0.1 if m.actuator_dyntype[i] == mujoco.mjtDyn.mjDYN_MUSCLE else 0.0
    d.act[:] = 0.1
    if m.nq > robots * single.nq:  # the ball's free joint comes last
        b = robots * single.nq
        d.qpos[b:b + 7] = (-1.2, -0.45, 1.45, 1, 0, 0, 0)
        d.qvel[robots * single.nv:robots * single.nv + 3] = (5.6, 1.6, 0.1)


def rate(m, robots, seconds):
    single = mujoco.MjModel.from_xml_path(ROBOT)
    names = [mujoco.mj_id2name(single, mujoco.mjtObj.mjOBJ_KEY, k) for k in range(single.nkey)]
    key = single.key_qpos[names.index("ready")].copy()
    d = mujoco.MjData(m)
    steps = 0
    start = time.perf_counter()
    while time.perf_counter() - start < seconds:
        ready_state(m, d, robots, single, key)
        mujoco.mj_step(m, d, nstep=NSTEP)
        steps += NSTEP
    return steps / (time.perf_counter() - start)


def model_rate(path, seconds):
    """One model from its keyframe: muscles at 0.1, servos holding their joint's keyframe position."""
    m = mujoco.MjModel.from_xml_path(path)
    names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_KEY, k) for k in range(m.nkey)]
    key = names.index("ready") if "ready" in names else 0
    d = mujoco.MjData(m)
    steps = 0
    start = time.perf_counter()
    while time.perf_counter() - start < seconds:
        mujoco.mj_resetDataKeyframe(m, d, key)
        for i in range(m.nu):
            if m.actuator_dyntype[i] == mujoco.mjtDyn.mjDYN_MUSCLE:
                d.ctrl[i] = 0.1
            else:
                q = d.qpos[m.jnt_qposadr[m.actuator_trnid[i][0]]]
                lo, hi = m.actuator_ctrlrange[i] if m.actuator_ctrllimited[i] else (-np.inf, np.inf)
                d.ctrl[i] = min(max(q, lo), hi)
        d.act[:] = 0.1
        mujoco.mj_step(m, d, nstep=NSTEP)
        steps += NSTEP
    return steps / (time.perf_counter() - start)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--model", help="time this MJCF file alone")
    args = ap.parse_args()
    if args.model:
        print(json.dumps({
            "single_steps_per_second": model_rate(args.model, args.seconds),
            "mujoco_version": mujoco.__version__,
        }))
        return
    single = mujoco.MjModel.from_xml_path(ROBOT)
    dual = dual_model()
    print(json.dumps({
        "single_steps_per_second": rate(single, 1, args.seconds),
        "dual_steps_per_second": rate(dual, 2, args.seconds),
        "mujoco_version": mujoco.__version__,
    }))


if __name__ == "__main__":
    main()
