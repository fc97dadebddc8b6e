#!/usr/bin/env python3
"""Writes MyoSuite's MyoChallenge 2025 table-tennis robot as one MJCF file that muscle-rally loads.

    python tools/myosuite_import.py OUT.xml

`rally model import myosuite` runs this script (it is compiled into the binary) with a Python that has
myosuite 3.0.0; run by hand it does the same. Steps:

1. MyoSuite builds the challenge's scene from its parts (recipe `challenge_tabletennis`) and writes it
   as one flat MJCF (`materialize_recipe_xml`); MuJoCo compiles it (the reference model).
2. Bodies whose mass MuJoCo derives from geoms (13 of them from STL meshes) get that mass, centre of
   mass and inertia written as an explicit `<inertial>`, so no mesh file is needed.
3. What only a renderer or MyoSuite's environment uses goes: assets, mesh geoms, materials, cameras,
   lights, sensors, `<size>`, the floor and scenery geoms, the table and the ball (muscle-rally's ball
   world has its own), and the `<contact>` pairs (muscle-rally does not simulate contacts between body
   parts; MuJoCo's default collision filter stays in the file).
4. The paddle, a free body in MyoSuite held by finger contacts, becomes a body welded to the palm
   (`capitate_r`) at the pose it has relative to the palm in MyoSuite's keyframe: muscle-rally's grip
   holds it. Its mass, blade and handle stay as MyoSuite has them; the blade geom (`pad`) is named
   `blade`, as muscle-rally's paddles name it.
5. The keyframe keeps the robot's 58 joints.

The result is checked with MuJoCo before it is written: every muscle's parameters and every tendon's
length at the keyframe must equal the reference model's, every body but the palm must keep its mass.
Prints one JSON line describing what was written. Exit status 3 means an unexpected input (a MyoSuite
release this script does not know); the message says what differed.
"""
import json
import math
import sys
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

EXPECTED_MYOSUITE = "3.0.0"
RECIPE = "challenge_tabletennis"
PALM = "capitate_r"
PADDLE = "paddle"
DROPPED_BODIES = ("tabletennis_table", "pingpong")


def fail(msg, code=3):
    print(f"myosuite_import: {msg}", file=sys.stderr)
    sys.exit(code)


try:
    import mujoco
    import numpy as np
    import myosuite
    from myosuite.core.model_recipes import materialize_recipe_xml
except ImportError as e:  # pragma: no cover
    fail(f"needs myosuite {EXPECTED_MYOSUITE} (pip install myosuite=={EXPECTED_MYOSUITE}): {e}", 2)


def num(x):
    """A float as the shortest text that reads back to the same double."""
    return repr(float(x))


def nums(xs):
    return " ".join(num(x) for x in xs)


def myosuite_version():
    try:
        from importlib.metadata import version

        return version("myosuite")
    except Exception:  # noqa: BLE001
        return getattr(myosuite, "__version__", "unknown")


def package_version(name):
    try:
        from importlib.metadata import version

        return version(name)
    except Exception:  # noqa: BLE001
        return "unknown"


def parent_map(root):
    return {c: p for p in root.iter() for c in p}


def strip(root, ref):
    """Steps 2, 3 and 5 on the element tree; returns the paddle element (still in place)."""
    parents = parent_map(root)
    root.set("model", "myochallenge")
    for tag in ("size", "asset", "visual", "statistic", "sensor", "contact", "extension", "custom"):
        for e in root.findall(tag):
            root.remove(e)
    compiler = root.find("compiler")
    if compiler is not None:
        for k in ("meshdir", "texturedir", "assetdir"):
            compiler.attrib.pop(k, None)
    for e in list(root.iter()):
        e.attrib.pop("material", None)
    for tag in ("camera", "light"):
        for e in list(root.iter(tag)):
            parents[e].remove(e)
    worldbody = root.find("worldbody")
    for g in worldbody.findall("geom"):
        worldbody.remove(g)
    for name in DROPPED_BODIES:
        b = worldbody.find(f"body[@name='{name}']")
        if b is None:
            fail(f"no body '{name}' under <worldbody>")
        worldbody.remove(b)

    # Step 2: bake geom-derived inertia for every body without <inertial>.
    baked = []
    for body in root.iter("body"):
        if body.find("inertial") is not None:
            continue
        name = body.get("name")
        bid = mujoco.mj_name2id(ref, mujoco.mjtObj.mjOBJ_BODY, name)
        if bid < 0:
            fail(f"body '{name}' is not in the compiled model")
        if ref.body_mass[bid] <= 0:
            continue
        inertial = ET.Element("inertial", {
            "pos": nums(ref.body_ipos[bid]),
            "quat": nums(ref.body_iquat[bid]),
            "mass": num(ref.body_mass[bid]),
            "diaginertia": nums(ref.body_inertia[bid]),
        })
        body.insert(0, inertial)
        baked.append(name)
    parents = parent_map(root)
    for g in list(root.iter("geom")):
        if g.get("type") == "mesh" or "mesh" in g.attrib:
            parents[g].remove(g)
    for g in root.iter("geom"):
        for k in ("fluidcoef", "fluidshape", "shellinertia"):
            g.attrib.pop(k, None)
    return baked


