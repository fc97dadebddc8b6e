#!/usr/bin/env bash
# Regenerates every MuJoCo fixture that sim/tests/mujoco_kinematics.rs compares against, into OUTDIR
# (default: sim/tests/fixtures/mujoco). PYTHON must have `mujoco` and `numpy`.
#   tools/mujoco_fixtures.sh [OUTDIR]
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
