"""A whole lap on the fake AmigoBot through the ROS 2 adapter, paced by its clock at 20 Hz.

The fake robot runs in lockstep (a tick per command, on its own clock): the lap takes
730-odd ticks of 50 ms of the robot's time however long the machine needs for them. Its
world has no obstacle: the innate behaviours drive into one and back off from it until the
timing of a busy machine's messages frees the robot, seconds or minutes later (there is no
referee on a robot to end the episode at the contact).
"""

from __future__ import annotations

import asyncio

import ros2_or_skip  # noqa: F401  # before rclpy: skips the module without it
from amigobot_process import LOCKSTEP, fake_amigobot
from fakes import InMemoryRunStore

from core.brain.catalog import load_catalog
from core.engine import RunEngine
from core.events import Outcome
from core.ports import Mode, RunSpec, RunStatus
from server.robots.ros2 import RobotPacer, Ros2World

CATALOG = load_catalog()


def test_a_whole_lap_through_the_adapter_at_20_hz() -> None:
    robot = LOCKSTEP
    assert robot.hz == 20.0
    with fake_amigobot("--world", robot.world, "--hz", "20", "--no-obstacle") as fake:
        world = Ros2World(robot)
        try:
            spec = RunSpec("innate", 1, 1, Mode.REALTIME, hz=robot.hz, world=robot.world)
            store = InMemoryRunStore(CATALOG)
            engine = RunEngine.create(spec, store, world=world, pacer=RobotPacer(world))
            status = asyncio.run(engine.run())
        finally:
            world.close()
        fake.stop()
    snap = engine.sim.snapshot
    assert status is RunStatus.FINISHED
    assert snap.outcome is Outcome.SUCCESS, snap
    assert snap.progress_m >= world.geometry.lap_length_m
    assert world.rejected == 0
    # Every tick sent its command, and the robot drove on them.
    assert world.sent >= snap.tick
    assert 0 < fake.stats["commands"] <= world.sent
