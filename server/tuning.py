"""Process-wide settings for a process that runs engines."""

from __future__ import annotations

import sys

SWITCH_INTERVAL_S = 0.0005
"""How long a thread may hold the GIL while another waits for it."""


def configure_process() -> None:
    """Tune the interpreter for an event loop beside storage threads.

    The engine commits through worker threads. With CPython's default switch interval
    (5 ms) a worker that finished its I/O waits up to 5 ms for the tick loop to hand over
    the GIL, and a busy worker can delay a realtime tick as long; a short interval keeps
    both under a millisecond (bench/engine.py measures the effect).
    """
    sys.setswitchinterval(SWITCH_INTERVAL_S)
