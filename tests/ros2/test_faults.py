"""Faults on the fake AmigoBot: it dies mid-lap, its sonar stops, it publishes 10x as often."""

from __future__ import annotations

import asyncio
import math
import signal
import threading
import time
from typing import Any

import ros2_or_skip  # noqa: F401  # before rclpy: skips the module without it
from amigobot_process import GUARD_S, LOCKSTEP, fake_amigobot, heard_all, settle
from fakes import InMemoryRunStore

from core.brain.catalog import load_catalog
from core.engine import RunEngine
from core.ports import Mode, RunSpec, RunStatus
from core.run.conditions import CONDITIONS
from core.run.simulation import Simulation
from core.sim.channels import CHANNELS
from server.robots.ros2 import Ros2World

CATALOG = load_catalog()
ROBOT = LOCKSTEP
SONAR_STIMULI = {s.id for s in CATALOG.stimuli if s.sensor in ("wall", "sonar_obstacle")}


class TwistListener:
    """Every Twist on `cmd_vel`, as (linear.x, angular.z), heard by a node of its own."""

    def __init__(self) -> None:
        import rclpy  # after ros2_or_skip
        from geometry_msgs.msg import Twist
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile
        from rclpy.signals import SignalHandlerOptions

        self.heard: list[tuple[float, float]] = []
        self._context = rclpy.Context()
        rclpy.init(context=self._context, signal_handler_options=SignalHandlerOptions.NO)
        self._node = rclpy.create_node("twist_listener", context=self._context)
        self._node.create_subscription(Twist, ROBOT.cmd_vel, self._hear, QoSProfile(depth=100))
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self._node)
        self._thread = threading.Thread(target=self._executor.spin, daemon=True)
        self._thread.start()

    def _hear(self, msg: Any) -> None:
        self.heard.append((float(msg.linear.x), float(msg.angular.z)))

    def close(self) -> None:
        self._executor.shutdown()
        self._thread.join(timeout=5)
        self._node.destroy_node()
        self._context.shutdown()


def test_a_robot_killed_mid_lap_gets_a_zero_twist_and_the_run_stops() -> None:
    listener = TwistListener()
    with fake_amigobot("--world", ROBOT.world) as fake:
        world = Ros2World(ROBOT)
        spec = RunSpec("innate", 1, None, Mode.REALTIME, hz=ROBOT.hz, world=ROBOT.world)
        engine = RunEngine.create(spec, InMemoryRunStore(CATALOG), world=world)

        async def scenario() -> RunStatus:
            loop = asyncio.get_running_loop()
            world.on_lost(lambda: loop.call_soon_threadsafe(engine.stop))
            run = asyncio.create_task(engine.run())
            async with asyncio.timeout(GUARD_S):
                while engine.sim.tick_count < 60:  # 3 s into the lap
                    await asyncio.sleep(0.01)
                moving = engine.sim.snapshot.x
                fake.kill()
                status = await run
            assert engine.sim.snapshot.x == moving or engine.sim.tick_count > 60
            return status

        try:
            status = asyncio.run(scenario())
            deadline = time.monotonic() + GUARD_S  # the zero Twist on its way to the listener
            while not listener.heard or listener.heard[-1] != (0.0, 0.0):
                assert time.monotonic() < deadline, listener.heard[-3:]
                time.sleep(0.01)
        finally:
            world.close()
            listener.close()
    assert fake.process.returncode == -signal.SIGKILL
    assert world.lost
    assert status is RunStatus.STOPPED
    assert any(speed > 0 for speed, _ in listener.heard), "it drove before"
    # The zero Twist went out once the robot was silent for lost_after_s (bench/ros2.py
    # measures how soon after).
    assert world.stopped_after_s >= ROBOT.lost_after_s


def _simulation(world: Ros2World) -> Simulation:
    sim = Simulation(CONDITIONS["innate"], 1, world=world, catalog=CATALOG)
    sim.reset()
    heard_all(world)
    return sim


def test_a_sonar_gone_quiet_is_stale_and_releases_nothing() -> None:
    with fake_amigobot("--world", ROBOT.world, "--sonar-for-s", "2") as _:
        world = Ros2World(ROBOT)
        try:
            sim = _simulation(world)
            fresh, stale = 0, 0
            deadline = time.monotonic() + GUARD_S
            while stale < 20 and time.monotonic() < deadline:
                sim.tick()
                sonars = sim.sonar_m()  # read at the end of the tick: the next one acts on them
                upcoming = set(sim.upcoming_stimuli())
                if all(math.isnan(v) for v in sonars):
                    stale += 1
                    names = [CATALOG.stimuli[s].name for s in upcoming & SONAR_STIMULI]
                    assert not names, names
                else:
                    assert stale == 0, "a sonar that stopped stays stale"
                    assert all(math.isfinite(v) for v in sonars)
                    fresh += 1
                settle(world, world.sent)
        finally:
            world.close()
    assert fresh > 0
    assert stale == 20


def test_ten_times_the_message_rate_leaves_no_backlog() -> None:
    with fake_amigobot("--world", ROBOT.world, "--rate", "10") as fake:
        world = Ros2World(ROBOT)
        try:
            sim = _simulation(world)
            for _ in range(60):
                frame = world.step()
                stale = [CHANNELS[c] for c in sorted(world.fed) if math.isnan(frame.channels[c])]
                assert not stale, "every channel the robot feeds"
                sim.tick()
                settle(world, world.sent)
        finally:
            world.close()
        fake.stop()
    assert world.rejected == 0
    # A command a tick, the zero Twist of close(), and any zero Twist sent while the machine
    # was too busy to command it for two of its ticks.
    assert world.sent == 61 + world.held
    assert 0 < fake.stats["commands"] <= world.sent


def test_a_robot_left_without_commands_is_stopped() -> None:
    listener = TwistListener()
    with fake_amigobot("--world", ROBOT.world) as _:
        world = Ros2World(ROBOT)
        try:
            sim = _simulation(world)
            while not any(speed > 0 for speed, _ in listener.heard):  # it drives off
                sim.tick()
                settle(world, world.sent)
                assert sim.tick_count < 200, "it never drove"
            sent, held = world.sent, world.held
            deadline = time.monotonic() + GUARD_S  # then nothing commands it (a pause)
            while listener.heard[-1] != (0.0, 0.0):
                assert time.monotonic() < deadline, listener.heard[-3:]
                time.sleep(0.01)
        finally:
            world.close()
            listener.close()
    assert world.held == held + 1
    assert world.sent == sent + 2  # the held stop, then close()'s
    assert not world.lost
