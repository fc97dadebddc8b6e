#!/usr/bin/env bash
# Trains a rally agent from a single-serve Diff-Muscle run by the recipe of the rally built-in
# (docs/training.md, "The rally built-in: what it took"), stage by stage, each a warm start of the next:
#   1. rs      the heuristic rally serves (--serve rally), from BASE's last saved state;
#   2. stroke  stroke serves (a robot's return, half of them outside the box) with the ball_out reward,
#              validated on single serves every 50 iterations (best.json: the best success rate);
#   3. bankK   ROUNDS rounds: a ball bank of every legal return of 1 000 self-play rallies of the
#              previous stage's best.json (`rally match --returns`), then training on half bank balls,
#              half stroke serves from the previous stage's best state, validated on self-play rallies;
#   4. the last round's best.json played with NOISE times its trained action noise
#      (`rally checkpoint scale-noise`), written to OUT.
# Every stage resumes its own directory when the script is run again, and a stage already finished is
# skipped, so after any interruption the same command continues where it stopped. The stages'
# configurations are CONFIG with their tables replaced, written beside the runs.
# The committed kmac-rally was made by hand along these stages (its runs: docs/runs/README.md); this
# script is the recipe in one command, not a byte-for-byte replay of that history.
# Usage: [MODEL=myochallenge CONFIG=config/train-myochallenge.toml]
#        [RS_STEPS=1.68e6] [STROKE_STEPS=4e6] [BANK_STEPS=2.5e6] [ROUNDS=2] [NOISE=0.5]
#        [STROKE_VALIDATE_EVERY=50] [VALIDATE_EVERY=100] [BANK_RALLIES=1000]
#        [LR=1e-4: every stage's learning_rate instead of CONFIG's]
#        tools/train_rally.sh BASE_RUN [RUNS_DIR] [OUT]
# e.g.   tools/train_rally.sh runs/kmac runs/rally runs/rally/kmac-rally.json
set -euo pipefail
cd "$(dirname "$0")/.."
if [ $# -lt 1 ] || [ "$1" = -h ] || [ "$1" = --help ]; then
  sed -n '2,/^set -euo/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//' >&2
  [ $# -ge 1 ] && exit 0
  exit 2
fi
base="$1"
runs="${2:-runs/rally}"
out="${3:-$runs/kmac-rally.json}"
rally="${RALLY:-target/release/rally}"
model="${MODEL:-default}"
config="${CONFIG:-config/train.toml}"
rounds="${ROUNDS:-2}"
if [ ! -d "$base/resume" ] && [ ! -d "$base/resume.old" ]; then
  echo "error: $base has no saved training state (resume/): give the directory of a rally train run" >&2
  exit 2
fi
mkdir -p "$runs"

# CONFIG without the tables this script sets, with LR as its learning rate when given, and for the
# stroke and bank stages (argument "stroke") serve = "stroke" and the ball_out reward.
stage_config() {
  awk '
    /^\[/ { skip = ($0 ~ /^\[(validation|bank)\]/) }
    skip { next }
    /^learning_rate[ \t]*=/ && lr != "" { print "learning_rate = " lr; next }
    stroke && /^serve[ \t]*=/ { print "serve = \"stroke\""; next }
    stroke && /^ball_out[ \t]*=/ { next }
    { print }
    stroke && /^\[reward\]/ { print "ball_out = 100.0" }
  ' lr="${LR:-}" stroke="$([ "${1:-}" = stroke ] && echo 1 || echo 0)" "$config"
}

# One training stage: name, init directory, steps, seed, config, extra arguments.
train() {
  local dir="$1" init="$2" steps="$3" seed="$4" cfg="$5"; shift 5
  local resume=(--init "$init")
  if [ -d "$dir/resume" ] || [ -d "$dir/resume.old" ]; then resume=(--resume); fi
  echo "== $dir (from $init, $steps steps, seed $seed)" >&2
  "$rally" train --model "$model" --config "$cfg" --method kmac --steps "$steps" --seed "$seed" \
    --out "$dir" --name kmac-rally --quiet "${resume[@]}" "$@"
}

# 1. rally serves
cfg="$runs/rs.toml"
stage_config >"$cfg"
train "$runs/rs" "$base" "${RS_STEPS:-1.68e6}" 3 "$cfg" --serve rally

# 2. stroke serves, validated on single serves
cfg="$runs/stroke.toml"
{ stage_config stroke; printf "\n[validation]\nevery = %s\nepisodes = 200\nseed = 4242\nenv = \"single\"\n" "${STROKE_VALIDATE_EVERY:-50}"; } >"$cfg"
train "$runs/stroke" "$runs/rs" "${STROKE_STEPS:-4e6}" 31 "$cfg"
prev="$runs/stroke"

# 3. ball-bank rounds, validated on self-play rallies
for k in $(seq 1 "$rounds"); do
  dir="$runs/bank$k"
  mkdir -p "$dir"
  if [ ! -f "$dir/returns.json" ]; then
    echo "== $dir/returns.json (returns of $prev/best.json in self-play)" >&2
    "$rally" match "$prev/best.json" "$prev/best.json" --model "$model" \
      --rallies "${BANK_RALLIES:-1000}" --seed $((9000 + k)) --returns "$dir/returns.json.part" >/dev/null
    mv "$dir/returns.json.part" "$dir/returns.json"
  fi
  cfg="$dir/train.toml"
  { stage_config stroke
    printf '\n[bank]\nfile = "%s"\nfraction = 0.5\n' "$dir/returns.json"
    printf '\n[validation]\nevery = %s\nepisodes = 200\nseed = 4242\nenv = "rally"\n' "${VALIDATE_EVERY:-100}"
  } >"$cfg"
  train "$dir/run" "$prev/best" "${BANK_STEPS:-2.5e6}" $((50 + k)) "$cfg"
  prev="$dir/run"
done

# 4. played with a fraction of its noise
"$rally" checkpoint scale-noise "$prev/best.json" --factor "${NOISE:-0.5}" --out "$out"
echo "wrote $out (from $prev/best.json); try it: $rally match $out $out --model $model --rallies 200 --seed 2026" >&2
