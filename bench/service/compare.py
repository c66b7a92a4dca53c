"""``--part engines`` (D3 and D4 per placement of the engines) and ``--part costs``."""

from __future__ import annotations

import argparse
import statistics
import time
from collections import Counter
from pathlib import Path

from bench.procs import tree_cpu_seconds
from bench.service.clients import RawClient
from bench.service.day import event_streams, many_runs
from bench.service.harness import (
    CONTROL_TIMEOUT_S,
    PLACEMENTS,
    Server,
    edit_target,
    placement_env,
    placement_name,
    recover,
    start_run,
    stop_run,
    wait_healthy,
)
from bench.service.load import mixed


async def compare_engines(args: argparse.Namespace, folder: Path) -> None:
    """D3 and D4 with the engines in each of `PLACEMENTS`, alternated.

    Each round starts a fresh `srlab serve` per placement (`placement_env`), so all of
    them see the same machine within minutes of each other.
    """
    rows: dict[str, list[dict[str, float]]] = {p: [] for p in PLACEMENTS}
    for k in range(args.rounds):
        for placement in PLACEMENTS:
            server = Server(folder / f"{placement}-{k}")
            server.folder.mkdir(parents=True)
            server.env["SRLAB_MAX_RUNS"] = str(args.runs + 4)
            server.env.update(placement_env(placement))
            server.start()
            try:
                print(f"\n== round {k + 1}, engines on {placement_name(placement)} ==")
                control = RawClient(server.port, 2, CONTROL_TIMEOUT_S)
                await wait_healthy(control, server, args.startup_timeout)
                d3 = await event_streams(args, server, control)
                await recover(control, 30)
                await control.aclose()
                d4 = await many_runs(args, server)
                rows[placement].append({**{f"d3_{key}": v for key, v in d3.items()}, **d4})
            finally:
                server.stop()
    print(f"\nD3 and D4 side by side, {args.rounds} round(s), medians over rounds:")
    print(f"  {'':44}" + "".join(f"{placement_name(p):>22}" for p in PLACEMENTS))
    for key, label in (
        ("d3_overruns", "D3 overruns (goal 0)"),
        ("d3_max_ms", "D3 lateness max, ms"),
        ("p99_worst_ms", "D4 lateness p99 worst run, ms (goal 5)"),
        ("p99_median_ms", "D4 lateness p99 median run, ms"),
        ("max_ms", "D4 lateness max worst run, ms (goal 25)"),
        ("overruns", "D4 overruns, all runs (goal 0)"),
        ("request_p99_ms", "D4 requests p99, ms"),
        ("errors", "D4 request errors"),
    ):
        cells = [statistics.median(r[key] for r in rows[p]) for p in PLACEMENTS]
        print(f"  {label:<44}" + "".join(f"{c:>22.2f}" for c in cells))


async def request_costs(args: argparse.Namespace, server: Server) -> None:
    """``--part costs``: the server's CPU per request of each kind in D4's mix.

    Sent one at a time on one connection, ``--samples`` of each kind after 20 uncounted,
    to a realtime run at ``--hz``; the server's CPU counts the processes it started. Then
    what ``--rate`` requests/s of the mix would cost it, in cores: above what the machine
    has left beside the ticks, D4's load cannot be served on time.
    """
    control = RawClient(server.port, 1, CONTROL_TIMEOUT_S)
    await wait_healthy(control, server, args.startup_timeout)
    run_id = await start_run(control, args.hz)
    edits, why = await edit_target(control, args.seed)
    if edits is None:
        print(f"costs: no edits ({why})")
    plan = mixed(run_id, edits, args.mix, args.seed)
    drawn = [plan(i) for i in range(20_000)]
    share = {k: n / len(drawn) for k, n in Counter(r.kind for r in drawn).items()}
    cores = 0.0
    print(f"server CPU per request, one at a time, {args.samples} of each kind:")
    for kind in sorted(share):
        requests = [r for r in drawn if r.kind == kind][: args.samples + 20]
        warm, counted = requests[:20], requests[20:]
        for r in warm:
            await control.request(r.method, r.path, r.body)
        before, started = tree_cpu_seconds(server.pid), time.perf_counter()
        statuses = Counter([(await control.request(r.method, r.path, r.body))[0] for r in counted])
        after, wall = tree_cpu_seconds(server.pid), time.perf_counter() - started
        if before is None or after is None:
            raise SystemExit("costs: the server's CPU time cannot be read (/proc)")
        cpu_ms = (after - before) / len(counted) * 1000
        cores += args.rate * share[kind] * cpu_ms / 1000
        print(
            f"  {kind:28} {cpu_ms:6.2f} ms CPU, {wall / len(counted) * 1000:6.2f} ms "
            f"wall; {share[kind]:4.0%} of the mix; statuses {dict(sorted(statuses.items()))}"
        )
    print(f"the mix at {args.rate:g} requests/s: {cores:.2f} cores of the server's CPU")
    await stop_run(control, run_id)
