"""The fake AmigoBot (fake_amigobot.py) as a subprocess of a test."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

FAKE = Path(__file__).resolve().parent / "fake_amigobot.py"
ROOT = FAKE.parents[2]


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


@contextmanager
def fake_amigobot(*args: str) -> Iterator[FakeRobot]:
    """`with fake_amigobot("--rate", "10") as robot:` runs the fake AmigoBot meanwhile."""
    robot = FakeRobot(args)
    try:
        yield robot
    finally:
        robot.stop()
