"""Process-wide settings for a process that runs engines."""

from __future__ import annotations

import asyncio
import contextlib
import ctypes
import functools
import gc
import os
import platform
import sys
from pathlib import Path

SWITCH_INTERVAL_S = 0.0005
"""How long a thread may hold the GIL while another waits for it."""

SHORT_SLICE_NS = 100_000
"""The scheduler slice srlab's threads ask Linux for: 0.1 ms, the shortest it grants."""

_SCHED_SETATTR = {"x86_64": 314, "aarch64": 274, "arm64": 274, "riscv64": 274}
"""`sched_setattr`'s system call number by machine (`sched_getattr` is the next one)."""
_SCHED_OTHER = 0


class _SchedAttr(ctypes.Structure):
    """Linux's `struct sched_attr` up to `sched_period` (its first version, 48 bytes)."""

    _fields_ = [
        ("size", ctypes.c_uint32),
        ("sched_policy", ctypes.c_uint32),
        ("sched_flags", ctypes.c_uint64),
        ("sched_nice", ctypes.c_int32),
        ("sched_priority", ctypes.c_uint32),
        ("sched_runtime", ctypes.c_uint64),
        ("sched_deadline", ctypes.c_uint64),
        ("sched_period", ctypes.c_uint64),
    ]


def configure_process() -> None:
    """Tune the interpreter for an event loop beside storage threads.

    The engine commits through worker threads. With CPython's default switch interval
    (5 ms) a worker that finished its I/O waits up to 5 ms for the tick loop to hand over
    the GIL, and a busy worker can delay a realtime tick as long; a short interval keeps
    both under a millisecond (bench/engine.py measures the effect). Every thread asks
    Linux for short scheduler slices (`ask_short_slices`), so the ticks and the storage
    threads wake on time beside busy processes.
    """
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    ask_short_slices()


@functools.cache
def _libc() -> ctypes.CDLL:
    return ctypes.CDLL(None, use_errno=True)


def _sched_attr(tid: int) -> _SchedAttr | None:
    """Thread `tid`'s scheduling attributes (0: the calling thread); None where unknown."""
    number = _SCHED_SETATTR.get(platform.machine())
    if number is None or not sys.platform.startswith("linux"):
        return None
    attr = _SchedAttr()
    if _libc().syscall(number + 1, tid, ctypes.byref(attr), ctypes.sizeof(attr), 0) != 0:
        return None
    return attr


def slice_ns(tid: int = 0) -> int | None:
    """Thread `tid`'s scheduler slice in ns, as Linux reports it; None where it does not.

    0: the calling thread. Linux 6.12 and later report the default slice unless a thread
    asked for another; older kernels report 0.
    """
    attr = _sched_attr(tid)
    return None if attr is None else int(attr.sched_runtime)


def _ask_slice(tid: int, ns: int) -> bool:
    attr = _sched_attr(tid)
    if attr is None or attr.sched_policy != _SCHED_OTHER:
        return False  # not Linux, or a policy someone chose (batch, idle, realtime): kept
    attr.size = ctypes.sizeof(attr)
    attr.sched_flags = 0
    attr.sched_runtime = ns  # the nice value read above is written back as is
    number = _SCHED_SETATTR[platform.machine()]
    if _libc().syscall(number, tid, ctypes.byref(attr), 0) != 0:
        return False
    return ns == 0 or slice_ns(tid) == ns  # older kernels take the call and ignore it


def ask_short_slices(ns: int = SHORT_SLICE_NS) -> bool:
    """Ask Linux to run every thread of this process in short slices (`SHORT_SLICE_NS`).

    A realtime run wakes a few times per tick: the tick task at its deadline, a storage
    thread for each write, the event loop again when the write is done. Beside busy
    processes (an experiment on every core) a thread that wakes after a millisecond of
    work is often not let in before the busy process's slice ends, up to a scheduler tick
    later (4 ms at the usual 250 Hz): beside two busy processes 27 % of such wake-ups were
    more than 1 ms late on this machine, 0.6 % with a 0.1 ms slice (`bench.slices`;
    docs/benchmarks.md). Linux's
    EEVDF scheduler (6.12 and later) lets a thread ask for a shorter slice without
    privileges: it gets no larger share of the CPU, only its turns sooner and shorter.

    Threads and processes started later inherit the slice. Where the kernel has no such
    request (older Linux, other systems), or a thread runs under a policy someone chose,
    nothing changes. Returns whether every thread now asks for it. `ns` 0 asks for the
    kernel's default slice again.
    """
    asked = [_ask_slice(tid, ns) for tid in threads("self") or [0]]
    return all(asked)


def freeze_heap() -> None:
    """Leave what the process built to start out of every later garbage collection.

    Modules, classes, the catalogue, the app and its routes live as long as the process,
    yet each of CPython's full collections scans them all again: 80-110 ms in the service
    (about 170,000 objects), 10-70 ms in the engines' process, and
    the event loop, with every run it ticks, stands still meanwhile (a 20 Hz run's period
    is 50 ms). `gc.freeze` moves every object alive now to a generation no collection
    scans, so a later one looks only at what came after. Called once a process is set up:
    the service and the engines' process at their warm-up (`warm_up`), `srlab run`. What
    it freezes is never freed, so the garbage goes first.
    """
    gc.collect()
    gc.freeze()


def threads(pid: int | str) -> list[int]:
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
    """Lower this process's CPU priority by `increment` (nice).

    For a service whose runs tick in the engines' process (`service_nice`): called once
    that process runs, so it keeps the default priority, and on a busy machine the ticks
    get a core before requests do. Linux gives each thread its own nice value, so every
    thread of this process is lowered (threads made later inherit it from the thread that
    makes them); elsewhere the process is. Raising a priority needs privileges, so this
    cannot be undone in the process.
    """
    if increment <= 0:
        return
    for tid in threads("self") or [0]:
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
