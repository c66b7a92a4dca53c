"""The benchmarks run and print what docs/benchmarks.md quotes (at tiny sizes).

A bench nobody runs rots; these check that each still runs end to end and reports its
figures, not the figures themselves (they depend on the machine).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def bench(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,  # a hang guard, not a speed test
        check=False,
    )


def test_the_store_bench_compares_the_driver_with_sessions() -> None:
    done = bench("bench.store", "--repeats", "5", "--idle", "1")
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    for what in ("back to back", "after 1 ms idle"):
        for write in ("log a reward", "commit it"):
            [line] = [x for x in lines if what in x and write in x]
            assert "driver" in line and "sessions" in line and "ratio" in line
    assert sum("applied rewards" in x for x in lines) == 2


def test_the_engine_bench_reports_fast_mode_and_realtime_with_its_floor() -> None:
    done = bench(
        "bench.engine",
        *("--seconds", "1", "--repeats", "2", "--episodes", "2", "--stores", "threads,sessions"),
        "--untraced",
    )
    assert done.returncode == 0, done.stderr
    out = done.stdout
    ratios = ("ratio, threads", "ratio, sessions", "ratio, threads, no trace")
    for line in (*ratios, "reward commit p99"):
        assert line in out
    assert out.count("empty thread hand-off p99") == 2  # one per store


def test_the_engine_bench_refuses_an_unknown_store_without_a_traceback() -> None:
    done = bench("bench.engine", "--stores", "threads,elsewhere")
    assert done.returncode == 2
    assert "--stores: unknown elsewhere" in done.stderr
    assert "Traceback" not in done.stderr


def test_the_service_bench_prices_each_request_kind() -> None:
    done = bench("bench.service", "--part", "costs", "--samples", "3")
    assert done.returncode == 0, done.stderr[-3000:]
    out = done.stdout
    for kind in ("GET /api/runs/{id}", "POST /api/runs/{id}/rewards", "PUT association"):
        assert kind in out
    assert "the mix at 200 requests/s" in out
    assert "5xx responses                       0" in out


def test_the_instruction_bench_runs_the_same_work_in_each_variant() -> None:
    # What each callgrind run executes (the counting itself needs valgrind and minutes).
    ticks = set()
    for variant in ("plain", "engine", "engine-untraced"):
        done = bench("bench.instructions", "--child", variant, "--episodes", "2", "--seed", "3")
        assert done.returncode == 0, done.stderr
        ticks.add(int(done.stdout.split()[-1]))
    assert len(ticks) == 1 and ticks.pop() > 0


def test_the_instruction_bench_refuses_no_episodes_without_a_traceback() -> None:
    done = bench("bench.instructions", "--episodes", "0")
    assert done.returncode == 2
    assert "--episodes must be at least 1" in done.stderr
    assert "Traceback" not in done.stderr
