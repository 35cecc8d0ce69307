#!/usr/bin/env bash
# Load test (issue 16, item 7): a release server (ROBOCAL_PROFILE=dev: the dev build, as CI runs
# it; its latencies are not the release's) on a fresh database, `clients` concurrent clients
# for `seconds` mixing measurement batches, compensation requests and history reads while
# identification jobs run (examples/load.rs); then the checks — zero errors, every session holding
# exactly the measurements acknowledged (nothing lost or duplicated), the job queue drained — the
# p50/p99 table, and `PRAGMA integrity_check` on the database after a clean stop.
# With `slow` > 0, that many slowloris connections run alongside (each sends a header line every
# 2 s and never ends its headers; the server must close each within its 10 s header timeout), and
# the table shows the other clients' latencies under that attack.
#   scripts/load_test.sh [seconds=60] [clients=64] [slow=0]   (needs python3 for a free port; sqlite3 optional)
# Exit status 0 only when every check passes.
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-60}
clients=${2:-64}
slow=${3:-0}
profile=${ROBOCAL_PROFILE:-release}
case "$profile" in dev) dir=target/debug ;; *) dir=target/$profile ;; esac
cargo build --quiet --profile "$profile" --locked --bin robocal --example load
tmp=$(mktemp -d)
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
"$dir/robocal" serve --db "$tmp/load.db" --bind "127.0.0.1:$port" --grace-s 5 >"$tmp/serve.log" 2>&1 &
server=$!
trap 'kill $server 2>/dev/null || true; rm -rf "$tmp"' EXIT
for _ in $(seq 200); do
  if python3 -c "import urllib.request,sys; urllib.request.urlopen('http://127.0.0.1:$port/readyz', timeout=1)" 2>/dev/null; then break; fi
  sleep 0.05
done
status=0
"$dir/examples/load" --url "http://127.0.0.1:$port" --seconds "$seconds" --clients "$clients" --slowloris "$slow" || status=$?
kill -TERM $server
wait $server || { echo "FAILED: the server did not stop cleanly"; status=1; }
if command -v sqlite3 >/dev/null; then
  integrity=$(sqlite3 "$tmp/load.db" 'PRAGMA integrity_check')
  echo "integrity_check: $integrity"
  [ "$integrity" = ok ] || status=1
fi
if grep -q ' ERROR ' "$tmp/serve.log"; then
  echo "server errors logged:"; grep ' ERROR ' "$tmp/serve.log" | head -5; status=1
fi
exit $status
