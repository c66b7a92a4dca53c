"""Imported first by the ROS 2 tests: skips their module without the ros2 extra or off loopback.

The tests talk DDS to a fake robot; inside `make test-ros2`'s network namespace
(scripts/loopback-netns.sh) only loopback exists, so none of it leaves the machine. Outside
it they skip rather than send discovery traffic onto the host's network. With
SRLAB_REQUIRE_ROS2=1 (CI) they fail instead of skipping.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from core.sim.robotfile import INSTALL_HINT


def _skip(reason: str) -> None:
    if os.environ.get("SRLAB_REQUIRE_ROS2") == "1":
        pytest.fail(f"SRLAB_REQUIRE_ROS2=1 and {reason}", pytrace=False)
    pytest.skip(reason, allow_module_level=True)


try:
    import rclpy  # noqa: F401
except ImportError as e:
    _skip(f"{e.name} is not installed: {INSTALL_HINT}; `make test-ros2` runs these tests")

_INTERFACES = [
    line.split(":", 1)[0].strip()
    for line in Path("/proc/net/dev").read_text(encoding="utf-8").splitlines()[2:]
]
if _INTERFACES != ["lo"]:
    _skip(
        f"network interfaces {', '.join(_INTERFACES)} besides loopback: the ROS 2 tests run "
        "only in a namespace with loopback alone; `make test-ros2` runs them in one"
    )
