#!/usr/bin/env bash
# A throwaway PostgreSQL cluster for the tests (issue 27, item 5): no mock, a real server.
#
#   scripts/pg_cluster.sh start   # install PostgreSQL if missing, start the cluster, print its URL
#   scripts/pg_cluster.sh url     # print the URL of the running cluster (exit 1 when none runs)
#   scripts/pg_cluster.sh stop    # stop the cluster and remove its directory
#
# The cluster lives in one temporary directory (data, socket, log) and listens on 127.0.0.1 only,
# on a free port, with trust authentication for the superuser `robocal`; its database `robocal`
# uses the C locale, so text sorts bytewise as in SQLite. It runs as an unprivileged user:
# the invoking user, or — when that is root (PostgreSQL refuses to run as root) — the system user
# `robocal-pg`, created when missing. Durability is switched off (fsync, synchronous_commit,
# full_page_writes): the cluster is thrown away, and the tests need speed, not crash safety.
#
# Idempotent: `start` on a running cluster prints its URL; `stop` without one does nothing. The
# directory is `$ROBOCAL_PG_DIR`, by default one per checkout and user under the temp dir, so two
# worktrees on one machine get two clusters.
set -euo pipefail

ROOT=$(cd "$(dirname "$0")/.." && pwd)
KEY=$(printf '%s' "$ROOT" | sha256sum | cut -c1-12)
DIR=${ROBOCAL_PG_DIR:-${TMPDIR:-/tmp}/robocal-pg-$(id -u)-$KEY}
PG_USER_OS=robocal-pg

die() { echo "pg_cluster: $*" >&2; exit 1; }

# The directory holding initdb/pg_ctl/postgres: PATH first, then the distribution's layout
# (/usr/lib/postgresql/<version>/bin, highest version).
pg_bindir() {
  local d
  if command -v initdb >/dev/null 2>&1 && command -v pg_ctl >/dev/null 2>&1; then
    d=$(dirname "$(readlink -f "$(command -v initdb)")")
    [ -x "$d/postgres" ] && { echo "$d"; return 0; }
  fi
  d=$(ls -d /usr/lib/postgresql/*/bin 2>/dev/null | sort -V | tail -n 1 || true)
  [ -n "$d" ] && [ -x "$d/initdb" ] && [ -x "$d/pg_ctl" ] && [ -x "$d/postgres" ] && { echo "$d"; return 0; }
  return 1
}

install_postgres() {
  echo "pg_cluster: PostgreSQL not found; installing the distribution's package" >&2
  local sudo=""
  [ "$(id -u)" = 0 ] || sudo=sudo
  local t0=$SECONDS
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq postgresql >/dev/null
  echo "pg_cluster: installed in $((SECONDS - t0)) s" >&2
}

# Run a command as the cluster's owner.
as_owner() {
  if [ "$(id -u)" = 0 ]; then
    runuser -u "$PG_USER_OS" -- "$@"
  else
    "$@"
  fi
}

ensure_owner() {
  [ "$(id -u)" = 0 ] || return 0
  if ! id "$PG_USER_OS" >/dev/null 2>&1; then
    useradd --system --no-create-home --home-dir /nonexistent --shell /usr/sbin/nologin "$PG_USER_OS"
  fi
}

# A TCP port on 127.0.0.1 that nothing listens on now.
free_port() {
  python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1]); s.close()'
}

# Whether the cluster answers: asked over its port (`pg_ctl status` only checks that the pid in
# postmaster.pid exists, which a killed, unreaped server still does).
running() {
  local bin
  [ -f "$DIR/port" ] && [ -d "$DIR/data" ] || return 1
  bin=$(pg_bindir) || return 1
  "$bin/pg_isready" -q -h 127.0.0.1 -p "$(cat "$DIR/port")" -t 5
}

url() {
  echo "postgres://robocal@127.0.0.1:$(cat "$DIR/port")/robocal"
}

start() {
  if running; then
    url
    return 0
  fi
  local bin
  bin=$(pg_bindir) || { install_postgres; bin=$(pg_bindir) || die "no initdb/pg_ctl after installing postgresql"; }
  ensure_owner
  # A directory left by a cluster that died (or a half-made one): start afresh.
  [ -d "$DIR/data" ] && { as_owner "$bin/pg_ctl" stop -D "$DIR/data" -m immediate >/dev/null 2>&1 || true; }
  rm -rf "$DIR"
  mkdir -p "$DIR"
  chmod 700 "$DIR"
  [ "$(id -u)" = 0 ] && chown "$PG_USER_OS": "$DIR"
  as_owner "$bin/initdb" -D "$DIR/data" -U robocal --auth=trust --no-locale -E UTF8 --no-sync >"$DIR/initdb.log" 2>&1 ||
    { cat "$DIR/initdb.log" >&2; die "initdb failed"; }
  local port tries=0
  while :; do
    port=$(free_port)
    if as_owner "$bin/pg_ctl" start -D "$DIR/data" -l "$DIR/server.log" -w -t 60 -o \
      "-c listen_addresses=127.0.0.1 -c port=$port -c unix_socket_directories=$DIR -c fsync=off -c synchronous_commit=off -c full_page_writes=off -c max_connections=200" \
      >/dev/null; then
      break
    fi
    tries=$((tries + 1))
    # Another process may have taken the port between the probe and the start: try another.
    [ "$tries" -lt 3 ] || { cat "$DIR/server.log" >&2; die "the server did not start"; }
  done
  echo "$port" >"$DIR/port"
  as_owner "$bin/createdb" -h 127.0.0.1 -p "$port" -U robocal -T template0 -E UTF8 --locale=C robocal
  url
}

stop() {
  local bin
  if [ -d "$DIR/data" ] && bin=$(pg_bindir); then
    as_owner "$bin/pg_ctl" stop -D "$DIR/data" -m fast -w >/dev/null 2>&1 || true
  fi
  rm -rf "$DIR"
}

case "${1:-}" in
  start) start ;;
  stop) stop ;;
  url) running || die "no cluster is running in $DIR"; url ;;
  *) echo "usage: $0 start|stop|url" >&2; exit 2 ;;
esac
