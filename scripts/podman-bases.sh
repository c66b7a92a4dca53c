#!/usr/bin/env bash
# Stand-ins, made from Debian's packages, for the two images the container set-up pulls
# (python:3.11-slim-bookworm for the Dockerfile, postgres:16-bookworm for compose), so that
# tests/deploy can build and run them with podman where no outside image can be pulled.
#
#   scripts/podman-bases.sh      # build them if missing or stale (as root), print their names
#
# It prints `PYTHON_IMAGE=<name>` and `POSTGRES_IMAGE=<name>` on stdout. Each image carries
# a label with a hash of this file and the machine's extra CA certificates: a run with the
# same hash reuses them (0.1 s), another rebuilds them: 74 to 79 s for both at once on a
# busy 2-core machine (docs/deploy.md). The packages debootstrap downloads stay in
# $SRLAB_DEBOOTSTRAP_CACHE (default /var/cache/srlab-debootstrap) for the next build.
#
# Without podman or debootstrap, or not as root, it says what is missing and exits 0 (the
# tests that need the images skip); with SRLAB_REQUIRE_PODMAN=1 (CI) it exits 1 instead.
# scripts/system-deps.sh installs podman, podman's configuration and debootstrap.
#
# The Python stand-in is Debian's python3.11 with pip and venv, linked where the official
# image has its Python (/usr/local/bin), without Debian's "externally managed" marker, and
# trusting the machine's CA certificates (this machine's egress re-signs TLS), with
# UV_SYSTEM_CERTS=1 so that uv in the build trusts them too. The PostgreSQL stand-in is
# Debian's postgresql (15 on bookworm) with an entry point that honours the official
# image's POSTGRES_USER, POSTGRES_PASSWORD, POSTGRES_DB and PGDATA, as compose uses them.
set -euo pipefail
SELF="$(realpath "$0")"

