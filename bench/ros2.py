"""The brain on a ROS 2 robot: sensor-to-command latency and dropped commands.

Run as ``make bench-ros2`` (or ``bash scripts/loopback-netns.sh .venv/bin/python -m
bench.ros2 --ticks N`` after ``make install-ros2``): inside a network namespace with only
loopback, the fake AmigoBot (tests/ros2/fake_amigobot.py) runs as a process and a realtime
run of the engine drives it through the adapter (`server.robots.ros2.Ros2World`) at the robot
file's rate, paced by the robot's clock (`RobotPacer`), storing to SQLite as `srlab serve`
does, for ``--ticks`` ticks (default 10,000: 500 s at 20 Hz). Printed, not asserted:

- sensor-to-command latency, p50 / p99 / max: from the arrival of the newest sensor message
  a tick read to the publication of the Twist it decided (goal: p99 <= 10 ms);
- dropped commands: Twists published less Twists the robot received (goal: 0);
- ticks whose odometry was stale (the robot's messages came late);
- once the robot goes silent (it exits at the end), how long after its last message the
  zero Twist went out (goal: one tick period + 100 ms).

``--rate 10`` has the robot publish its sensors 10 times a tick.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from core.engine import RunEngine
from core.ports import Mode, RunSpec
from core.sim.robotfile import load_robot_file
from server.persistence.db import make_engine, make_sessionmaker
from server.persistence.migrate import upgrade
from server.persistence.sqlalchemy_repo import SqlAlchemyRunStore
from server.robots.ros2 import RobotPacer, Ros2World

FAKE = Path(__file__).resolve().parents[1] / "tests" / "ros2" / "fake_amigobot.py"


def _only_loopback() -> bool:
    lines = Path("/proc/net/dev").read_text(encoding="utf-8").splitlines()[2:]
    return [line.split(":", 1)[0].strip() for line in lines] == ["lo"]


def _pct(values: list[float], q: float) -> float:
    return statistics.quantiles(values, n=1000, method="inclusive")[round(q * 10) - 1]


def measure(robot_name: str, ticks: int, rate: int, folder: Path) -> dict[str, float]:
    """One realtime run of `ticks` ticks against the fake robot; its figures."""
    robot = load_robot_file(robot_name)
    fake = subprocess.Popen(
        [
            sys.executable,
            str(FAKE),
            "--world",
            robot.world,
            "--hz",
            str(robot.hz),
            "--rate",
            str(rate),
        ],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    world = Ros2World(robot)
    try:
        url = f"sqlite:///{folder / 'ros2.db'}"
        upgrade(url)
        store = SqlAlchemyRunStore(make_sessionmaker(make_engine(url)))
        spec = RunSpec("kp", 1, None, Mode.REALTIME, hz=robot.hz, world=robot.world)
        engine = RunEngine.create(spec, store, world=world, pacer=RobotPacer(world))
        started = time.monotonic()
        asyncio.run(engine.run(until_tick=ticks))
        elapsed = time.monotonic() - started
        time.sleep(0.5)  # the last Twists on their way
        sent = world.sent
        out, _ = fake.communicate(timeout=30)  # the robot goes silent: it is lost
        silent_until = time.monotonic() + 10
        while not world.lost and time.monotonic() < silent_until:
            time.sleep(0.01)
    finally:
        world.close()
        if fake.poll() is None:
            fake.kill()
    received = int(json.loads(out.strip().splitlines()[-1])["commands"])
    lat = [s * 1000 for s in world.latencies_s if s < 1e9]
    return {
        "ticks": len(world.latencies_s),
        "seconds": elapsed,
        "p50_ms": _pct(lat, 50),
        "p99_ms": _pct(lat, 99),
        "max_ms": max(lat),
        "stale_odometry_ticks": len(world.latencies_s) - len(lat),
        "dropped": sent - received,
        "stopped_after_ms": world.stopped_after_s * 1000,
        "stop_goal_ms": (1.0 / robot.hz + 0.1) * 1000,
    }


def main() -> None:
    """Measure and print."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="amigobot", help="a robot file (core/data/robots)")
    parser.add_argument("--ticks", type=int, default=10_000)
    parser.add_argument("--rate", type=int, default=1, help="sensor messages per tick")
    args = parser.parse_args()
    if not _only_loopback():
        sys.exit("bench.ros2: run it in a loopback-only namespace: `make bench-ros2`")
    with tempfile.TemporaryDirectory() as folder:
        r = measure(args.robot, args.ticks, args.rate, Path(folder))
    print(f"ROS 2 adapter, robot {args.robot}, sensors x{args.rate} a tick")
    print(f"  ticks                        {r['ticks']:>8.0f} in {r['seconds']:.1f} s")
    print(
        f"  sensor-to-command latency    p50 {r['p50_ms']:.2f} ms, p99 {r['p99_ms']:.2f} ms, "
        f"max {r['max_ms']:.2f} ms  (goal: p99 <= 10 ms)"
    )
    print(f"  dropped commands             {r['dropped']:>8.0f}  (goal: 0)")
    print(f"  ticks on stale odometry      {r['stale_odometry_ticks']:>8.0f}")
    print(
        f"  zero Twist after it went silent {r['stopped_after_ms']:>5.0f} ms  "
        f"(goal: <= one tick period + 100 ms = {r['stop_goal_ms']:.0f} ms)"
    )


if __name__ == "__main__":
    main()
