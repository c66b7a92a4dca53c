"""Busy processes beside a benchmark: a machine with more runnable work than cores.

``with busy(2): ...`` starts two processes that spin on a core each until the block ends:
what a user's machine looks like with an experiment on every core, and what a slow day's
scheduling delays look like on this one. The benchmarks' ``--busy N`` options use it, so a
figure "beside two busy processes" is one command anyone can rerun.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager

from server.tuning import ask_short_slices


@contextmanager
def busy(count: int) -> Iterator[None]:
    """`count` processes spinning while the block runs, as other people's processes would.

    They run at the default priority and the kernel's default slice, whatever the
    benchmark asked for itself (children inherit a slice: `server.tuning`).
    """
    spinners = [
        subprocess.Popen(
            [sys.executable, "-c", "while True: pass"],
            preexec_fn=lambda: ask_short_slices(0),  # one thread, so safe after fork
        )
        for _ in range(count)
    ]
    try:
        yield
    finally:
        for p in spinners:
            p.kill()
        for p in spinners:
            p.wait()
