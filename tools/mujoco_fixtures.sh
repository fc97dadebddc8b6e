#!/usr/bin/env bash
# Regenerates every MuJoCo fixture that sim/tests/mujoco_kinematics.rs compares against, into OUTDIR
# (default: sim/tests/fixtures/mujoco). PYTHON must have `mujoco` and `numpy`.
#   tools/mujoco_fixtures.sh [OUTDIR]
# With RALLY_MYOCHALLENGE naming the file `rally model import myosuite` wrote, it also writes
# myochallenge.json for MyoSuite's robot (12 MB; never committed: the model is not either).
# .ci/run calls it with a temporary OUTDIR and runs the comparison on the fresh files
# (RALLY_MUJOCO_FIXTURES=OUTDIR), so the test runs live against the MuJoCo that pip just installed.
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-sim/tests/fixtures/mujoco}"
py="${PYTHON:-python3}"
mkdir -p "$out"
models=sim/tests/fixtures/models
"$py" tools/mujoco_crosscheck.py "$models/two_link.xml" "$out/two_link.json"
"$py" tools/mujoco_crosscheck.py "$models/two_link_uncoupled.xml" "$out/two_link_uncoupled.json"
# The default robot: the actuated motion starts hanging, with gentle controls, and leaves the grip
# muscles quiet (they would close the fingers onto their joint limit within the 0.5 s).
"$py" tools/mujoco_crosscheck.py config/models/upper_body.xml "$out/upper_body.json" \
  --ctrl-range 0.02 0.15 --actuated-key hang --quiet FDS,FDP,FPL,EDC
"$py" tools/mujoco_crosscheck.py "$models/free_body.xml" "$out/free_body.json"
"$py" tools/mujoco_wrap_cases.py "$out/wrap_cases.json"
if [ -n "${RALLY_MYOCHALLENGE:-}" ]; then
  # MyoSuite's robot: the keyframe and 25 sampled configurations; the motions start with every
  # joint mid-range (from the keyframe, gravity takes the wrist onto its limit within 0.2 s), with
  # contacts off (muscle-rally has none between body parts) and the wrist and hand muscles quiet
  # in the actuated one (the light fingers would reach their limits).
  hand=ECRL,ECRB,ECU,FCR,FCU,PL,FDS5,FDS4,FDS3,FDS2,FDP5,FDP4,FDP3,FDP2,EDC5,EDC4,EDC3,EDC2,EDM,EIP,EPL,EPB,FPL,APL,OP
  hand="$hand,RI2,LU_RB2,UI_UB2,RI3,LU_RB3,UI_UB3,RI4,LU_RB4,UI_UB4,RI5,LU_RB5,UI_UB5"
  "$py" tools/mujoco_crosscheck.py "$RALLY_MYOCHALLENGE" "$out/myochallenge.json" \
    --configs 25 --keyframe-config --no-contacts --motion-start mid --ctrl-range 0.02 0.1 --quiet "$hand" \
    --fd-moments
fi