PYTHON_IMAGE=localhost/srlab-standin/python:3.11-slim-bookworm
POSTGRES_IMAGE=localhost/srlab-standin/postgres:bookworm
SUITE=bookworm
CACHE="${SRLAB_DEBOOTSTRAP_CACHE:-/var/cache/srlab-debootstrap}"
EXTRA_CA=(/usr/local/share/ca-certificates/*.crt)
[[ -e "${EXTRA_CA[0]}" ]] || EXTRA_CA=()

say() { echo "podman-bases: $*" >&2; }

unavailable() {
    say "$1"
    if [[ "${SRLAB_REQUIRE_PODMAN:-0}" == 1 ]]; then exit 1; fi
    say "the tests that run containers will be skipped"
    exit 0
}

command -v podman >/dev/null || unavailable "podman is missing: run scripts/system-deps.sh as root"
command -v debootstrap >/dev/null \
    || unavailable "debootstrap is missing: run scripts/system-deps.sh as root"
[[ $(id -u) == 0 ]] || unavailable "building the stand-in images needs root (debootstrap)"

KEY="$(cat "$SELF" "${EXTRA_CA[@]}" | sha256sum | cut -c1-16)"

# The Debian mirror apt uses here (deb822 sources first, then one-line ones).
mirror() {
    local found
    found="$(grep -hsE '^\s*URIs:' /etc/apt/sources.list.d/*.sources \
        | awk '{print $2}' | grep -E '/debian/?$' | head -n1 || true)"
    if [[ -z "$found" ]]; then
        found="$(grep -hsE '^\s*deb\s' /etc/apt/sources.list /etc/apt/sources.list.d/*.list \
            | awk '{print $2}' | grep -E '/debian/?$' | head -n1 || true)"
    fi
    echo "${found:-http://deb.debian.org/debian}"
}

current() {
    [[ "$(podman image inspect --format '{{index .Labels "srlab.standin"}}' "$1" 2>/dev/null)" \
        == "$KEY" ]]
}

# A minbase Debian tree in $1 with the packages $2 (comma-separated). In two stages, with
# dpkg's unsafe-io set between them (Debian's official images set it too): otherwise dpkg
# syncs every file it unpacks, which took most of the build on a busy disk.
bootstrap() {
    local root="$1" log="$WORK/${1##*/}.log" cache="$CACHE/${1##*/}"
    mkdir -p "$cache"
    if ! {
        debootstrap --foreign --variant=minbase --include="$2" --cache-dir="$cache" \
            "$SUITE" "$root" "$(mirror)" \
            && echo force-unsafe-io >"$root/etc/dpkg/dpkg.cfg.d/unsafe-io" \
            && chroot "$root" /debootstrap/debootstrap --second-stage
    } >"$log" 2>&1; then
        cp "$log" "/var/tmp/srlab-podman-bases-${1##*/}.log"
        tail -n 20 "$log" >&2
        say "debootstrap failed (the whole log: /var/tmp/srlab-podman-bases-${1##*/}.log)"
        exit 1
    fi
    rm -rf "$root"/var/cache/apt/archives/*.deb "$root"/var/lib/apt/lists/*
}

# The tree $1 as the image $2, with the Containerfile-style --change lines that follow.
import_tree() {
    local tree="$1" name="$2" changes=() change replaced
    shift 2
    for change in "$@" "LABEL srlab.standin=$KEY"; do changes+=(--change "$change"); done
    replaced="$(podman image inspect --format '{{.Id}}' "$name" 2>/dev/null || true)"
    tar -C "$tree" --numeric-owner -c . | podman import --quiet "${changes[@]}" - "$name" >/dev/null
    rm -rf "$tree"
    # The stale stand-in, unless an image built on it still needs it.
    [[ -z "$replaced" ]] || podman rmi "$replaced" >/dev/null 2>&1 || true
}

python_image() {
    local root="$WORK/python"
    say "building $PYTHON_IMAGE from Debian $SUITE"
    bootstrap "$root" python3.11,python3-pip,python3-venv,ca-certificates
    ln -sf /usr/bin/python3.11 "$root/usr/local/bin/python3.11"
    ln -sf python3.11 "$root/usr/local/bin/python3"
    ln -sf python3.11 "$root/usr/local/bin/python"
    rm -f "$root"/usr/lib/python3.*/EXTERNALLY-MANAGED
    if ((${#EXTRA_CA[@]})); then
        cp "${EXTRA_CA[@]}" "$root/usr/local/share/ca-certificates/"
        chroot "$root" update-ca-certificates --fresh >/dev/null 2>&1
    fi
    import_tree "$root" "$PYTHON_IMAGE" \
        "ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin" \
        "ENV LANG=C.UTF-8" \
        "ENV SSL_CERT_FILE=/etc/ssl/certs/ca-certificates.crt" \
        "ENV UV_SYSTEM_CERTS=1" \
        'CMD ["python3"]'
}

postgres_image() {
    local root="$WORK/postgres" bin
    say "building $POSTGRES_IMAGE from Debian $SUITE"
    bootstrap "$root" postgresql
    bin="$(ls -d "$root"/usr/lib/postgresql/*/bin | sort -V | tail -n1)"
    bin="${bin#"$root"}"
    # The package's own cluster: the entry point makes one in $PGDATA instead.
    rm -rf "$root"/etc/postgresql/*/main "$root"/var/lib/postgresql/*/main
    write_entrypoint "$root/usr/local/bin/docker-entrypoint.sh"
    import_tree "$root" "$POSTGRES_IMAGE" \
        "ENV PATH=$bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin" \
        "ENV LANG=C.UTF-8" \
        "ENV PGDATA=/var/lib/postgresql/data" \
        "VOLUME /var/lib/postgresql/data" \
        "EXPOSE 5432" \
        "STOPSIGNAL SIGINT" \
        'ENTRYPOINT ["docker-entrypoint.sh"]' \
        'CMD ["postgres"]'
}

# The official image's entry point, as far as srlab's compose file relies on it.
write_entrypoint() {
    cat >"$1" <<'EOF'
#!/bin/sh
# On an empty $PGDATA: a cluster whose superuser is $POSTGRES_USER (default postgres) with
# $POSTGRES_PASSWORD, and the database $POSTGRES_DB (default the user's name). Then the
# server, as the user postgres, on every interface: password (scram) authentication over
# the network, trust over the local socket (where the healthcheck's pg_isready asks).
set -eu
if [ "${1:-}" != postgres ]; then exec "$@"; fi
if [ "$(id -u)" = 0 ]; then
    mkdir -p "$PGDATA" /run/postgresql
    chown -R postgres:postgres "$PGDATA" /run/postgresql
    chmod 700 "$PGDATA"
    exec setpriv --reuid=postgres --regid=postgres --init-groups "$0" "$@"
fi
if [ ! -s "$PGDATA/PG_VERSION" ]; then
    : "${POSTGRES_PASSWORD:?POSTGRES_PASSWORD is not set}"
    user="${POSTGRES_USER:-postgres}"
    db="${POSTGRES_DB:-$user}"
    pwfile="$(mktemp)"
    printf '%s\n' "$POSTGRES_PASSWORD" >"$pwfile"
    initdb -D "$PGDATA" --username="$user" --pwfile="$pwfile" --encoding=UTF8 \
        --locale=C.UTF-8 --auth-local=trust --auth-host=scram-sha-256 >/dev/null
    rm -f "$pwfile"
    echo "host all all all scram-sha-256" >>"$PGDATA/pg_hba.conf"
    if [ "$db" != postgres ]; then
        pg_ctl -D "$PGDATA" -o "-c listen_addresses=''" -w start >/dev/null
        psql -v ON_ERROR_STOP=1 -q --username="$user" --dbname=postgres \
            -c "CREATE DATABASE \"$db\""
        pg_ctl -D "$PGDATA" -m fast -w stop >/dev/null
    fi
    echo "docker-entrypoint.sh: initialised $PGDATA (user $user, database $db)"
fi
exec "$@" -c listen_addresses='*'
EOF
    chmod 755 "$1"
}

# One build at a time on this machine (several work trees may run the tests at once).
exec 9>/run/lock/srlab-podman-bases.lock
flock 9
WORK=""
if ! current "$PYTHON_IMAGE" || ! current "$POSTGRES_IMAGE"; then
    WORK="$(mktemp -d /var/tmp/srlab-podman-bases.XXXXXX)"
    trap 'rm -rf "$WORK"' EXIT
    started=$SECONDS
    # Both at once: each mostly waits on the disk and the network.
    pids=()
    if ! current "$PYTHON_IMAGE"; then python_image & pids+=($!); fi
    if ! current "$POSTGRES_IMAGE"; then postgres_image & pids+=($!); fi
    failed=0
    for pid in "${pids[@]}"; do wait "$pid" || failed=1; done
    ((failed == 0)) || exit 1
    say "built in $((SECONDS - started)) s"
fi
echo "PYTHON_IMAGE=$PYTHON_IMAGE"
echo "POSTGRES_IMAGE=$POSTGRES_IMAGE"
