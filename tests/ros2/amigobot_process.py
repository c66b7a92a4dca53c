"""The fake AmigoBot (fake_amigobot.py) as a subprocess of a test, in lockstep by default.

In lockstep the fake robot steps a tick per command and publishes its time on `/clock`, and
`LOCKSTEP` (the AmigoBot's robot file with `use_sim_time`) reads message ages on that clock:
a test runs tick for tick as at 20 Hz, however busy the machine is. Losing the robot is
still wall-clock silence, given a second here (the fake robot, waiting, publishes every 20 ms).
"""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from core.sim.robotfile import load_robot_file

if TYPE_CHECKING:
    from server.robots.ros2 import Ros2World

FAKE = Path(__file__).resolve().parent / "fake_amigobot.py"
ROOT = FAKE.parents[2]
_AMIGOBOT = load_robot_file("amigobot")
LOCKSTEP = replace(
    _AMIGOBOT,
    use_sim_time=True,
    lost_after_s=1.0,
    topics=tuple(replace(t, stale_after_s=1.0) for t in _AMIGOBOT.topics),
)
"""The AmigoBot's robot file on the fake robot's own clock. A message without a header
(the bumper's, the camera's) is aged from when this process reads it, and a busy machine
may read it several of the robot's ticks late: its staleness limit is 20 ticks here."""
GUARD_S = 60.0
"""A guard against hanging, not a speed goal."""


def settle(world: Ros2World, ticks: int) -> None:
    """Wait until the robot has stepped `ticks` ticks (its odometry says so)."""
    deadline = time.monotonic() + GUARD_S
    while world.robot_time < ticks / world.robot.hz - 1e-6:
        assert time.monotonic() < deadline, f"the robot did not reach tick {ticks}"
        time.sleep(0.001)


class FakeRobot:
    """A running fake AmigoBot: its process, and what it printed when it stopped."""

    def __init__(self, args: tuple[str, ...]) -> None:
        self.process = subprocess.Popen(
            [sys.executable, str(FAKE), *args],
            cwd=ROOT,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        self.stats: dict[str, Any] = {}

    def kill(self) -> None:
        """Kill it on the spot (SIGKILL), as a robot that loses power."""
        self.process.send_signal(signal.SIGKILL)
        self.process.wait(timeout=30)

    def stop(self) -> None:
        """Stop it: it reports what it got (`stats`) and exits."""
        out, _ = self.process.communicate(timeout=30)  # closes its input first
        if out.strip():
            self.stats = json.loads(out.strip().splitlines()[-1])


def heard_all(world: Ros2World) -> None:
    """Wait until every channel the robot feeds has been heard (each topic's discovery
    ends on its own: one may still be unheard when the first odometry arrives)."""
    deadline = time.monotonic() + GUARD_S
    while any(math.isnan(world.latest().channels[c]) for c in world.fed):
        assert time.monotonic() < deadline, "the robot's topics were not all heard"
        time.sleep(0.01)


@contextmanager
def fake_amigobot(*args: str, lockstep: bool = True) -> Iterator[FakeRobot]:
    """`with fake_amigobot("--rate", "10") as robot:` runs the fake AmigoBot meanwhile."""
    robot = FakeRobot((*args, "--lockstep") if lockstep else args)
    try:
        yield robot
    finally:
        robot.stop()
