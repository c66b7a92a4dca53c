"""The robots a run host drives: each run on a robot (world ``ros2:ROBOT``) reaches it here.

`Robots.connect` is the `core.engine.build.Connect` a host hands `RunEngine.restore`: it
reads the run's robot file, makes sure no other run of this host drives that robot, and
opens the ROS 2 adapter (`server.robots.ros2`, from the optional srlab[ros2] extra) with the
robot's clock as the run's pacer. `release` closes it (a zero Twist, then leaves ROS 2) when
the run ends.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import TYPE_CHECKING

from core.errors import RunStateError
from core.sim.robotfile import RobotFileError, load_robot_file, robot_of

if TYPE_CHECKING:
    from core.engine.pacing import Pacer
    from core.ports import RunSpec
    from core.sim.world import World
    from server.robots.ros2 import Ros2World


class Robots:
    """The robots this host's runs drive, one run per robot."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._driving: dict[str, int] = {}
        """Robot name: the run driving it (claimed before its adapter opens)."""
        self._worlds: dict[int, Ros2World] = {}

    def connect_for(self, run_id: int) -> Callable[[RunSpec], tuple[World, Pacer]]:
        """A `Connect` for run `run_id`: it claims the robot before it reaches it."""

        def connect(spec: RunSpec) -> tuple[World, Pacer]:
            return self.connect(run_id, spec)

        return connect

    def connect(self, run_id: int, spec: RunSpec) -> tuple[World, Pacer]:
        """Reach the robot `spec`'s world names for run `run_id` (blocking: in a thread).

        `RunStateError` if another run drives it, its file cannot be read, or the
        srlab[ros2] extra is missing.
        """
        name = robot_of(spec.world)
        if name is None:
            raise RunStateError(f"run {run_id} runs in a simulated world, not on a robot")
        with self._lock:
            holder = self._driving.get(name)
            if holder is not None and holder != run_id:
                raise RunStateError(f"the robot {name!r} is driven by run {holder}: stop it first")
            self._driving[name] = run_id
        try:
            robot = load_robot_file(name)
            from server.robots.ros2 import RobotPacer, Ros2World

            try:
                world = Ros2World(robot)
            except ImportError as e:
                raise RunStateError(str(e)) from None
        except RobotFileError as e:
            self._unclaim(run_id)
            raise RunStateError(str(e)) from None
        except BaseException:
            self._unclaim(run_id)
            raise
        with self._lock:
            self._worlds[run_id] = world
        return world, RobotPacer(world)

    def world(self, run_id: int) -> Ros2World | None:
        """The adapter run `run_id` drives its robot through, while it does."""
        return self._worlds.get(run_id)

    def release(self, run_id: int) -> None:
        """The run ended (or never started): stop its robot and leave ROS 2 (blocking)."""
        with self._lock:
            world = self._worlds.pop(run_id, None)
        try:
            if world is not None:
                world.close()
        finally:
            self._unclaim(run_id)

    def _unclaim(self, run_id: int) -> None:
        with self._lock:
            for name, holder in list(self._driving.items()):
                if holder == run_id:
                    del self._driving[name]
