#!/usr/bin/env bash
# Run a command in a network namespace of its own with only loopback up, so nothing it sends
# (ROS 2's DDS discovery and data included) leaves the machine:
#
#   scripts/loopback-netns.sh CMD [ARG...]
#
# `unshare -rn` makes the namespace as an unprivileged user (mapped to root inside it, which
# `ip link set lo up` needs); ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST keeps DDS discovery on
# this host as well. The namespace goes away with the command.
set -euo pipefail
[[ $# -ge 1 ]] || { echo "usage: loopback-netns.sh CMD [ARG...]" >&2; exit 2; }
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
exec unshare -rn bash -c 'ip link set lo up && exec "$@"' loopback-netns "$@"
