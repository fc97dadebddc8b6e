#!/usr/bin/env python3
"""Times MuJoCo on the ball-only reference scene, the same work as `rally bench ball`.

Loads sim/tests/fixtures/myosuite_tt_ball_only.xml (the MyoChallenge scene's ball, table, net and
floor), serves P2-style balls at side A and steps each for 300 control steps (1500 physics steps)
with one `mj_step(m, d, nstep=1500)` call, so no Python loop runs per step. Prints one JSON object:
{"steps_per_second": ..., "steps": ..., "mujoco_version": ...}. Needs `pip install mujoco numpy`.
"""
import argparse
import json
import os
import sys
import time

try:
    import mujoco
    import numpy as np
except ImportError as e:  # pragma: no cover - reported to the caller
    sys.exit(f"bench_ball.py needs the mujoco and numpy packages (pip install mujoco numpy): {e}")

HERE = os.path.dirname(os.path.abspath(__file__))
MODEL = os.path.join(HERE, "..", "sim", "tests", "fixtures", "myosuite_tt_ball_only.xml")
STEPS_PER_SERVE = 1500


def p2_serve(rng):
    """MyoChallenge P2 sampling (docs/design.md §4)."""
    x, y, z = rng.uniform(-1.25, -0.8), rng.uniform(-0.5, 0.5), rng.uniform(1.4, 1.5)
    vz = rng.uniform(-0.1, 0.1)
    ax, ay = rng.uniform(0.5, 1.35), rng.uniform(-0.6, 0.7)
    t = (vz + np.sqrt(vz * vz + 2 * 9.81 * (z - 0.785))) / 9.81
    return (x, y, z), ((ax - x) / t, (ay - y) / t, vz)


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=3.0)
    args = ap.parse_args()
    m = mujoco.MjModel.from_xml_path(MODEL)
    d = mujoco.MjData(m)
    rng = np.random.default_rng(1)
    steps = 0
    start = time.perf_counter()
    while time.perf_counter() - start < args.seconds:
        pos, vel = p2_serve(rng)
        mujoco.mj_resetData(m, d)
        d.qpos[:3] = pos
        d.qpos[3:7] = (1, 0, 0, 0)
        d.qvel[:3] = vel
        mujoco.mj_step(m, d, nstep=STEPS_PER_SERVE)
        steps += STEPS_PER_SERVE
    elapsed = time.perf_counter() - start
    print(json.dumps({"steps_per_second": steps / elapsed, "steps": steps, "mujoco_version": mujoco.__version__}))


if __name__ == "__main__":
    main()
