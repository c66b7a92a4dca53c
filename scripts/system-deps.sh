#!/usr/bin/env bash
# System packages the test suite needs beyond Python: Debian's Chromium (browser tests) and
# docker-compose v1 (validates docker-compose.yml without an engine).
#
#   scripts/system-deps.sh          # install what is missing (as root, with apt-get),
#                                   # otherwise say what to install and carry on
#
# With SRLAB_REQUIRE_BROWSER=1 (CI) a missing Chromium is an error instead.
# PostgreSQL is handled by scripts/pg-test-server.sh, which also starts it.
set -euo pipefail

say() { echo "system-deps: $*" >&2; }

declare -A NEED=()
[[ -x /usr/bin/chromium ]] || NEED[chromium]=1
command -v docker-compose >/dev/null || NEED[docker-compose]=1

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
