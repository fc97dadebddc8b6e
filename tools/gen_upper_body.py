#!/usr/bin/env python3
"""Generates config/models/upper_body.xml, muscle-rally's default robot, from the tables below.

    python tools/gen_upper_body.py [--out config/models/upper_body.xml]

The robot (side A; the dual arena turns it about (0, 0.04) for side B):
- pelvis on two slide joints (x, y in the robot frame) driven by position servos (kp 3500, as MyoSuite),
  standing in for footwork: +-0.4 m forward/back, +-1.0 m sideways, damped (600 N s/m) to about 0.7 of
  critical for the ~50 kg body;
- a lumbar spine of five levels (L5/S1 .. L1/L2), three hinges each (flexion, lateral bending, axial
  rotation); the L5/S1 hinges are the three independent torso DoF and the other twelve follow them by
  linear couplings (<equality><joint polycoef>), 40 trunk muscles (20 per side);
- a right arm: shoulder (flexion, abduction, rotation), elbow flexion, forearm pronation, wrist
  flexion and deviation, and a finger flexion joint that closes the grip, 35 muscles; the finger
  joint's upper limit (1.0 rad) is where the fingers meet the handle, a stiff limit (solreflimit 0.004,
  solimplimit 0.99 0.999) and a damped finger (soft tissue on the handle), so that the grip muscles squeeze against it nearly
  isometrically;
- the paddle welded to the hand at its nominal grip pose (the grip model in `sim` may release it).

Robot frame: x forward, y to the robot's left, z up; the root is at world (2.1, -0.6, 0) turned 180
degrees about z so the robot faces the net (-x), standing to the left of the centre line as a
right-handed player does (the pelvis slides then reach the whole hitting plane with the forehand). Muscle paths run through sites only (no wrapping).
Joint signs: shoulder_flex > 0 raises the arm forward, shoulder_abd > 0 raises it sideways,
shoulder_rot > 0 rotates it inwards, elbow_flex > 0 bends the elbow, wrist_flex > 0 bends the hand
towards the palm, wrist_dev > 0 towards the thumb, grip > 0 closes the fingers; lumbar signs below.

Sources and honesty: segment masses follow de Leva (1996)-style proportions for a 75 kg adult
(upper arm 2.0 kg, forearm 1.2 kg, hand 0.45 kg), the trunk lumps thorax, head and the left arm.
Arm peak forces are rounded values in the range of Holzbaur et al. (2005, Ann Biomed Eng 33:829),
the model MyoSuite's MyoArm derives from; the elbow allows 0.1 rad of hyperextension, as many adults have; trunk forces are of the order of lumbar models
(Christophy et al. 2012, Biomech Model Mechanobiol 11:19). Attachment sites are hand-placed to give
each muscle its textbook action with moment arms of 1-6 cm; they are not digitised anatomy.
`lengthrange` is written for every muscle: MuJoCo's own estimate of the draft model (so the
generator needs `pip install mujoco`); the shipped file then depends on no compile-time estimate.
"""
import argparse
import math
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.join(HERE, "..")

# --- skeleton -------------------------------------------------------------------------------------
# Lumbar levels: (child body, joint prefix, offset from parent, coupling ratio to L5/S1). The ratios
# spread a torso motion over the five levels, more at the lower levels for flexion (a lumbar rhythm).
LEVELS = [
    ("L5", "L5S1", (-0.03, 0.0, 0.08), None),
    ("L4", "L4L5", (0.0, 0.0, 0.035), (0.9, 0.8, 0.9)),
    ("L3", "L3L4", (0.0, 0.0, 0.035), (0.8, 0.8, 0.9)),
    ("L2", "L2L3", (0.0, 0.0, 0.035), (0.6, 0.7, 0.8)),
    ("L1", "L1L2", (0.0, 0.0, 0.035), (0.45, 0.6, 0.8)),
]
# (axis suffix, axis, range in rad) for each lumbar level. The L5/S1 ranges bound the torso DoF; times
# the sum of the coupling ratios they give the whole lumbar spine about 1.0 rad of flexion and 0.5 of
# extension, +-0.5 of lateral bending and +-0.6 of axial rotation (rotation stands in for the thoracic
# spine and hips too, which the model does not have). Dependent levels share the same range, which their
# ratios (at most 1) keep them inside.
# Signs: flex > 0 bends forward, lat > 0 bends to the robot's right, rot > 0 turns the chest to the left.
# Each level also has the passive stiffness of its disc and ligaments (N m/rad, towards upright), of the
# order of published lumbar motion-segment stiffness (flexion ~1 N m/deg, lateral ~1.5, axial rotation
# several N m/deg), which is what keeps a real trunk steady while the legs move it around.
LUMBAR_AXES = [("flex", (0, 1, 0), (-0.13, 0.27)), ("lat", (1, 0, 0), (-0.13, 0.13)), ("rot", (0, 0, 1), (-0.14, 0.14))]
LUMBAR_STIFFNESS = {"flex": 60.0, "lat": 90.0, "rot": 300.0}

