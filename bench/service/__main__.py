"""``python -m bench.service``: the command line, which runs the parts asked for."""

from __future__ import annotations

import argparse
import asyncio
import importlib.util
import shutil
import signal
import sys
import tempfile
import time
from collections.abc import Callable, Coroutine
from pathlib import Path
from typing import Any

import bench.service
from bench.service.compare import compare_engines, request_costs
from bench.service.day import day, one_run_part, store_episodes
from bench.service.harness import PLACEMENTS, Server, print_log
from bench.service.load import Mix
from bench.service.load_part import under_load


def loop_runner(choice: str) -> tuple[Callable[[Coroutine[Any, Any, None]], None], str]:
    """How to run the bench's coroutine: on uvloop when asked or available, else asyncio."""
    if choice == "asyncio" or (choice == "auto" and importlib.util.find_spec("uvloop") is None):
        return asyncio.run, "asyncio"
    import uvloop

    return uvloop.run, "uvloop"


def main() -> None:
    parser = argparse.ArgumentParser(
        prog="python -m bench.service", description=(bench.service.__doc__ or "").splitlines()[0]
    )
    parser.add_argument("--seconds", type=float, default=60.0, help="each realtime run (60)")
    parser.add_argument("--seconds-get", type=float, default=20.0, help="GET throughput (20)")
    parser.add_argument("--hz", type=float, default=20.0, help="realtime tick rate (20)")
    parser.add_argument("--rate", type=float, default=200.0, help="mixed load req/s (200)")
    parser.add_argument("--get-rate", type=float, default=1000.0, help="GET req/s (1000)")
    parser.add_argument("--connections", type=int, default=32, help="client pool (32)")
    parser.add_argument("--warmup", type=float, default=1.0, help="GET warm-up seconds (1)")
    parser.add_argument(
        "--warmup-run",
        type=float,
        default=2.0,
        help="seconds of a first, uncounted realtime run (2; 0: none)",
    )
    parser.add_argument(
        "--mix",
        type=Mix.parse,
        default=Mix(),
        metavar="READS,EDITS,REWARDS",
        help="shares of the mixed load (60,20,20)",
    )
    parser.add_argument("--timeout", type=float, default=10.0, help="per request (10 s)")
    parser.add_argument("--startup-timeout", type=float, default=60.0)
    parser.add_argument("--seed", type=int, default=0, help="of the traffic mix")
    parser.add_argument(
        "--client",
        choices=["raw", "httpx"],
        default="raw",
        help="raw asyncio streams (default) or httpx.AsyncClient",
    )
    parser.add_argument("--loop", choices=["auto", "asyncio", "uvloop"], default="auto")
    parser.add_argument("--no-wrk", action="store_true", help="skip the wrk measurement")
    parser.add_argument("--server-log", type=Path, help="keep the server's log here")
    parser.add_argument(
        "--part",
        choices=["all", "load", "day", "runs", "engines", "costs"],
        default="all",
        help="the load figures (1-2), the long day's (D1-D4), both (default), D4 alone, "
        "D3 and D4 with the engines on the service's loop and in their own process, or "
        "the server's CPU per request of each kind in D4's mix",
    )
    parser.add_argument("--rounds", type=int, default=2, help="--part engines' rounds (2)")
    parser.add_argument(
        "--env",
        action="append",
        default=[],
        metavar="SRLAB_NAME=VALUE",
        help="a setting for every server the bench starts (repeatable), e.g. "
        "SRLAB_STORE_PROCESS=false",
    )
    parser.add_argument(
        "--engines",
        choices=list(PLACEMENTS),
        default="process",
        help="where the servers tick their runs: the service's loop (SRLAB_ENGINES=local) "
        "or a process of their own (SRLAB_ENGINES=process, the default, as srlab serve); "
        "--part engines runs both",
    )
    parser.add_argument("--episodes", type=int, default=10_000, help="D2's stored episodes")
    parser.add_argument("--old-ticks", type=int, default=200_000, help="D1's old run's age")
    parser.add_argument("--samples", type=int, default=1000, help="GETs per D1/D2 figure")
    parser.add_argument("--streams", type=int, default=500, help="D3's stream clients")
    parser.add_argument("--stream-seconds", type=float, default=15.0, help="D3's length")
    parser.add_argument("--runs", type=int, default=32, help="D4's realtime runs")
    args = parser.parse_args()
    if min(args.seconds, args.seconds_get, args.hz, args.rate, args.get_rate) <= 0:
        parser.error("durations and rates must be positive")
    if args.connections < 1 or args.warmup < 0 or args.warmup_run < 0:
        parser.error("--connections must be at least 1, --warmup(-run) not negative")
    if args.episodes <= 50 or min(args.old_ticks, args.samples, args.streams, args.runs) < 1:
        parser.error("--episodes must be over 50; --old-ticks, --samples, --streams, --runs >= 1")
    if bad := [item for item in args.env if not item.startswith("SRLAB_") or "=" not in item]:
        parser.error(f"--env takes SRLAB_NAME=VALUE, not {bad[0]!r}")

    # SIGTERM ends the bench as Ctrl-C does: through the finally that stops the server.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(128 + signal.SIGTERM))
    with tempfile.TemporaryDirectory(prefix="srlab-bench-") as tmp:
        Server.placement = args.engines
        Server.extra = dict(item.split("=", 1) for item in args.env)
        server = Server(Path(tmp))
        started = time.perf_counter()
        try:
            runner, args.loop_name = loop_runner(args.loop)
            if args.part in ("all", "load"):
                server.start()
                runner(under_load(args, server))
            if args.part in ("all", "day"):
                if server.proc is not None:
                    server.stop()
                    print_log(server.log)
                    server = Server(Path(tmp) / "day")
                server.folder.mkdir(exist_ok=True)
                server.env["SRLAB_MAX_RUNS"] = str(args.runs + 4)
                episodes_run = store_episodes(server.url, args.episodes)
                server.start()
                runner(day(args, server, episodes_run))
            if args.part == "engines":
                runner(compare_engines(args, Path(tmp) / "engines"))
            if args.part == "runs":
                server.env["SRLAB_MAX_RUNS"] = str(args.runs + 4)
                server.start()
                runner(one_run_part(args, server))
            if args.part == "costs":
                server.start()
                runner(request_costs(args, server))
        finally:
            code = server.stop()
            if server.proc is not None:
                print(
                    f"srlab serve stopped (SIGINT), exit code {code}; "
                    f"bench took {time.perf_counter() - started:.0f} s"
                )
                print_log(server.log)
                if args.server_log is not None:
                    shutil.copyfile(server.log, args.server_log)
                    print(f"server log kept in {args.server_log}")


if __name__ == "__main__":
    try:
        main()
    except KeyboardInterrupt:
        sys.exit("bench.service: interrupted")
