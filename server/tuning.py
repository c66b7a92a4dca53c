"""Process-wide settings for a process that runs engines."""

from __future__ import annotations

import asyncio
import contextlib
import gc
import multiprocessing
import os
import sys
from pathlib import Path

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


def freeze_heap() -> None:
    """Leave what the process built to start out of every later garbage collection.

    Modules, classes, the catalogue, the app and its routes live as long as the process,
    yet each of CPython's full collections scans them all again: 80-110 ms in the service
    (about 170,000 objects), 10-70 ms in the engines' and the store's processes, and
    the event loop, with every run it ticks, stands still meanwhile (a 20 Hz run's period
    is 50 ms). `gc.freeze` moves every object alive now to a generation no collection
    scans, so a later one looks only at what came after. Called once a process is set up:
    the service and the engines' process at their warm-up (`warm_up`),
    the store process, `srlab run`. What it freezes is never freed, so the garbage goes
    first.
    """
    gc.collect()
    gc.freeze()


def _threads(pid: int | str) -> list[int]:
    """The thread ids of process `pid` (Linux); [] where /proc does not tell."""
    try:
        return [int(tid) for tid in os.listdir(Path("/proc") / str(pid) / "task")]
    except OSError:
        return []


def _lower(who: int, increment: int) -> None:
    with contextlib.suppress(OSError):  # gone meanwhile, or not ours to change
        now = os.getpriority(os.PRIO_PROCESS, who)
        os.setpriority(os.PRIO_PROCESS, who, min(19, now + increment))


def step_back(increment: int) -> None:
    """Lower this process's CPU priority by `increment` (nice), and its store process's.

    For a service whose runs tick in the engines' process (`service_nice`): called once
    that process runs, so it and the store process it starts keep the default priority,
    and on a busy machine the ticks get a core before requests do. Linux gives each
    thread its own nice value, so every thread of this process is lowered (threads made
    later inherit it from the thread that makes them); elsewhere the process is. Children
    started by `multiprocessing` (the service's store process) are lowered too. Raising
    a priority needs privileges, so this cannot be undone in the process.
    """
    if increment <= 0:
        return
    for tid in _threads("self") or [0]:
        _lower(tid, increment)
    for child in multiprocessing.active_children():
        if child.pid is not None:
            for tid in _threads(child.pid) or [child.pid]:
                _lower(tid, increment)


async def warm_up(kernel: bool = True) -> None:
    """Load the sensing kernel's machine code now (`kernel`), not in the first run's tick.

    Then keep everything loaded so far (it lives as long as the process) out of the cyclic
    collector's way (`freeze_heap`), so a full collection does not stall realtime ticks.
    A process whose runs tick elsewhere (the service beside an engines' process) skips
    the kernel: it never simulates, and numba stays unloaded there.
    """
    if kernel:
        from core.sim.world import PymunkWorld

        await asyncio.to_thread(lambda: PymunkWorld().reset(0, 0))
    freeze_heap()
