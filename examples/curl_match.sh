#!/usr/bin/env bash
# The raw API with curl and jq: submit a checkpoint, queue a match against a built-in, wait for it,
# print its rallies and the leaderboard.
#
#   RALLY_ADMIN_TOKEN=secret cargo run --release -- serve &      # the server, submissions on
#   RALLY_ADMIN_TOKEN=secret examples/curl_match.sh [http://127.0.0.1:8080]
set -euo pipefail
S="${1:-http://127.0.0.1:8080}/api/v1"
RALLY="${RALLY:-cargo run --release --quiet --}"
: "${RALLY_ADMIN_TOKEN:?set RALLY_ADMIN_TOKEN (the server admin token)}"
NAME="example-$(date +%s)"

echo "== submit $NAME (the built-in Diff-Muscle's checkpoint; the server qualifies it on single-serve episodes)"
$RALLY checkpoint builtin kmac > "/tmp/$NAME.json"
jq -n --arg n "$NAME" --slurpfile c "/tmp/$NAME.json" '{name: $n, checkpoint: $c[0]}' > "/tmp/$NAME.body.json"
curl -sf -H "Authorization: Bearer $RALLY_ADMIN_TOKEN" -H 'Content-Type: application/json' \
  -d @"/tmp/$NAME.body.json" "$S/agents" > "/tmp/$NAME.reply.json"
jq '{agent: .agent.name, hit_rate: .qualification.hit_rate, success_rate: .qualification.success_rate}' "/tmp/$NAME.reply.json"
ID=$(jq -r '.agent.id' "/tmp/$NAME.reply.json")
echo

echo "== queue $NAME (id $ID) against the built-in 'scripted' (id 1), 10 rallies, seed 7"
MATCH=$(curl -sf -H "Authorization: Bearer $RALLY_ADMIN_TOKEN" -H 'Content-Type: application/json' -d "{\"a\": $ID, \"b\": 1, \"rallies\": 10, \"seed\": 7}" "$S/matches" | jq -r .id)
until [ "$(curl -sf "$S/matches/$MATCH" | jq -r .status)" = done ]; do sleep 0.5; done
curl -sf "$S/matches/$MATCH" | jq '{points: [.points_a, .points_b], mean_rally_length, rallies: [.rally_log[] | {idx, server, length, end_reason, failing_side}]}'

echo "== leaderboard"
curl -sf "$S/leaderboard" | jq -r '.rows[] | "\(.rank)\t\(.agent)\t\(.rating | floor)\t\(.matches) matches"'
