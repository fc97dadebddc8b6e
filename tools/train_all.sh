#!/usr/bin/env bash
# Trains the four methods of the paper's comparison one after another with the same configuration
# and step budget, each resuming its own run directory if it exists (so this script can be run again
# after any interruption and continues where it stopped), then copies each checkpoint to
# config/checkpoints/. Usage: [METHODS="kmac muscle ..."] tools/train_all.sh [STEPS] [SEED] [RUNS_DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
steps="${1:-8000000}"
seed="${2:-1}"
runs="${3:-runs}"
rally="${RALLY:-target/release/rally}"
mkdir -p "$runs" config/checkpoints
for method in ${METHODS:-kmac muscle muscle-pd dynsyn}; do
  out="$runs/$method"
  resume=()
  [ -d "$out/resume" ] || [ -d "$out/resume.old" ] && resume=(--resume)
  "$rally" train --method "$method" --steps "$steps" --seed "$seed" --out "$out" --quiet "${resume[@]}"
  case "$method" in muscle) name=muscle-ppo ;; *) name="$method" ;; esac
  cp "$out/checkpoint.json" "config/checkpoints/$name.json"
done
"$rally" plot "$runs/kmac" "$runs/muscle" "$runs/muscle-pd" "$runs/dynsyn" --out docs/learning_curves.png
