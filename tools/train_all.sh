#!/usr/bin/env bash
# Trains the four methods of the paper's comparison one after another with the same configuration
# and step budget, each resuming its own run directory if it exists (so this script can be run again
# after any interruption and continues where it stopped), then copies each checkpoint to
# config/checkpoints/ (config/checkpoints/MODEL/ for another robot than the default).
# Usage: [METHODS="kmac muscle ..."] [MODEL=myochallenge CONFIG=config/train-myochallenge.toml]
#        tools/train_all.sh [STEPS] [SEED] [RUNS_DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
steps="${1:-8000000}"
seed="${2:-1}"
runs="${3:-runs}"
rally="${RALLY:-target/release/rally}"
model="${MODEL:-default}"
config="${CONFIG:-config/train.toml}"
if [ "$model" = default ]; then dest=config/checkpoints; curves=docs/learning_curves.png
else dest="config/checkpoints/$model"; curves="docs/learning_curves-$model.png"; fi
mkdir -p "$runs" "$dest"
for method in ${METHODS:-kmac muscle muscle-pd dynsyn}; do
  out="$runs/$method"
  resume=()
  [ -d "$out/resume" ] || [ -d "$out/resume.old" ] && resume=(--resume)
  "$rally" train --model "$model" --config "$config" --method "$method" --steps "$steps" \
    --seed "$seed" --out "$out" --quiet "${resume[@]}"
  case "$method" in muscle) name=muscle-ppo ;; *) name="$method" ;; esac
  cp "$out/checkpoint.json" "$dest/$name.json"
done
"$rally" plot "$runs/kmac" "$runs/muscle" "$runs/muscle-pd" "$runs/dynsyn" --out "$curves"
