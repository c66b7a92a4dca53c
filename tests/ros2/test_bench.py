"""bench/ros2.py runs end to end on a few ticks and prints its figures (not judged here)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import ros2_or_skip  # noqa: F401  # before rclpy: skips the module without it

ROOT = Path(__file__).resolve().parents[2]


def test_the_bench_prints_latency_and_dropped_commands() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "bench.ros2", "--ticks", "40"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        check=True,
    )
    assert "ticks                              40 in" in done.stdout
    assert "sensor-to-command latency    p50 " in done.stdout
    assert "dropped commands" in done.stdout
    assert "zero Twist after it went silent" in done.stdout
