#!/usr/bin/env bash
# The optional srlab[ros2] extra (rclpy, the Fast DDS middleware and the message packages the
# ROS 2 adapter reads, server/robots/ros2.py) in the project's .venv:
#
#   scripts/install-ros2.sh UV PYTHON     # what `make install-ros2` runs
#
# The extra at uv.lock's versions, added to the venv (`uv pip install`, so the dev group and
# the other extras stay). The wheels carry ROS 2's C libraries and find each other through
# their own ament index: no ROS install, no sourced setup file and no environment variable
# is needed. A later `uv sync` (make install, when pyproject.toml or uv.lock changed)
# removes the extra again, since it syncs exactly what the lock's default extras hold; run
# this again then.
set -euo pipefail

UV=${1:?usage: install-ros2.sh UV PYTHON}
PY=${2:?usage: install-ros2.sh UV PYTHON}

say() { echo "install-ros2: $*" >&2; }

if ! "$PY" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))'; then
    say "the ROS 2 wheels are built for CPython 3.11 only; this venv's Python is $("$PY" -V)"
    exit 1
fi
pins=$(mktemp)
trap 'rm -f "$pins"' EXIT
"$UV" export --frozen --quiet --extra ros2 --no-dev --no-hashes --no-emit-project >"$pins"
"$UV" pip install --quiet --compile-bytecode --python "$PY" --requirement "$pins"
"$PY" - <<'PYEOF'
import importlib.metadata as md
import sys

import rclpy  # noqa: F401
from geometry_msgs.msg import Twist  # noqa: F401
from nav_msgs.msg import Odometry  # noqa: F401
from sensor_msgs.msg import PointCloud  # noqa: F401
from std_msgs.msg import Float32MultiArray  # noqa: F401

print(f"install-ros2: rclpy {md.version('ros-rclpy')}, Fast DDS RMW {md.version('ros-rmw-fastrtps-cpp')}", file=sys.stderr)
PYEOF
