#!/usr/bin/env bash
# The compose.yaml topology without containers (issue 27, items 4 and 6): the throwaway
# PostgreSQL cluster of scripts/pg_cluster.sh, two `robocal serve` replicas on a fresh database
# of it, and HAProxy in front configured by deploy/haproxy.cfg (the file compose.yaml mounts).
#
#   scripts/replicas.sh start   # prints the proxy's URL, then an admin token, one per line
#   scripts/replicas.sh stop    # stops the proxy and the replicas (the cluster: pg_cluster.sh stop)
#
# ROBOCAL_BIN (default target/release/robocal, built when missing) is the server; REPLICAS (1 or
# 2, default 2) how many run behind the proxy; ROBOCAL_JOB_LEASE_S their lease. HAProxy is
# installed from the distribution's packages when missing. Everything lives in one temporary
# directory (logs: replica-N.log, haproxy.log).
set -euo pipefail

ROOT=$(cd "$(dirname "$0")/.." && pwd)
KEY=$(printf '%s' "$ROOT" | sha256sum | cut -c1-12)
DIR=${TMPDIR:-/tmp}/robocal-replicas-$(id -u)-$KEY
BIN=${ROBOCAL_BIN:-$ROOT/target/release/robocal}
REPLICAS=${REPLICAS:-2}

die() { echo "replicas: $*" >&2; exit 1; }
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }

stop() {
  [ -d "$DIR" ] || return 0
  for f in "$DIR"/*.pid; do
    [ -e "$f" ] || continue
    kill -TERM "$(cat "$f")" 2>/dev/null || true
  done
  sleep 1
  for f in "$DIR"/*.pid; do
    [ -e "$f" ] || continue
    kill -KILL "$(cat "$f")" 2>/dev/null || true
  done
  rm -rf "$DIR"
}

wait_ready() { # url
  for _ in $(seq 1 600); do
    curl -fs "$1/readyz" >/dev/null 2>&1 && return 0
    sleep 0.1
  done
  die "$1 did not become ready"
}

start() {
  case "$REPLICAS" in 1|2) ;; *) die "REPLICAS must be 1 or 2" ;; esac
  stop
  mkdir -p "$DIR"
  if ! command -v haproxy >/dev/null 2>&1; then
    echo "replicas: installing HAProxy from the distribution's packages" >&2
    local sudo=""
    [ "$(id -u)" = 0 ] || sudo=sudo
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq haproxy >/dev/null
  fi
  if [ ! -x "$BIN" ]; then
    (cd "$ROOT" && cargo build --release --locked --bin robocal >&2)
  fi
  local server db
  server=$("$ROOT/scripts/pg_cluster.sh" start)
  db="replicas_$(date +%s)_$$"
  psql -q "$server" -c "CREATE DATABASE $db TEMPLATE template0 LC_COLLATE 'C' LC_CTYPE 'C' ENCODING 'UTF8'" >&2
  local url="${server%/*}/$db"
  echo "$url" > "$DIR/db.url"
  local token
  token=$("$BIN" token create --db "$url" --name admin --scopes admin | python3 -c 'import json,sys; print(json.load(sys.stdin)["token"])')
  local addrs=()
  for i in $(seq 1 "$REPLICAS"); do
    local port
    port=$(free_port)
    RUST_LOG=${RUST_LOG:-warn} nohup "$BIN" serve --db "$url" --bind "127.0.0.1:$port" --require-auth \
      > "$DIR/replica-$i.log" 2>&1 &
    echo $! > "$DIR/replica-$i.pid"
    addrs+=("127.0.0.1:$port")
  done
  for a in "${addrs[@]}"; do wait_ready "http://$a"; done
  # One replica: the second server line points at the first as well (the file names two).
  local proxy
  proxy=$(free_port)
  ROBOCAL_PROXY_BIND="127.0.0.1:$proxy" ROBOCAL_1="${addrs[0]}" ROBOCAL_2="${addrs[${#addrs[@]}-1]}" \
    nohup haproxy -db -f "$ROOT/deploy/haproxy.cfg" > "$DIR/haproxy.log" 2>&1 &
  echo $! > "$DIR/haproxy.pid"
  wait_ready "http://127.0.0.1:$proxy"
  echo "http://127.0.0.1:$proxy"
  echo "$token"
}

case "${1:-}" in
  start) start ;;
  stop) stop ;;
  *) die "usage: scripts/replicas.sh start|stop" ;;
esac
