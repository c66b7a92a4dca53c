#!/usr/bin/env bash
# A throwaway PostgreSQL server for the storage tests, on 127.0.0.1 only.
#
#   scripts/pg-test-server.sh start        # install if missing (as root), init .pg/, start, print the URL
#   scripts/pg-test-server.sh stop         # stop it (the cluster stays in .pg/ for next time)
#   scripts/pg-test-server.sh url          # print the URL of the running server
#   scripts/pg-test-server.sh run -- CMD   # CMD with SRLAB_TEST_POSTGRES_URL set, then stop the
#                                          # server if this started it; exits with CMD's status
#
# The URL is also written to .pg/url. Without PostgreSQL binaries (and not root to install
# them) it says what to install and carries on without a server (run) or exits 0 (start);
# with SRLAB_REQUIRE_PG=1 it exits 1 instead. `run` leaves an existing
# SRLAB_TEST_POSTGRES_URL alone and starts nothing.
set -euo pipefail
cd "$(dirname "$0")/.."

PGHOME="${SRLAB_PG_DIR:-$PWD/.pg}"
# As root the cluster belongs to `postgres`, which must reach it: if this clone is not open
# to that user, the cluster lives in /tmp instead (the URL file stays in .pg/).
if [[ -z "${SRLAB_PG_DIR:-}" && $(id -u) == 0 ]] && id postgres >/dev/null 2>&1 \
    && ! runuser -u postgres -- test -x "$PWD"; then
    PGHOME="/tmp/srlab-pg-$(printf %s "$PWD" | md5sum | cut -c1-12)"
fi
DATA="$PGHOME/data"
SOCK="$PGHOME/sock"
LOG="$PGHOME/server.log"
URLFILE="$PWD/.pg/url"
DB=srlab_test
FIRST_PORT="${SRLAB_PG_PORT:-54329}"

say() { echo "pg-test-server: $*" >&2; }

find_bin() {
    local d
    if [[ -n "${PG_BIN:-}" && -x "$PG_BIN/initdb" ]]; then echo "$PG_BIN"; return; fi
    for d in $(ls -d /usr/lib/postgresql/*/bin 2>/dev/null | sort -V -r); do
        if [[ -x "$d/initdb" && -x "$d/pg_ctl" ]]; then echo "$d"; return; fi
    done
    if command -v initdb >/dev/null && command -v pg_ctl >/dev/null; then
        dirname "$(command -v initdb)"
    fi
}

missing() {
    say "PostgreSQL server binaries (initdb, pg_ctl) not found."
    say "install them, e.g. 'apt-get install -y postgresql' (Debian/Ubuntu) or set PG_BIN."
    if [[ "${SRLAB_REQUIRE_PG:-0}" == 1 ]]; then exit 1; fi
    if [[ "${1:-start}" == start ]]; then exit 0; fi
    say "the PostgreSQL tests will be skipped"
}

BIN="$(find_bin || true)"
if [[ -z "$BIN" && "${1:-start}" =~ ^(start|run)$ && -z "${SRLAB_TEST_POSTGRES_URL:-}" ]]; then
    if [[ $(id -u) == 0 ]] && command -v apt-get >/dev/null; then
        say "installing PostgreSQL with apt-get"
        export DEBIAN_FRONTEND=noninteractive
        apt-get update -qq && apt-get install -y -qq postgresql >/dev/null || say "apt-get failed"
        BIN="$(find_bin || true)"
    fi
    [[ -n "$BIN" ]] || missing "${1:-start}"
fi

# initdb and postgres refuse to run as root: as root the cluster belongs to `postgres`.
as_owner() {
    if [[ $(id -u) == 0 ]]; then
        (cd / && runuser -u postgres -- "$@")
    else
        "$@"
    fi
}

port_in_use() { (exec 3<>"/dev/tcp/127.0.0.1/$1") 2>/dev/null; }

running() { [[ -n "$BIN" && -f "$DATA/PG_VERSION" ]] && as_owner "$BIN/pg_ctl" -D "$DATA" status >/dev/null 2>&1; }

start() {
    mkdir -p "$PGHOME"
    if [[ $(id -u) == 0 ]]; then
        id postgres >/dev/null 2>&1 || useradd --system --home-dir /var/lib/postgresql postgres
        chown postgres "$PGHOME"
        if ! runuser -u postgres -- test -w "$PGHOME"; then
            say "the postgres user cannot write $PGHOME (set SRLAB_PG_DIR to a folder it can reach)"
            exit 1
        fi
    fi
    mkdir -p "$(dirname "$URLFILE")"
    if running && [[ -s "$URLFILE" ]]; then
        createdb_if_missing "$(cat "$PGHOME/port")"
        cat "$URLFILE"
        return
    fi
    if [[ ! -f "$DATA/PG_VERSION" ]]; then
        as_owner "$BIN/initdb" -D "$DATA" -U postgres -A trust -E UTF8 --locale=C --no-sync >/dev/null
    fi
    as_owner mkdir -p "$SOCK"
    local port="$FIRST_PORT"
    while port_in_use "$port"; do
        port=$((port + 1))
        if ((port > FIRST_PORT + 50)); then say "no free port from $FIRST_PORT"; exit 1; fi
    done
    # Throwaway data: no fsync, so the tests do not wait for the disk.
    if ! as_owner "$BIN/pg_ctl" -D "$DATA" -l "$LOG" -w -t 60 start -o \
        "-c listen_addresses=127.0.0.1 -p $port -k $SOCK -c fsync=off -c synchronous_commit=off -c full_page_writes=off -c max_connections=50" \
        >/dev/null; then
        say "PostgreSQL did not start; its log:"
        tail -n 20 "$LOG" >&2 || true
        exit 1
    fi
    echo "$port" >"$PGHOME/port"
    createdb_if_missing "$port"
    echo "postgresql+psycopg://postgres@127.0.0.1:$port/$DB" >"$URLFILE"
    cat "$URLFILE"
}

createdb_if_missing() {
    local port="$1"
    if ! "$BIN/psql" -h 127.0.0.1 -p "$port" -U postgres -d postgres -tAqc \
        "SELECT 1 FROM pg_database WHERE datname = '$DB'" | grep -q 1; then
        "$BIN/createdb" -h 127.0.0.1 -p "$port" -U postgres "$DB"
    fi
}

stop() {
    if running; then as_owner "$BIN/pg_ctl" -D "$DATA" -m fast -w stop >/dev/null; fi
    rm -f "$URLFILE"
}

run() {
    if [[ -n "${SRLAB_TEST_POSTGRES_URL:-}" ]]; then exec "$@"; fi
    local url="" started=0 status=0
    if [[ -n "$BIN" ]]; then
        running || started=1
        url="$(start)" || exit 1
    fi
    if ((started)); then trap stop EXIT; fi
    SRLAB_TEST_POSTGRES_URL="$url" "$@" || status=$?
    exit "$status"
}

case "${1:-start}" in
    start) start ;;
    run)
        shift
        [[ "${1:-}" != -- ]] || shift
        run "$@"
        ;;
    stop) stop ;;
    url) if running && [[ -s "$URLFILE" ]]; then cat "$URLFILE"; else exit 1; fi ;;
    *) say "usage: $0 start|stop|url"; exit 2 ;;
esac
