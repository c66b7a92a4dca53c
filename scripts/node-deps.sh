#!/usr/bin/env bash
# node and npm for the web client's tooling (ESLint in `make lint`; web/test/ under node's
# test runner): Debian's packages, installed with apt-get when missing (as root), otherwise
# say what to install. ESLint 9 needs node 18.18 or later (Debian 12 has 18.20).
set -euo pipefail

command -v node >/dev/null && command -v npm >/dev/null && exit 0
if [[ $(id -u) == 0 ]] && command -v apt-get >/dev/null; then
    echo "node-deps: installing nodejs and npm with apt-get" >&2
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq && apt-get install -y -qq nodejs npm >/dev/null
else
    echo "node-deps: node and npm are missing: 'sudo apt-get install -y nodejs npm'" >&2
    exit 1
fi