# --- trunk muscles (left side; the right side mirrors y) -----------------------------------------
# name: (force N, [(body, (x, y, z)), ...]); bodies: pelvis, L5..L1, thorax.
TRUNK = {
    "RA": (300, [("pelvis", (0.09, 0.03, -0.07)), ("thorax", (0.13, 0.04, 0.12))]),
    "EO1": (200, [("thorax", (0.07, 0.13, 0.14)), ("pelvis", (0.10, 0.06, 0.00))]),
    "EO2": (200, [("thorax", (0.03, 0.15, 0.10)), ("pelvis", (0.06, 0.12, 0.03))]),
    "EO3": (150, [("thorax", (-0.02, 0.15, 0.06)), ("pelvis", (0.02, 0.14, 0.04))]),
    "IO1": (150, [("pelvis", (0.05, 0.13, 0.04)), ("thorax", (0.12, 0.05, 0.08))]),
    "IO2": (150, [("pelvis", (0.01, 0.14, 0.05)), ("thorax", (0.07, 0.12, 0.06))]),
    "IO3": (120, [("pelvis", (-0.03, 0.12, 0.05)), ("thorax", (0.01, 0.14, 0.04))]),
    "IL1": (200, [("pelvis", (-0.09, 0.06, 0.05)), ("thorax", (-0.10, 0.07, 0.15))]),
    "IL2": (150, [("pelvis", (-0.08, 0.08, 0.05)), ("L2", (-0.05, 0.06, 0.01))]),
    "IL3": (150, [("pelvis", (-0.08, 0.08, 0.04)), ("L3", (-0.05, 0.06, 0.01))]),
    "LT1": (250, [("pelvis", (-0.10, 0.03, 0.04)), ("thorax", (-0.09, 0.04, 0.20))]),
    "LT2": (150, [("pelvis", (-0.10, 0.035, 0.05)), ("L1", (-0.06, 0.03, 0.0))]),
    "LT3": (150, [("pelvis", (-0.095, 0.04, 0.06)), ("L3", (-0.06, 0.03, 0.0))]),
    "MF1": (100, [("pelvis", (-0.09, 0.015, 0.06)), ("L4", (-0.07, 0.005, 0.01))]),
    "MF2": (100, [("pelvis", (-0.09, 0.02, 0.07)), ("L2", (-0.07, 0.005, 0.01))]),
    "MF3": (80, [("L5", (-0.07, 0.015, 0.0)), ("L1", (-0.07, 0.005, 0.01))]),
    "PS1": (200, [("L1", (0.02, 0.03, 0.0)), ("pelvis", (0.06, 0.08, -0.12))]),
    "PS2": (200, [("L3", (0.02, 0.03, 0.0)), ("pelvis", (0.06, 0.08, -0.12))]),
    "QL1": (80, [("pelvis", (-0.06, 0.09, 0.06)), ("thorax", (-0.06, 0.07, 0.02))]),
    "QL2": (60, [("pelvis", (-0.06, 0.09, 0.05)), ("L2", (-0.03, 0.06, 0.0))]),
}

