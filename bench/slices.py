"""Wake-ups on time beside busy processes: the kernel's default slice against a short one.

Run as ``.venv/bin/python -m bench.slices`` (``--busy 2`` by default). A realtime run's
threads wake a few times per tick (the tick task at its deadline, a storage thread for a
write, the event loop when the write is done) after a little work each. This measures
exactly that, side by side in one run: a thread that works ``--work-ms`` (1 ms, about a
tick's work), then sleeps ``--sleep-ms`` (10 ms), and how late each wake-up is, in
processes alternating between Linux's default slice and the short one srlab's processes
ask for (`server.runtime.tuning.ask_short_slices`), beside ``--busy`` spinning processes.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time

from bench.busy import busy
from bench.figures import percentile
from server.runtime.tuning import SHORT_SLICE_NS, ask_short_slices, slice_ns

LATE_S = 0.001
"""A wake-up this late counts as late."""


def wake_ups(short: bool, count: int, work_s: float, sleep_s: float) -> list[float]:
    """How late each of `count` wake-ups was, in seconds (in this process)."""
    if not ask_short_slices(SHORT_SLICE_NS if short else 0):
        raise SystemExit("this kernel takes no slice requests (Linux 6.12 or later does)")
    late = []
    for _ in range(count):
        started = time.perf_counter()
        time.sleep(sleep_s)
        late.append(time.perf_counter() - started - sleep_s)
        until = time.perf_counter() + work_s
        while time.perf_counter() < until:
            pass
    return late


def _measured(short: bool, count: int, work_s: float, sleep_s: float) -> list[float]:
    """`wake_ups` in a fresh process."""
    argv = [sys.executable, "-m", "bench.slices", "--child", "short" if short else "default"]
    argv += ["--count", str(count), "--work-ms", str(work_s * 1000)]
    argv += ["--sleep-ms", str(sleep_s * 1000)]
    done = subprocess.run(argv, capture_output=True, text=True, check=True)
    result: list[float] = json.loads(done.stdout)
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--busy", type=int, default=2, help="spinning processes beside")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--count", type=int, default=1000, help="wake-ups per round")
    parser.add_argument("--work-ms", type=float, default=1.0)
    parser.add_argument("--sleep-ms", type=float, default=10.0)
    parser.add_argument("--child", choices=("default", "short"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    work_s, sleep_s = args.work_ms / 1000, args.sleep_ms / 1000
    if args.child:
        print(json.dumps(wake_ups(args.child == "short", args.count, work_s, sleep_s)))
        return
    if not slice_ns():
        print("bench.slices: skipped, the kernel takes no slice requests (Linux 6.12+ does)")
        return
    late: dict[bool, list[float]] = {False: [], True: []}
    with busy(args.busy):
        time.sleep(0.5)  # the spinners running
        for _ in range(args.rounds):
            for short in (False, True):
                late[short] += _measured(short, args.count, work_s, sleep_s)
    print(
        f"wake-ups after {args.work_ms:g} ms of work and {args.sleep_ms:g} ms of sleep, "
        f"beside {args.busy} busy processes, {args.rounds} x {args.count} each:"
    )
    for short in (False, True):
        samples = late[short]
        share = sum(s > LATE_S for s in samples) / len(samples)
        name = f"short slice ({SHORT_SLICE_NS / 1e6:g} ms)" if short else "default slice"
        p50, p99 = percentile(samples, 50) * 1e3, percentile(samples, 99) * 1e3
        print(
            f"  {name:24} late > 1 ms {share:6.1%}   p50 {p50:5.2f} ms   "
            f"p99 {p99:5.2f} ms   max {max(samples) * 1e3:5.2f} ms"
        )


if __name__ == "__main__":
    main()
