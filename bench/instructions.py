"""Fast mode's cost over the plain loop in instructions: a figure the machine's mood cannot move.

Run as ``.venv/bin/python -m bench.instructions`` (needs valgrind; about 5 minutes). On a
shared machine the same run goes at rates up to a third apart from one second to the next,
so `bench.engine`'s ratio of rates moves by a few hundredths between runs and cannot show a
change of a per cent or two. This counts instructions instead (valgrind's callgrind): the
plain headless loop (`core.run.runner.run`) and the engine in fast mode with its store on
SQLite in worker threads, with and without recording episodes' traces, each run for 1 and
for 1 + ``--episodes`` episodes of one seed; the difference is what those episodes cost,
start-up excluded. It prints the main thread's count (the ticks, and all the engine does
on its event loop) and every thread's (the storage threads too).

The plain loop's count repeats to a few instructions: hash randomisation is fixed
(``PYTHONHASHSEED=0``), address-space randomisation is off (``setarch -R``) and OpenBLAS
starts no spinning thread (``OPENBLAS_NUM_THREADS=1``). The engine's repeats to about half
a per cent: its writers gather what arrives within 50 ms of wall time, which callgrind
slows some 50 times, so it commits in more and smaller transactions than it does natively,
and by timing. The main thread's figure is the one that bounds the ticks' rate; the storage
threads' share of the other is larger here than in a native run.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import re
import shutil
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

VARIANTS = ("plain", "engine", "engine-untraced")
"""The plain loop; the engine with its store on SQLite in worker threads; the same, untraced."""
ROOT = Path(__file__).resolve().parents[1]
SUMMARY = re.compile(r"^summary: (\d+)$", re.MULTILINE)


def child(variant: str, condition: str, seed: int, episodes: int, folder: Path) -> int:
    """Run `variant` for `episodes` episodes in this process; its ticks."""
    from core.brain.catalog import load_catalog
    from core.engine import RunEngine
    from core.ports import Mode, RunSpec
    from core.run.conditions import get_condition
    from core.run.runner import run
    from server.persistence import SqlAlchemyRunStore, make_engine, make_sessionmaker, upgrade

    catalog = load_catalog()
    if variant == "plain":
        return run(get_condition(condition), seed, episodes, catalog=catalog).ticks
    url = f"sqlite:///{folder / 'instructions.db'}"
    upgrade(url)
    # Under callgrind a transaction runs some 50 times slower: a 5 s wait for the write
    # lock (the default) would fail the run.
    store = SqlAlchemyRunStore(make_sessionmaker(make_engine(url, busy_timeout_ms=600_000)))
    spec = RunSpec(condition, seed, episodes, Mode.FAST)
    engine = RunEngine.create(spec, store, catalog=catalog, trace=variant == "engine")
    asyncio.run(engine.run())
    return engine.totals.ticks


@dataclass(frozen=True, slots=True)
class Count:
    """What one callgrind run counted."""

    main: int
    """Instructions of the main thread: the plain loop, or the engine's event loop (ticks)."""
    all: int
    """Instructions of every thread (the engine's storage threads too)."""
    ticks: int


def count(variant: str, condition: str, seed: int, episodes: int) -> Count:
    """What callgrind counts of a child process running `variant`."""
    with tempfile.TemporaryDirectory() as tmp:
        env = {
            **os.environ,
            "PYTHONHASHSEED": "0",
            "OPENBLAS_NUM_THREADS": "1",
            "PYTHONPATH": str(ROOT),
        }
        # Without address-space randomisation, objects hashed by id() come in the same
        # order every run: the plain loop's count then repeats to a few instructions.
        fixed = ["setarch", os.uname().machine, "-R"] if shutil.which("setarch") else []
        argv = [
            *fixed,
            "valgrind",
            "--tool=callgrind",
            "--separate-threads=yes",
            f"--callgrind-out-file={tmp}/callgrind.out",
            sys.executable,
            "-m",
            "bench.instructions",
            "--child",
            variant,
            "--condition",
            condition,
            "--seed",
            str(seed),
            "--episodes",
            str(episodes),
            "--folder",
            tmp,
        ]
        done = subprocess.run(argv, env=env, capture_output=True, cwd=ROOT, check=False)
        threads = {
            f.name: sum(map(int, SUMMARY.findall(f.read_text(errors="replace"))))
            for f in Path(tmp).glob("callgrind.out-*")
        }
        if done.returncode != 0 or "callgrind.out-01" not in threads:
            said = done.stderr.decode(errors="replace")[-2000:]
            raise SystemExit(f"{variant} under callgrind failed ({done.returncode}):\n{said}")
        return Count(
            threads["callgrind.out-01"], sum(threads.values()), int(done.stdout.split()[-1])
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=40, help="episodes counted (default 40)")
    parser.add_argument("--condition", default="kp")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--jobs", type=int, default=2, help="callgrind runs at once")
    parser.add_argument("--child", choices=VARIANTS, help=argparse.SUPPRESS)
    parser.add_argument("--folder", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.episodes < 1:
        parser.error("--episodes must be at least 1")
    if args.child is not None:
        with tempfile.TemporaryDirectory() as tmp:
            folder = args.folder or Path(tmp)
            print(child(args.child, args.condition, args.seed, args.episodes, folder))
        return
    if shutil.which("valgrind") is None:
        print("bench.instructions: skipped, valgrind is not installed (Debian: valgrind)")
        return
    runs = [(v, n) for v in VARIANTS for n in (1, 1 + args.episodes)]
    print(
        f"instructions of {args.episodes} episodes of {args.condition}, seed {args.seed} "
        f"(runs of 1 and {1 + args.episodes} episodes under callgrind, {len(runs)} runs):",
        flush=True,
    )
    with ThreadPoolExecutor(max(1, args.jobs)) as pool:
        counted = dict(
            zip(
                runs,
                pool.map(lambda r: count(r[0], args.condition, args.seed, r[1]), runs),
                strict=True,
            )
        )
    if len({counted[r].ticks for r in runs}) != 2:
        raise SystemExit("the variants ran different ticks: they are not the same work")
    ticks = counted[("plain", 1 + args.episodes)].ticks - counted[("plain", 1)].ticks
    cost = {
        v: (
            counted[(v, 1 + args.episodes)].main - counted[(v, 1)].main,
            counted[(v, 1 + args.episodes)].all - counted[(v, 1)].all,
        )
        for v in VARIANTS
    }
    plain = cost["plain"][1]
    print(f"  {'':16} {'main thread':>22} {'all threads':>22}   plain / variant")
    for v, (main_thread, every) in cost.items():
        ratios = f"{plain / main_thread:.3f} / {plain / every:.3f}" if v != "plain" else ""
        print(
            f"  {v:16} {main_thread / 1e6:9,.1f} M ({main_thread / ticks:6,.0f}/tick) "
            f"{every / 1e6:9,.1f} M ({every / ticks:6,.0f}/tick)   {ratios}"
        )


if __name__ == "__main__":
    main()