# --- right-arm muscles ------------------------------------------------------------------------------
# Right arm: y < 0 is lateral. Humerus, forearm (ulna, radius) and hand frames hang along -z; in the
# forearm and hand, +x is the radial (thumb) side and +y the palmar side.
ARM = {
    # shoulder
    "DELT1": (1140, [("thorax", (0.05, -0.16, 0.33)), ("humerus", (0.03, -0.02, -0.04)), ("humerus", (0.005, -0.015, -0.13))]),
    "DELT2": (1140, [("thorax", (0.0, -0.20, 0.35)), ("humerus", (0.0, -0.035, -0.03)), ("humerus", (0.0, -0.015, -0.13))]),
    "DELT3": (260, [("thorax", (-0.07, -0.17, 0.33)), ("humerus", (-0.03, -0.02, -0.04)), ("humerus", (-0.005, -0.015, -0.13))]),
    "SUPSP": (490, [("thorax", (-0.07, -0.12, 0.33)), ("humerus", (0.0, -0.025, 0.02))]),
    "INFSP": (1210, [("thorax", (-0.10, -0.11, 0.23)), ("humerus", (-0.025, -0.02, 0.0))]),
    "TMIN": (350, [("thorax", (-0.09, -0.13, 0.18)), ("humerus", (-0.025, -0.02, -0.02))]),
    "SUBSC": (1380, [("thorax", (-0.05, -0.10, 0.24)), ("humerus", (0.02, 0.015, -0.01))]),
    "TMAJ": (425, [("thorax", (-0.09, -0.10, 0.14)), ("humerus", (0.01, 0.012, -0.06))]),
    "PECM1": (365, [("thorax", (0.06, -0.10, 0.32)), ("humerus", (0.02, -0.01, -0.06))]),
    "PECM2": (515, [("thorax", (0.11, -0.02, 0.25)), ("humerus", (0.02, -0.005, -0.07))]),
    "PECM3": (390, [("thorax", (0.11, -0.05, 0.14)), ("humerus", (0.02, 0.0, -0.08))]),
    "LAT1": (390, [("thorax", (-0.11, -0.03, 0.10)), ("humerus", (0.01, 0.01, -0.05))]),
    "LAT2": (280, [("pelvis", (-0.08, -0.10, 0.06)), ("thorax", (-0.10, -0.09, 0.10)), ("humerus", (0.01, 0.01, -0.06))]),
    "CORB": (240, [("thorax", (0.04, -0.15, 0.30)), ("humerus", (0.005, 0.01, -0.14))]),
    # elbow and forearm
    "TRIlong": (800, [("thorax", (-0.03, -0.18, 0.28)), ("humerus", (-0.03, 0.0, -0.20)), ("ulna", (-0.025, 0.0, 0.02))]),
    "TRIlat": (625, [("humerus", (-0.015, -0.01, -0.08)), ("humerus", (-0.03, 0.0, -0.22)), ("ulna", (-0.025, 0.0, 0.02))]),
    "TRImed": (625, [("humerus", (-0.01, 0.01, -0.14)), ("humerus", (-0.028, 0.0, -0.24)), ("ulna", (-0.025, 0.0, 0.02))]),
    "ANC": (350, [("humerus", (-0.035, -0.025, -0.27)), ("ulna", (-0.03, -0.01, -0.02))]),
    "BIClong": (625, [("thorax", (0.0, -0.19, 0.33)), ("humerus", (0.03, -0.005, -0.03)), ("humerus", (0.03, 0.0, -0.22)), ("radius", (0.02, 0.0, -0.04))]),
    "BICshort": (435, [("thorax", (0.04, -0.16, 0.30)), ("humerus", (0.025, 0.01, -0.10)), ("humerus", (0.03, 0.005, -0.22)), ("radius", (0.02, 0.0, -0.04))]),
    "BRA": (990, [("humerus", (0.015, 0.0, -0.17)), ("ulna", (0.02, 0.0, -0.035))]),
    "BRD": (260, [("humerus", (0.01, -0.03, -0.22)), ("radius", (0.02, -0.01, -0.23))]),
    "PT": (565, [("humerus", (0.0, 0.035, -0.28)), ("radius", (0.02, -0.015, -0.12))]),
    "PQ": (75, [("ulna", (-0.01, 0.02, -0.23)), ("radius", (0.015, 0.02, -0.23))]),
    "SUP": (475, [("ulna", (-0.02, -0.02, -0.04)), ("radius", (0.015, -0.02, -0.06))]),
    # wrist
    "ECRL": (305, [("humerus", (0.01, -0.035, -0.25)), ("radius", (0.02, -0.02, -0.24)), ("hand", (0.015, -0.015, -0.03))]),
    "ECRB": (100, [("humerus", (0.005, -0.035, -0.28)), ("radius", (0.012, -0.02, -0.24)), ("hand", (0.005, -0.017, -0.03))]),
    "ECU": (95, [("humerus", (-0.005, -0.035, -0.29)), ("ulna", (-0.02, -0.012, -0.24)), ("hand", (-0.02, -0.008, -0.03))]),
    "FCR": (75, [("humerus", (0.0, 0.035, -0.29)), ("radius", (0.012, 0.018, -0.24)), ("hand", (0.012, 0.016, -0.03))]),
    "FCU": (130, [("humerus", (-0.005, 0.035, -0.29)), ("ulna", (-0.015, 0.018, -0.24)), ("hand", (-0.018, 0.012, -0.02))]),
    "PL": (30, [("humerus", (0.0, 0.037, -0.29)), ("radius", (0.0, 0.022, -0.245)), ("hand", (0.0, 0.022, -0.04))]),
    # grip: the fingers' flexors and extensor, lumped
    "FDS": (320, [("humerus", (0.0, 0.034, -0.285)), ("radius", (0.0, 0.02, -0.24)), ("hand", (0.0, 0.02, -0.06)), ("fingers", (0.0, 0.015, -0.03))]),
    "FDP": (350, [("ulna", (0.0, 0.015, -0.06)), ("ulna", (0.0, 0.018, -0.24)), ("hand", (0.0, 0.018, -0.065)), ("fingers", (0.0, 0.012, -0.05))]),
    "FPL": (280, [("radius", (0.015, 0.015, -0.10)), ("radius", (0.015, 0.018, -0.24)), ("hand", (0.02, 0.015, -0.05)), ("fingers", (0.015, 0.012, -0.04))]),
    "EDC": (120, [("humerus", (0.0, -0.035, -0.29)), ("radius", (0.0, -0.02, -0.24)), ("hand", (0.0, -0.015, -0.06)),
                  ("hand", (0.0, -0.018, -0.085)), ("fingers", (0.0, -0.016, -0.01)), ("fingers", (0.0, -0.012, -0.03))]),
}