def weld_paddle(root, ref):
    """Step 4: the free paddle becomes a child of the palm at its keyframe pose relative to it."""
    worldbody = root.find("worldbody")
    paddle = worldbody.find(f"body[@name='{PADDLE}']")
    if paddle is None:
        fail(f"no body '{PADDLE}' under <worldbody>")
    palm = next((b for b in root.iter("body") if b.get("name") == PALM), None)
    if palm is None:
        fail(f"no body '{PALM}'")
    d = mujoco.MjData(ref)
    mujoco.mj_resetDataKeyframe(ref, d, 0)
    mujoco.mj_kinematics(ref, d)
    hb = mujoco.mj_name2id(ref, mujoco.mjtObj.mjOBJ_BODY, PALM)
    pb = mujoco.mj_name2id(ref, mujoco.mjtObj.mjOBJ_BODY, PADDLE)
    # Plain Python floats in a fixed order, not numpy's matmul and norm: those call the BLAS, whose
    # kernel (chosen at run time for the CPU) changes the last bits, and so the file, from one machine
    # to another. MuJoCo's own functions are the same code on every machine.
    r = [float(v) for v in d.xmat[hb]]
    dp = [float(d.xpos[pb][i]) - float(d.xpos[hb][i]) for i in range(3)]
    rel_pos = [r[i] * dp[0] + r[3 + i] * dp[1] + r[6 + i] * dp[2] for i in range(3)]
    inv = np.zeros(4)
    mujoco.mju_negQuat(inv, d.xquat[hb])
    q = np.zeros(4)
    mujoco.mju_mulQuat(q, inv, d.xquat[pb])
    q = [float(v) for v in q]
    norm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    rel_quat = [v / norm for v in q]
    for j in paddle.findall("joint") + paddle.findall("freejoint"):
        paddle.remove(j)
    blade = paddle.find("geom[@name='pad']")
    if blade is None:
        fail(f"the paddle has no geom 'pad'")
    blade.set("name", "blade")
    paddle.set("pos", nums(rel_pos))
    paddle.set("quat", nums(rel_quat))
    worldbody.remove(paddle)
    palm.append(paddle)


def trim_keyframe(root, ref):
    """Step 5: the key's qpos for the robot's joints only (those before the paddle's free joint)."""
    nq_robot = int(ref.jnt_qposadr[mujoco.mj_name2id(ref, mujoco.mjtObj.mjOBJ_JOINT, "paddle_freejoint")])
    for key in root.iter("key"):
        for attr in ("qpos", "qvel"):
            if attr in key.attrib:
                vals = key.get(attr).split()
                key.set(attr, " ".join(vals[:nq_robot if attr == "qpos" else nq_robot]))
        for attr in ("act", "ctrl", "mpos", "mquat"):
            key.attrib.pop(attr, None)
    return nq_robot


