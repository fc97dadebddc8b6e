#!/usr/bin/env python3
"""How much the ball's sliding friction changes a table bounce in MuJoCo's MyoChallenge scene.

    python tools/mujoco_ball_friction.py

MyoChallenge's P2 draws the ball's sliding friction from U(0.9, 1.1) each episode. This drops balls on
the table of sim/tests/fixtures/myosuite_tt_ball_only.xml (the scene's ball, table, net and floor) at
horizontal speeds 0.5-10 m/s and vertical speeds 1-10 m/s, with friction 0.9, 1.0 and 1.1, and prints
per bounce the rebound ratio (vertical speed out / in) and the horizontal speed kept (out / in),
measured over the steps that have a contact. docs/simulator.md quotes what it prints. Needs
`pip install mujoco numpy`.
"""
import os
import sys

try:
    import mujoco
except ImportError as e:  # pragma: no cover - reported to the caller
    sys.exit(f"mujoco_ball_friction.py needs the mujoco package (pip install mujoco): {e}")

HERE = os.path.dirname(os.path.abspath(__file__))
MODEL = os.path.join(HERE, "..", "sim", "tests", "fixtures", "myosuite_tt_ball_only.xml")


def bounce(m, d, ball, mu, vx, vz):
    """(vertical rebound ratio, horizontal speed kept) of one bounce on the table."""
    m.geom_friction[ball] = [mu, 0.005, 0.0001]
    mujoco.mj_resetData(m, d)
    joint = m.body_jntadr[m.geom_bodyid[ball]]
    qa, va = m.jnt_qposadr[joint], m.jnt_dofadr[joint]
    d.qpos[qa:qa + 7] = [0.6, 0.0, 0.9, 1, 0, 0, 0]
    d.qvel[va:va + 6] = [vx, 0.0, -vz, 0, 0, 0]
    before = None
    for _ in range(3000):
        v = d.qvel[va:va + 3].copy()
        mujoco.mj_step(m, d)
        if d.ncon > 0 and before is None:
            before = v
        if before is not None and d.ncon == 0:
            after = d.qvel[va:va + 3]
            return after[2] / -before[2], after[0] / before[0]
    raise RuntimeError("no bounce")


def main():
    m = mujoco.MjModel.from_xml_path(MODEL)
    d = mujoco.MjData(m)
    ball = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "pingpong")
    print(f"MuJoCo {mujoco.__version__}; per friction 0.9 / 1.0 / 1.1")
    print("vx m/s  vz m/s  rebound ratio              horizontal speed kept")
    for vx in (0.5, 3.0, 10.0):
        for vz in (1.0, 3.0, 10.0):
            r = [bounce(m, d, ball, mu, vx, vz) for mu in (0.9, 1.0, 1.1)]
            ez = " ".join(f"{x[0]:.5f}" for x in r)
            kx = " ".join(f"{x[1]:.6f}" for x in r)
            print(f"{vx:5.1f}  {vz:6.1f}  {ez}  {kx}")


if __name__ == "__main__":
    main()
