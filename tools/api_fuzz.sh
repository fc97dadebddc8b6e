#!/usr/bin/env bash
# Fuzzes the REST API with schemathesis against the OpenAPI document it serves: a fresh `rally serve`
# (one worker, no continuous mode, no built-in checkpoints) on a scratch database, for SECONDS. The
# checks: no 5xx, every status code, content type, header and body as the document says. The two
# server-sent-event streams (/events, /matches/{id}/live) never end and are left out.
# Usage: tools/api_fuzz.sh RALLY_BINARY SCHEMATHESIS [SECONDS]
# One schemathesis worker: with two threads, hypothesis's ast.parse (it describes lambdas by their
# source) raised CPython 3.11's "SystemError: AST constructor recursion depth mismatch" once in CI, an
# error of the tool and not of the API that still failed the run.
# RALLY_TEST_DB, if set, is the server's store instead of a scratch SQLite file (an empty PostgreSQL
# database's URL: CI fuzzes both engines).
set -euo pipefail
rally="$1"
st="$2"
seconds="${3:-90}"
dir="$(mktemp -d)"
cat >"$dir/server.toml" <<TOML
addr = "127.0.0.1:0"
db = "${RALLY_TEST_DB:-$dir/rally.db}"
workers = 1
continuous = false
continuous_rallies = 4
continuous_pause_s = 1.0
max_rallies = 50
qualification_episodes = 2
max_body_bytes = 65536
admin_token = ""
builtin_checkpoints = ""
TOML
RALLY_ADMIN_TOKEN=api-fuzz-token RUST_LOG=warn "$rally" serve --config "$dir/server.toml" >"$dir/out" 2>"$dir/err" &
pid=$!
trap 'kill $pid 2>/dev/null || true' EXIT
for _ in $(seq 100); do
  grep -q "^listening on " "$dir/out" 2>/dev/null && break
  sleep 0.1
done
addr="$(sed -n 's/^listening on //p' "$dir/out")"
[ -n "$addr" ] || { cat "$dir/err"; echo "rally serve did not start"; exit 1; }
"$st" run "$addr/api/v1/openapi.json" \
  --checks not_a_server_error,status_code_conformance,content_type_conformance,response_schema_conformance,response_headers_conformance \
  --max-time "$seconds" -w 1 -H "Authorization: Bearer api-fuzz-token" \
  --exclude-path-regex 'events|live' --seed 1