def check(ref, out, nq_robot):
    """The written model keeps the reference's muscles, tendon paths and masses."""
    if out.nu != ref.nu or out.ntendon != ref.ntendon or out.nq != nq_robot:
        fail(f"counts differ: nu {out.nu}/{ref.nu}, ntendon {out.ntendon}/{ref.ntendon}, nq {out.nq}/{nq_robot}")
    for field in ("actuator_gainprm", "actuator_biasprm", "actuator_dynprm", "actuator_lengthrange",
                  "actuator_ctrlrange", "jnt_range", "dof_damping", "dof_armature"):
        a, b = getattr(out, field), getattr(ref, field)
        if field.startswith(("jnt_", "dof_")):
            b = b[: a.shape[0]]
        if not np.array_equal(a, b):
            fail(f"{field} differs from MyoSuite's model")
    dr, do = mujoco.MjData(ref), mujoco.MjData(out)
    mujoco.mj_resetDataKeyframe(ref, dr, 0)
    mujoco.mj_resetDataKeyframe(out, do, 0)
    mujoco.mj_forward(ref, dr)
    mujoco.mj_forward(out, do)
    worst = float(np.max(np.abs(do.ten_length - dr.ten_length)))
    if worst > 1e-12:
        fail(f"tendon lengths at the keyframe differ from MyoSuite's by up to {worst:.3g} m")
    palm = mujoco.mj_name2id(out, mujoco.mjtObj.mjOBJ_BODY, PALM)
    for b in range(out.nbody):
        name = mujoco.mj_id2name(out, mujoco.mjtObj.mjOBJ_BODY, b)
        rb = mujoco.mj_name2id(ref, mujoco.mjtObj.mjOBJ_BODY, name)
        if b != palm and abs(out.body_mass[b] - ref.body_mass[rb]) > 1e-12:
            fail(f"body '{name}' mass {out.body_mass[b]} differs from MyoSuite's {ref.body_mass[rb]}")
    return worst


def main():
    if len(sys.argv) != 2:
        fail("usage: myosuite_import.py OUT.xml", 2)
    out_path = Path(sys.argv[1])
    version = myosuite_version()
    if version != EXPECTED_MYOSUITE:
        fail(f"myosuite {version} is installed; this import is written for {EXPECTED_MYOSUITE}")
    with tempfile.TemporaryDirectory() as tmp:
        flat = materialize_recipe_xml(RECIPE, Path(tmp) / f"{RECIPE}.xml")
        ref = mujoco.MjModel.from_xml_path(str(flat))
        root = ET.parse(flat).getroot()
    baked = strip(root, ref)
    weld_paddle(root, ref)
    nq_robot = trim_keyframe(root, ref)
    ET.indent(root, space="  ")
    body = ET.tostring(root, encoding="unicode")
    out = mujoco.MjModel.from_xml_string(body)
    worst = check(ref, out, nq_robot)
    muscles = int(np.sum(out.actuator_dyntype == mujoco.mjtDyn.mjDYN_MUSCLE))
    header = (
        "<!--\n"
        f"  MyoChallenge 2025 table-tennis robot, imported by `rally model import myosuite`.\n"
        f"  Source: MyoSuite {version} (recipe '{RECIPE}', materialize_recipe_xml), myo_sim "
        f"{package_version('myo-sim')}, compiled with MuJoCo {mujoco.__version__}.\n"
        "  Licence: MyoSuite and myo_sim are Apache-2.0 (https://github.com/MyoHub/myosuite); this file is a\n"
        "  derived work under the same licence.\n"
        "  Changes from MyoSuite's file: geom-derived inertias written as <inertial> ("
        f"{', '.join(baked)}); assets, mesh geoms, materials, cameras, lights, sensors, <size>, <contact>,\n"
        "  scenery, table and ball removed; the paddle welded to capitate_r at its keyframe pose (its\n"
        f"  geom 'pad' named 'blade'); the keyframe cut to the robot's {nq_robot} qpos. Muscles, tendons,\n"
        "  joints and equalities are MyoSuite's.\n"
        "-->\n"
    )
    out_path.write_text(header + body + "\n", encoding="utf-8")
    print(json.dumps({
        "myosuite": version,
        "myo_sim": package_version("myo-sim"),
        "mujoco": mujoco.__version__,
        "nq": int(out.nq), "nv": int(out.nv), "nu": int(out.nu), "muscles": muscles,
        "ntendon": int(out.ntendon), "nbody": int(out.nbody), "baked_inertia": baked,
        "tendon_length_max_diff": worst,
    }))


if __name__ == "__main__":
    main()
