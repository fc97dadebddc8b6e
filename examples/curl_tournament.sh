#!/usr/bin/env bash
# The raw API with curl and jq: issue a submitter token, queue a round robin of the built-in agents,
# follow its progress, print its standings and cross-table; then run an SPRT between two of them.
# (`rally batch examples/batch_plan.toml` does the same from a plan file, with progress bars.)
#
#   RALLY_ADMIN_TOKEN=secret cargo run --release -- serve &      # the server
#   RALLY_ADMIN_TOKEN=secret examples/curl_tournament.sh [http://127.0.0.1:8080]
set -euo pipefail
S="${1:-http://127.0.0.1:8080}/api/v1"
: "${RALLY_ADMIN_TOKEN:?set RALLY_ADMIN_TOKEN (the server admin token)}"
J='Content-Type: application/json'

echo "== a submitter token (shown once; the server keeps its SHA-256 only)"
T=$(curl -sf -H "Authorization: Bearer $RALLY_ADMIN_TOKEN" -H "$J" -d "{\"name\": \"lab-$(date +%s)\"}" "$S/tokens" | jq -r .token)
echo "${T:0:12}…"

echo "== round robin of the built-ins, 6 rallies a match, 2 rounds (sides swap), seed 100"
IDS=$(curl -sf "$S/agents" | jq -c '[.agents[] | select(.builtin) | .id]')
TID=$(curl -sf -H "Authorization: Bearer $T" -H "$J" \
  -d "{\"kind\": \"round_robin\", \"agents\": $IDS, \"rallies_per_match\": 6, \"rounds\": 2, \"seed\": 100}" \
  "$S/tournaments" | jq -r .id)
until [ "$(curl -sf "$S/tournaments/$TID" | jq -r .progress.state)" = finished ]; do
  curl -sf "$S/tournaments/$TID" | jq -r '"  \(.progress.done)/\(.progress.total) done, \(.progress.running) running"'
  sleep 1
done
curl -sf "$S/tournaments/$TID" | jq -r '.standings[] | "\(.place)\t\(.agent)\t\(.points_for)-\(.points_against)\t\(.points_won_pct | floor)%"'
curl -sf "$S/tournaments/$TID" | jq -c '{agents: .cross_table_agents, points: [.cross_table[] | [.[] | if . == null then null else "\(.points_for)-\(.points_against)" end]]}'

echo "== SPRT: is the first built-in 50 Elo better than the second? (α = β = 0.05, at most 40 matches)"
A=$(echo "$IDS" | jq '.[0]'); B=$(echo "$IDS" | jq '.[1]')
PID=$(curl -sf -H "Authorization: Bearer $T" -H "$J" \
  -d "{\"a\": $A, \"b\": $B, \"elo0\": 0, \"elo1\": 50, \"rallies_per_match\": 10, \"max_matches\": 40, \"seed\": 1}" \
  "$S/sprt" | jq -r .id)
until [ "$(curl -sf "$S/sprt/$PID" | jq -r .status)" != running ]; do sleep 1; done
curl -sf "$S/sprt/$PID" | jq '{status, llr, bounds, matches_done, elo_estimate}'
