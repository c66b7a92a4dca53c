"""Busy processes beside a benchmark: a machine with more runnable work than cores.

``with busy(2): ...`` starts two processes that spin on a core each until the block ends:
what a user's machine looks like with an experiment on every core, and what a slow day's
scheduling delays look like on this one. The benchmarks' ``--busy N`` options use it, so a
figure "beside two busy processes" is one command anyone can rerun.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

SPIN = "from server.runtime.tuning import ask_short_slices\nask_short_slices(0)\nwhile True: pass"
"""A spinner's code: the kernel's default slice (not an inherited one), then work."""


@contextmanager
def busy(count: int) -> Iterator[None]:
    """`count` processes spinning while the block runs, as other people's processes would.

    They run at the default priority and the kernel's default slice, whatever the
    benchmark asked for itself (children inherit a slice: `server.runtime.tuning`).
    """
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)
    env = {**os.environ, "PYTHONPATH": path}  # `server` importable from any directory
    spinners = [subprocess.Popen([sys.executable, "-c", SPIN], env=env) for _ in range(count)]
    try:
        yield
    finally:
        for p in spinners:
            p.kill()
        for p in spinners:
            p.wait()
