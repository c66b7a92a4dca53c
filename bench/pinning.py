"""Chromium kept off the server's core: pinned to a CPU at a niceness, and its CPU time."""

from __future__ import annotations

import asyncio
import contextlib
import os
from pathlib import Path

from bench.browser import CHROMIUM
from bench.procs import cpu_seconds, descendants, parent_of


def chromium_cpu_s(server_pid: int) -> float:
    """CPU seconds of this bench's Chromium processes so far."""
    total = 0.0
    for pid in descendants(os.getpid()) - descendants(server_pid) - {server_pid}:
        try:
            comm = Path(f"/proc/{pid}/comm").read_text().strip()
        except OSError:
            continue
        if comm.startswith("chrom") or comm.startswith("headless"):
            total += cpu_seconds(pid) or 0.0
    return total


def chromium_command(folder: Path, nice: int, cpu: int | None) -> Path:
    """A wrapper that starts Chromium `nice`d and pinned to `cpu` (its children inherit)."""
    wrapper = folder / f"chromium-{nice}-{cpu}"
    pin = f"taskset -c {cpu} " if cpu is not None else ""
    wrapper.write_text(f'#!/bin/sh\nexec {pin}nice -n {nice} "{CHROMIUM}" "$@"\n')
    wrapper.chmod(0o755)
    return wrapper


def pin_process(pid: int, cpu: int) -> None:
    """Pin every thread of a process to one CPU (threads it starts later inherit it)."""
    for task in Path(f"/proc/{pid}/task").iterdir():
        with contextlib.suppress(OSError):
            os.sched_setaffinity(int(task.name), {cpu})


def confine(root: int, cpu: int, nice: int) -> int:
    """Put every thread of `root` and its descendants on `cpu` at niceness `nice`.

    Starting Chromium under ``taskset`` and ``nice`` is not enough: SwiftShader pins its
    rendering workers (``Thread<00>``, ``Thread<01>`` in the GPU process) to cores 0 and
    1 itself, and Chromium sets its threads' priorities itself (to -8 for its compositor
    and IO threads when it may). Those workers then render on the server's core at the
    server's priority. Returns how many threads were found off `cpu` or at another
    niceness (and were moved).
    """
    moved = 0
    for pid in {root} | descendants(root):
        with contextlib.suppress(OSError):
            for task in Path(f"/proc/{pid}/task").iterdir():
                tid = int(task.name)
                with contextlib.suppress(OSError):
                    changed = False
                    if os.sched_getaffinity(tid) != {cpu}:
                        os.sched_setaffinity(tid, {cpu})
                        changed = True
                    if os.getpriority(os.PRIO_PROCESS, tid) != nice:
                        os.setpriority(os.PRIO_PROCESS, tid, nice)
                        changed = True
                    moved += changed
    return moved


async def confined(root: int, cpu: int, nice: int, every_s: float, counts: list[int]) -> None:
    """`confine` now and every `every_s` (threads Chromium starts later escape too)."""
    while True:
        counts.append(confine(root, cpu, nice))
        await asyncio.sleep(every_s)


def browser_root(before: set[int], after: set[int]) -> int:
    """The browser process a launch started: the new process whose parent is not new."""
    new = after - before
    for pid in sorted(new):
        ppid = parent_of(pid)
        if ppid is not None and ppid not in new:
            return pid
    raise RuntimeError("could not find the Chromium that was just started")
