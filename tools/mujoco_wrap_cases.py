#!/usr/bin/env python3
"""Writes MuJoCo's tendon lengths and moment arms for random single-wrap cases, one small model each,
for muscle-rally's wrapping tests (sim/tests/mujoco_kinematics.rs, `wrap_cases_match_mujoco`).

    python tools/mujoco_wrap_cases.py OUT.json [--cases 180] [--seed 0]

Each case is a tendon from a site on the world, over a sphere or a cylinder on a body turned by
three hinges, to a site on a child body turned by a fourth: with no side site, a side site outside
the geom, or one inside it (MuJoCo's inside wrap); some cases put the path close to grazing the
geom. The fixture holds each case's MJCF text, its qpos and MuJoCo's length and moment arms
(`ten_J`), and whether MuJoCo wrapped. Needs `pip install mujoco numpy`.
"""
import argparse
import json
import sys

try:
    import mujoco
    import numpy as np
except ImportError as e:  # pragma: no cover
    sys.exit(f"mujoco_wrap_cases.py needs mujoco and numpy (pip install mujoco numpy): {e}")

KINDS = ("none", "outside", "inside")


def vec(v):
    return " ".join(repr(float(x)) for x in v)


def unit(rng):
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def case_xml(rng, shape, kind):
    radius = float(rng.uniform(0.01, 0.05))
    size = f"{radius!r} {float(rng.uniform(0.02, 0.1))!r}" if shape == "cylinder" else repr(radius)
    quat = rng.normal(size=4)
    quat /= np.linalg.norm(quat)
    geom_pos = rng.uniform(-0.01, 0.01, 3)
    # Ends 1.2 to 5 radii from the geom's centre, on random sides.
    a = geom_pos + unit(rng) * radius * rng.uniform(1.2, 5.0) + np.array([0, 0, 0.3])
    c = unit(rng) * radius * rng.uniform(1.2, 5.0)
    if kind == "inside":
        side = geom_pos + unit(rng) * radius * rng.uniform(0.0, 0.9)
    else:
        side = geom_pos + unit(rng) * radius * rng.uniform(1.5, 4.0)
    side_site = f'<site name="side" pos="{vec(side)}"/>' if kind != "none" else ""
    side_attr = ' sidesite="side"' if kind != "none" else ""
    return f"""<mujoco model="wrap_case">
  <compiler angle="radian"/>
  <worldbody>
    <site name="a" pos="{vec(a)}"/>
    <body name="b" pos="0 0 0.3">
      <joint name="bx" axis="1 0 0"/><joint name="by" axis="0 1 0"/><joint name="bz" axis="0 0 1"/>
      <inertial pos="0 0 0" mass="1" diaginertia="0.01 0.01 0.01"/>
      <geom name="wrap" type="{shape}" size="{size}" pos="{vec(geom_pos)}" quat="{vec(quat)}"/>
      {side_site}
      <body name="c" pos="{vec(unit(rng) * 0.02)}">
        <joint name="cy" axis="{vec(unit(rng))}"/>
        <inertial pos="0 0 0" mass="0.5" diaginertia="0.01 0.01 0.01"/>
        <site name="c" pos="{vec(c)}"/>
      </body>
    </body>
  </worldbody>
  <tendon>
    <spatial name="t"><site site="a"/><geom geom="wrap"{side_attr}/><site site="c"/></spatial>
  </tendon>
</mujoco>
"""


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out")
    ap.add_argument("--cases", type=int, default=180)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    cases = []
    for i in range(args.cases):
        shape = ("sphere", "cylinder")[i % 2]
        kind = KINDS[(i // 2) % 3]
        xml = case_xml(rng, shape, kind)
        m = mujoco.MjModel.from_xml_string(xml)
        d = mujoco.MjData(m)
        d.qpos[:] = rng.uniform(-1.5, 1.5, m.nq)
        mujoco.mj_forward(m, d)
        moment = np.zeros(m.nv)
        mujoco.mju_sparse2dense(moment.reshape(1, m.nv), d.ten_J, m.ten_J_rownnz, m.ten_J_rowadr, m.ten_J_colind)
        cases.append({
            "shape": shape,
            "side": kind,
            "xml": xml,
            "qpos": d.qpos.tolist(),
            "length": float(d.ten_length[0]),
            "moment": moment.tolist(),
            "wrapped": int(d.ten_wrapnum[0]) == 4,
        })
    with open(args.out, "w") as f:
        json.dump({"mujoco_version": mujoco.__version__, "cases": cases}, f)
    wrapped = sum(c["wrapped"] for c in cases)
    print(f"wrote {args.out}: {len(cases)} cases, {wrapped} wrapped (MuJoCo {mujoco.__version__})")


if __name__ == "__main__":
    main()