GRIP_MUSCLES = ["FDS", "FDP", "FPL"]


def fmt(v):
    return " ".join(f"{x:.6g}" for x in v)


def quat_from_matrix(r):
    """(w, x, y, z) of a rotation matrix given by rows."""
    tr = r[0][0] + r[1][1] + r[2][2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        return (0.25 * s, (r[2][1] - r[1][2]) / s, (r[0][2] - r[2][0]) / s, (r[1][0] - r[0][1]) / s)
    if r[0][0] > r[1][1] and r[0][0] > r[2][2]:
        s = math.sqrt(1.0 + r[0][0] - r[1][1] - r[2][2]) * 2
        return ((r[2][1] - r[1][2]) / s, 0.25 * s, (r[0][1] + r[1][0]) / s, (r[0][2] + r[2][0]) / s)
    if r[1][1] > r[2][2]:
        s = math.sqrt(1.0 + r[1][1] - r[0][0] - r[2][2]) * 2
        return ((r[0][2] - r[2][0]) / s, (r[0][1] + r[1][0]) / s, 0.25 * s, (r[1][2] + r[2][1]) / s)
    s = math.sqrt(1.0 + r[2][2] - r[0][0] - r[1][1]) * 2
    return ((r[1][0] - r[0][1]) / s, (r[0][2] + r[2][0]) / s, (r[1][2] + r[2][1]) / s, 0.25 * s)


def muscles():
    """[(name, force, [(body, pos)])] for both trunk sides and the arm."""
    out = []
    for side, sign in (("l", 1.0), ("r", -1.0)):
        for name, (force, pts) in TRUNK.items():
            out.append((f"{name}_{side}", force, [(b, (p[0], sign * p[1], p[2])) for b, p in pts]))
    for name, (force, pts) in ARM.items():
        out.append((name, force, pts))
    return out


def build(lengthranges=None):
    sites = {}  # body -> [(site name, pos)]
    tendons = []
    for name, force, pts in muscles():
        names = []
        for k, (body, pos) in enumerate(pts):
            sname = f"{name}_p{k}"
            sites.setdefault(body, []).append((sname, pos))
            names.append(sname)
        tendons.append((name, force, names))

    def site_lines(body, indent):
        return "".join(f'{indent}<site name="{s}" pos="{fmt(p)}" class="path"/>\n' for s, p in sites.get(body, []))

    x = []
    x.append('<mujoco model="muscle_rally_upper_body">\n')
    x.append("  <!-- Generated by tools/gen_upper_body.py: edit the generator, not this file.\n")
    x.append("       muscle-rally's default robot: pelvis slides, a 5-level lumbar spine (3 independent DoF, 40 muscles),\n")
    x.append("       a right arm (shoulder 3, elbow, pronation, wrist 2, grip; 35 muscles) and the paddle in the hand.\n")
    x.append("       Sources and the robot frame are documented in the generator. Loads unchanged in MuJoCo 3.x/4.x. -->\n")
    x.append('  <compiler angle="radian" autolimits="true"/>\n')
    x.append('  <option timestep="0.002" gravity="0 0 -9.81"/>\n')
    x.append("  <default>\n")
    x.append('    <joint damping="0.5" armature="0.01"/>\n')
    x.append('    <geom contype="0" conaffinity="0" group="1" rgba="0.85 0.8 0.7 1"/>\n')
    x.append('    <muscle ctrlrange="0 1"/>\n')
    x.append('    <default class="path">\n')
    x.append('      <site size="0.004" group="3" rgba="0.8 0.2 0.2 1"/>\n')
    x.append("    </default>\n")
    x.append('    <default class="spine">\n')
    x.append('      <joint damping="20" armature="0.02"/>\n')
    x.append("    </default>\n")
    x.append("  </default>\n")
    x.append("  <worldbody>\n")
    x.append('    <body name="root" pos="2.1 -0.6 0" euler="0 0 3.14159265358979">\n')
    x.append('      <body name="pelvis_slider">\n')
    x.append('        <joint name="pelvis_tx" type="slide" axis="1 0 0" range="-0.4 0.4" damping="600" armature="0"/>\n')
    x.append('        <inertial pos="0 0 0.5" mass="2" diaginertia="0.05 0.05 0.05"/>\n')
    x.append('        <body name="pelvis" pos="0 0 0.95">\n')
    x.append('          <joint name="pelvis_ty" type="slide" axis="0 1 0" range="-1.0 1.0" damping="600" armature="0"/>\n')
    x.append('          <inertial pos="0 0 0" mass="11" diaginertia="0.10 0.08 0.10"/>\n')
    x.append('          <geom type="box" size="0.09 0.15 0.07"/>\n')
    x.append(site_lines("pelvis", "          "))
    indent = "          "
    closers = []
    for i, (body, prefix, off, ratio) in enumerate(LEVELS):
        indent += "  "
        x.append(f'{indent}<body name="{body}" pos="{fmt(off)}">\n')
        for suffix, axis, rng in LUMBAR_AXES:
            k = LUMBAR_STIFFNESS[suffix]
            x.append(f'{indent}  <joint name="{prefix}_{suffix}" axis="{fmt(axis)}" range="{fmt(rng)}" stiffness="{k:g}" class="spine"/>\n')
        x.append(f'{indent}  <inertial pos="0 0 0.015" mass="1.2" diaginertia="0.004 0.004 0.006"/>\n')
        x.append(f'{indent}  <geom type="cylinder" size="0.025 0.012" pos="0 0 0.015"/>\n')
        x.append(site_lines(body, indent + "  "))
        closers.append(f"{indent}</body>\n")
    indent += "  "
    x.append(f'{indent}<body name="thorax" pos="0 0 0.035">\n')
    x.append(f'{indent}  <inertial pos="0 0 0.25" mass="28" diaginertia="1.0 0.9 0.35"/>\n')
    x.append(f'{indent}  <geom type="capsule" fromto="0 0.09 0.15 0 -0.09 0.15" size="0.12"/>\n')
    x.append(f'{indent}  <geom type="sphere" size="0.1" pos="0 0 0.55"/>\n')
    x.append(site_lines("thorax", indent + "  "))
    # right arm
    arm = indent + "  "
    x.append(f'{arm}<body name="humerus" pos="0 -0.19 0.30">\n')
    x.append(f'{arm}  <joint name="shoulder_flex" axis="0 -1 0" range="-1.0 2.8"/>\n')
    x.append(f'{arm}  <joint name="shoulder_abd" axis="-1 0 0" range="-0.4 2.6"/>\n')
    x.append(f'{arm}  <joint name="shoulder_rot" axis="0 0 1" range="-1.4 1.4"/>\n')
    x.append(f'{arm}  <inertial pos="0 0 -0.14" mass="2.0" diaginertia="0.013 0.013 0.002"/>\n')
    x.append(f'{arm}  <geom type="capsule" fromto="0 0 0 0 0 -0.28" size="0.03"/>\n')
    x.append(site_lines("humerus", arm + "  "))
    x.append(f'{arm}  <body name="ulna" pos="0 0 -0.30">\n')
    x.append(f'{arm}    <joint name="elbow_flex" axis="0 -1 0" range="-0.1 2.5"/>\n')
    x.append(f'{arm}    <inertial pos="0 0 -0.11" mass="0.7" diaginertia="0.005 0.005 0.0005"/>\n')
    x.append(f'{arm}    <geom type="capsule" fromto="-0.01 0 0 -0.01 0 -0.25" size="0.018"/>\n')
    x.append(site_lines("ulna", arm + "    "))
    x.append(f'{arm}    <body name="radius" pos="0 0 0">\n')
    x.append(f'{arm}      <joint name="pronation" axis="0 0 1" range="-1.4 1.4"/>\n')
    x.append(f'{arm}      <inertial pos="0.01 0 -0.13" mass="0.5" diaginertia="0.003 0.003 0.0003"/>\n')
    x.append(f'{arm}      <geom type="capsule" fromto="0.01 0 0 0.01 0 -0.25" size="0.015"/>\n')
    x.append(site_lines("radius", arm + "      "))
    x.append(f'{arm}      <body name="hand" pos="0 0 -0.26">\n')
    x.append(f'{arm}        <joint name="wrist_flex" axis="1 0 0" range="-1.2 1.2"/>\n')
    x.append(f'{arm}        <joint name="wrist_dev" axis="0 -1 0" range="-0.6 0.35"/>\n')
    x.append(f'{arm}        <inertial pos="0 0.005 -0.05" mass="0.45" diaginertia="0.0012 0.001 0.0004"/>\n')
    x.append(f'{arm}        <geom type="box" size="0.04 0.015 0.045" pos="0 0 -0.045"/>\n')
    x.append(f'{arm}        <site name="palm" pos="0 0.01 -0.07" class="path"/>\n')
    x.append(site_lines("hand", arm + "        "))
    x.append(f'{arm}        <body name="fingers" pos="0 0 -0.09">\n')
    x.append(f'{arm}          <joint name="grip" axis="1 0 0" range="0 1.0" damping="2" armature="0.001" solreflimit="0.004 1" solimplimit="0.99 0.999 0.001"/>\n')
    x.append(f'{arm}          <inertial pos="0 0.01 -0.03" mass="0.1" diaginertia="0.0001 0.0001 0.00003"/>\n')
    x.append(f'{arm}          <geom type="box" size="0.04 0.01 0.035" pos="0 0.01 -0.035"/>\n')
    x.append(site_lines("fingers", arm + "          "))
    x.append(f"{arm}        </body>\n")
    # Paddle frame in the hand: handle along hand +z (towards the wrist), blade normal along hand +x.
    r = [[0, 0, 1], [0, -1, 0], [1, 0, 0]]  # columns: paddle x, y, z in hand coordinates
    rows = [[r[i][j] for j in range(3)] for i in range(3)]
    q = quat_from_matrix(rows)
    x.append(f'{arm}        <body name="paddle" pos="0 0.01 -0.144" quat="{fmt(q)}">\n')
    x.append(f'{arm}          <inertial pos="-0.03 0 0" mass="0.15" diaginertia="0.0004 0.0004 0.0007"/>\n')
    x.append(f'{arm}          <geom name="blade" type="cylinder" size="0.093 0.02" pos="-0.07 0 0" rgba="0.7 0.1 0.1 1"/>\n')
    x.append(f'{arm}          <geom name="handle" type="cylinder" size="0.016 0.051" pos="0.074 0 0" euler="0 1.5707963267949 0" rgba="0.5 0.35 0.2 1"/>\n')
    x.append(f'{arm}          <site name="paddle_origin" pos="0 0 0" class="path"/>\n')
    x.append(f'{arm}          <site name="blade_center" pos="-0.07 0 0" class="path"/>\n')
    x.append(f"{arm}        </body>\n")
    x.append(f"{arm}      </body>\n")
    x.append(f"{arm}    </body>\n")
    x.append(f"{arm}  </body>\n")
    x.append(f"{arm}</body>\n")
    x.append(f"{indent}</body>\n")
    for c in reversed(closers):
        x.append(c)
    x.append("        </body>\n")
    x.append("      </body>\n")
    x.append("    </body>\n")
    x.append("  </worldbody>\n")
    x.append("  <tendon>\n")
    for name, _, names in tendons:
        x.append(f'    <spatial name="{name}_tendon">' + "".join(f'<site site="{s}"/>' for s in names) + "</spatial>\n")
    x.append("  </tendon>\n")
    x.append("  <actuator>\n")
    x.append('    <position name="pelvis_tx_servo" joint="pelvis_tx" kp="3500" ctrlrange="-0.4 0.4"/>\n')
    x.append('    <position name="pelvis_ty_servo" joint="pelvis_ty" kp="3500" ctrlrange="-1.0 1.0"/>\n')
    for name, force, _ in tendons:
        lr = ""
        if lengthranges is not None:
            lr = f' lengthrange="{fmt(lengthranges[name])}"'
        x.append(f'    <muscle name="{name}" tendon="{name}_tendon" force="{force}"{lr}/>\n')
    x.append("  </actuator>\n")
    x.append("  <equality>\n")
    for body, prefix, off, ratio in LEVELS[1:]:
        for (suffix, _, _), c in zip(LUMBAR_AXES, ratio):
            x.append(f'    <joint joint1="{prefix}_{suffix}" joint2="L5S1_{suffix}" polycoef="0 {c} 0 0 0"/>\n')
    x.append("  </equality>\n")
    x.append("  <keyframe>\n")
    x.append("    <!-- qpos order: pelvis_tx pelvis_ty, 15 lumbar (5 levels x flex lat rot), shoulder 3, elbow,\n")
    x.append("         pronation, wrist 2, grip. Dependent lumbar joints are set by the couplings on load. -->\n")
    # Ready: the blade waits behind the hitting plane (a rally serve starts on it) at the middle of where
    # P2 serves cross it, facing the net (solved with the paddle IK: agents/examples/ready_pose.rs).
    ready = [0.054, 0.219] + [0.08, 0.0, 0.0] * 5 + [-0.477, 1.017, -0.767, 0.8, 0.011, -0.097, -0.385, 1.0]
    x.append(f'    <key name="ready" qpos="{fmt(ready)}"/>\n')
    # Arm hanging near its equilibrium, trunk upright: the start of MuJoCo's passive cross-check motion.
    hang = [0.0, 0.0] + [0.0, 0.0, 0.0] * 5 + [0.0, 0.1, 0.0, 0.15, 0.0, 0.0, 0.0, 0.5]
    x.append(f'    <key name="hang" qpos="{fmt(hang)}"/>\n')
    x.append("  </keyframe>\n")
    x.append("</mujoco>\n")
    return "".join(x)


def mujoco_lengthranges(xml, samples=4000, seed=0):
    """Each muscle's (min, max) tendon length over the joint ranges, measured with MuJoCo's kinematics:
    uniform random configurations of the independent joints (couplings applied), then a coordinate
    search over the joint limits from each extreme. (MuJoCo's built-in estimate, which simulates,
    does not converge on the coupled spine.)"""
    import mujoco
    import numpy as np

    spec_xml = xml.replace('<compiler angle="radian" autolimits="true"/>',
                           '<compiler angle="radian" autolimits="true"><lengthrange mode="none"/></compiler>')
    m = mujoco.MjModel.from_xml_string(spec_xml)
    d = mujoco.MjData(m)
    coup = []
    for i in range(m.neq):
        j1, j2 = m.eq_obj1id[i], m.eq_obj2id[i]
        coup.append((m.jnt_qposadr[j1], m.jnt_qposadr[j2], m.eq_data[i][:5].copy()))
    dependents = {c[0] for c in coup}
    free = [(m.jnt_qposadr[j], m.jnt_range[j]) for j in range(m.njnt) if m.jnt_qposadr[j] not in dependents]
    muscles = [i for i in range(m.nu) if m.actuator_dyntype[i] == mujoco.mjtDyn.mjDYN_MUSCLE]

    def lengths(q):
        q = q.copy()
        for dep, ind, c in coup:
            x = q[ind] - m.qpos0[ind]
            q[dep] = m.qpos0[dep] + c[0] + c[1] * x + c[2] * x * x + c[3] * x ** 3 + c[4] * x ** 4
        d.qpos[:] = q
        mujoco.mj_fwdPosition(m, d)
        return d.actuator_length[muscles].copy()

    rng = np.random.default_rng(seed)
    best_lo = [(np.inf, None)] * len(muscles)
    best_hi = [(-np.inf, None)] * len(muscles)
    for _ in range(samples):
        q = m.qpos0.copy()
        for adr, (lo, hi) in free:
            q[adr] = rng.uniform(lo, hi)
        ls = lengths(q)
        for k, l in enumerate(ls):
            if l < best_lo[k][0]:
                best_lo[k] = (l, q.copy())
            if l > best_hi[k][0]:
                best_hi[k] = (l, q.copy())
    for k in range(len(muscles)):
        for best, sign in ((best_lo, 1.0), (best_hi, -1.0)):
            val, q = best[k]
            for _ in range(3):
                for adr, (lo, hi) in free:
                    for v in (lo, hi, 0.5 * (lo + hi)):
                        trial = q.copy()
                        trial[adr] = v
                        l = lengths(trial)[k]
                        if sign * l < sign * val:
                            val, q = l, trial
            best[k] = (val, q)
    out = {}
    for k, i in enumerate(muscles):
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, i)
        out[name] = (round(float(best_lo[k][0]), 6), round(float(best_hi[k][0]), 6))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=os.path.join(ROOT, "config", "models", "upper_body.xml"))
    args = ap.parse_args()
    draft = build()
    try:
        lr = mujoco_lengthranges(draft)
    except ImportError:
        sys.exit("gen_upper_body.py needs the mujoco package to compute length ranges (pip install mujoco)")
    xml = build(lr)
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as f:
        f.write(xml)
    n = len(muscles())
    print(f"wrote {args.out}: {n} muscles ({2 * len(TRUNK)} trunk, {len(ARM)} arm), length ranges from MuJoCo")


if __name__ == "__main__":
    main()
