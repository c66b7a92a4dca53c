#!/usr/bin/env bash
# What the test suite needs beyond Python: Debian's Chromium (browser tests), docker-compose
# v1 (validates docker-compose.yml without an engine), podman and debootstrap (tests/deploy
# builds and runs the image and the compose stack), and podman-compose from PyPI into .tools/.
#
#   scripts/system-deps.sh          # install what is missing (as root, with apt-get),
#                                   # otherwise say what to install and carry on
#
# With SRLAB_REQUIRE_BROWSER=1 (CI) a missing Chromium is an error instead.
# PostgreSQL is handled by scripts/pg-test-server.sh, which also starts it; the images the
# containers start from, by scripts/podman-bases.sh.
set -euo pipefail
cd "$(dirname "$0")/.."

# podman-compose runs docker-compose.yml itself under podman. Debian's (1.0.3) has no
# --env-file and no `config`; this one is the same project (containers/podman-compose).
PODMAN_COMPOSE=1.6.0

say() { echo "system-deps: $*" >&2; }

declare -A NEED=()
[[ -x /usr/bin/chromium ]] || NEED[chromium]=1
command -v docker-compose >/dev/null || NEED[docker-compose]=1
command -v podman >/dev/null || NEED[podman]=1
command -v debootstrap >/dev/null || NEED[debootstrap]=1

if ((${#NEED[@]})); then
    if [[ $(id -u) == 0 ]] && command -v apt-get >/dev/null; then
        say "installing ${!NEED[*]} with apt-get"
        export DEBIAN_FRONTEND=noninteractive
        apt-get update -qq && apt-get install -y -qq "${!NEED[@]}" >/dev/null || say "apt-get failed"
    else
        say "missing: ${!NEED[*]}; install with 'sudo apt-get install -y ${!NEED[*]}'"
        say "the tests that need them will be skipped"
    fi
fi
if [[ "${SRLAB_REQUIRE_BROWSER:-0}" == 1 && ! -x /usr/bin/chromium ]]; then
    say "Chromium is required (SRLAB_REQUIRE_BROWSER=1) and /usr/bin/chromium is missing"
    exit 1
fi

# Podman as root sets each container's open-files limit to 1048576 unless told otherwise;
# where the hard limit is lower (a sandboxed machine), no container starts ("error setting
# rlimits ... operation not permitted"). An empty list keeps the limits podman runs with.
CONF=/etc/containers/containers.conf
if command -v podman >/dev/null && [[ $(id -u) == 0 ]] \
    && ! grep -qsE '^\s*default_ulimits\s*=' "$CONF"; then
    mkdir -p "$(dirname "$CONF")"
    if grep -qsE '^\s*\[containers\]' "$CONF"; then
        sed -i -E '0,/^\s*\[containers\]/s//[containers]\ndefault_ulimits = []/' "$CONF"
    else
        printf '[containers]\ndefault_ulimits = []\n' >>"$CONF"
    fi
    say "set default_ulimits = [] in $CONF"
fi

if command -v podman >/dev/null && [[ ! -x .tools/bin/podman-compose \
    || "$(.tools/bin/podman-compose --version 2>/dev/null)" != *"version $PODMAN_COMPOSE"* ]]; then
    [[ -x .tools/bin/pip ]] || python3 -m venv .tools
    .tools/bin/pip install --quiet "podman-compose==$PODMAN_COMPOSE" || say "pip failed"
fi
