#!/usr/bin/env bash
# Trains the paper's §V-C ablations of Diff-Muscle (docs/training.md) with the Table I configuration
# and step budget: Diff-Muscle itself, Without-Planner, Position-only and Without-Task, each from every
# seed. Each run resumes its own directory if it exists (run the script again after any interruption
# and it continues where it stopped); each finished checkpoint is copied to config/checkpoints/ablations/
# (config/checkpoints/MODEL/ablations/ for another robot than the default), where
# `rally reproduce --ablations` reads it. The variants' configurations are written beside the runs:
# CONFIG with its [ablation] table replaced.
# Usage: [VARIANTS="full none position no-task"] [SEEDS="1 2 3"]
#        [MODEL=myochallenge CONFIG=config/train-myochallenge.toml]
#        tools/train_ablations.sh [STEPS] [RUNS_DIR]
set -euo pipefail
cd "$(dirname "$0")/.."
steps="${1:-8000000}"
runs="${2:-runs/ablations}"
rally="${RALLY:-target/release/rally}"
model="${MODEL:-default}"
config="${CONFIG:-config/train.toml}"
if [ "$model" = default ]; then dest=config/checkpoints/ablations
else dest="config/checkpoints/$model/ablations"; runs="$runs-$model"; fi
mkdir -p "$runs" "$dest"
for variant in ${VARIANTS:-full none position no-task}; do
  case "$variant" in
    full) name=diff-muscle command=full task=true ;;
    none) name=without-planner command=none task=true ;;
    position) name=position-only command=position task=true ;;
    no-task) name=without-task command=full task=false ;;
    *) echo "unknown variant '$variant' (full, none, position, no-task)" >&2; exit 2 ;;
  esac
  cfg="$runs/$name.toml"
  # CONFIG without its [ablation] table (up to the next table header), then this variant's.
  awk '/^\[/ { skip = ($0 ~ /^\[ablation\]/) } !skip' "$config" >"$cfg"
  printf '\n[ablation]\ncommand = "%s"\ntask_reward = %s\n' "$command" "$task" >>"$cfg"
  for seed in ${SEEDS:-1 2 3}; do
    out="$runs/$name-s$seed"
    resume=()
    if [ -d "$out/resume" ] || [ -d "$out/resume.old" ]; then resume=(--resume); fi
    "$rally" train --model "$model" --config "$cfg" --method kmac --steps "$steps" --seed "$seed" \
      --out "$out" --quiet "${resume[@]}"
    cp "$out/checkpoint.json" "$dest/$name-s$seed.json"
  done
done
