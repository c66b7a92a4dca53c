"""Realtime tick lateness of `srlab serve` with a 3D view watching, against none.

Run as ``.venv/bin/python -m bench.viewer`` (``make bench``; about 7 minutes, ``--seconds
10 --rounds 1`` for a quick check). It starts ``srlab serve`` itself on 127.0.0.1 (free
ports, a temporary SQLite database) and Debian's Chromium twice (Playwright, the flags of
bench/browser.py), then measures in one run, ``--rounds`` times in turn:

* **none**: a realtime ``kp`` run at ``--hz`` (20) for ``--seconds`` (40), no browser on
  the 3D view's port;
* **viewer**: the same with a real Chromium page (``--width`` x ``--height``, 1280x800)
  on the 3D view following that run live; the server is pinned to CPU 0 and this Chromium
  to CPU 1 at niceness ``--nice`` (19);
* **viewer, small page**: the same with a 64x64 page: the same messages to receive and
  apply, next to nothing to render - what the service itself pays, apart from the
  browser's rendering;
* **viewer, shared cores**: the same with Chromium at the server's priority on any core.

With ``--console`` it measures the trainer console instead, ``--rounds``
times in turn: **none** as above, and **console 2D**: the same run with the console page
(``/#/console/<run>``, which shows the 2D view) open in Chromium on CPU 1 at ``--nice``,
following the run's event stream. Besides the lateness it prints what the page measured
itself (``window.srlabView2d``): tick events received, frames drawn, each frame's draw
time and the delay from a tick's arrival to the end of its frame (p50, p99, max). The goal:
the console's lateness p99 within 0.5 ms of none's, and the page drawing every tick.

The page is loaded and idle before its run starts, so a figure is the steady state of
watching, not the page's start-up. For each run: tick lateness p99 and max and overruns,
from the engine's own live figures (GET /api/runs/{id}), the ticks the page showed, and
the CPU shares of the server, Chromium and the rest of the machine. The goal: the viewer's
lateness p99 within 1 ms of none's.

Why the pinning: Chromium has no GPU here, it renders WebGL with SwiftShader, and viser's
page redraws continuously, so an idle page alone takes about a core at 1280x800 - a load
a browser on the user's own machine puts on that machine, not on the service's. Starting
Chromium under ``taskset`` and ``nice`` does not keep it there: SwiftShader pins its
rendering workers to cores 0 and 1 itself and Chromium sets its threads' priorities
itself, so while a pinned phase runs, every Chromium thread is put back on CPU 1 at
``--nice`` every half second (the bench prints how many it moved). Sharing the two cores,
the browser's rendering competes with the server at the same priority; the last phase
shows that cost. ``--no-pin`` leaves every process on any core.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import re
import signal
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bench.browser import CHROMIUM, FLAGS  # the flags DEVELOPERS.md prescribes
from bench.figures import live_ms, ms, percentile
from bench.liveserver import free_port
from bench.pinning import browser_root, chromium_command, chromium_cpu_s, confined, pin_process
from bench.procs import cpu_seconds, descendants, machine_busy_s
from bench.service import HOST, RawClient, Server, call, stop_run, wait_healthy

TICK = re.compile(r"Episode (\d+), tick (\d+)")


@dataclass
class Phase:
    """One measured run."""

    name: str
    run_id: int
    ticks: int
    p99_s: float | None
    max_s: float | None
    overruns: int
    shown: tuple[int, int] | None
    """The first and last tick the page showed (viewer phases)."""
    cpu: str
    load: float
    page: dict[str, Any] | None = None
    """What the console page measured itself (console phases)."""


class Meter:
    """CPU shares of the server, Chromium and the rest, from now on."""

    def __init__(self, server_pid: int) -> None:
        self.pid = server_pid
        self.t0 = time.perf_counter()
        self.server0 = cpu_seconds(server_pid) or 0.0
        self.chrome0 = chromium_cpu_s(server_pid)
        self.machine0 = machine_busy_s() or 0.0
        self.me0 = time.process_time()

    def report(self) -> str:
        """Each one's share of one core since the start."""
        wall = time.perf_counter() - self.t0
        server = (cpu_seconds(self.pid) or 0.0) - self.server0
        chrome = chromium_cpu_s(self.pid) - self.chrome0
        me = time.process_time() - self.me0
        rest = max(0.0, (machine_busy_s() or 0.0) - self.machine0 - server - chrome - me)
        return (
            f"server {server / wall:4.0%}, chromium {chrome / wall:4.0%}, "
            f"rest {rest / wall:4.0%} of one core"
        )


async def page_tick(page: Any) -> tuple[int, int] | None:
    """(episode, tick) the page's panel shows now."""
    text = await page.inner_text("body")
    m = TICK.search(text)
    return (int(m[1]), int(m[2])) if m else None


async def canvas_tick(page: Any) -> int | None:
    """The tick the console's 2D view drew last."""
    tick = await page.get_attribute("#view2d", "data-tick")
    return int(tick) if tick else None


async def measure(
    client: RawClient,
    server: Server,
    page: Any | None,
    args: argparse.Namespace,
    name: str,
    console_url: str | None = None,
) -> Phase:
    run = await call(
        client,
        "POST",
        "/api/runs",
        {"condition": "kp", "mode": "realtime", "hz": args.hz, "seed": args.seed},
    )
    run_id = int(run["id"])
    if page is not None and console_url is not None:
        # The console opens on the created run and follows it once it starts.
        await page.goto(f"{console_url}/#/console/{run_id}")
        await page.wait_for_selector("body[data-ready=true]", timeout=60_000)
        if name == "console, no 2D":
            await page.evaluate("() => document.querySelector('#view2d-card').remove()")
        await asyncio.sleep(3.0)  # the page settles before the run
    meter = Meter(server.pid)
    await call(client, "POST", f"/api/runs/{run_id}/start")
    first = None
    if page is not None and console_url is not None and name == "console, no 2D":
        await page.wait_for_function(
            "() => /^[0-9]+$/.test(document.querySelector('#st-tick').textContent)",
            timeout=30_000,
        )
    elif page is not None and console_url is not None:
        await page.wait_for_selector("#view2d[data-tick]", timeout=30_000)
        await page.evaluate("() => Object.assign(window.srlabView2d, {ticks: 0, draws: 0, "
                            "drawMs: [], delayMs: []})")  # fmt: skip
        tick = await canvas_tick(page)
        first = (0, tick) if tick is not None else None
    elif page is not None:
        await page.get_by_text(f"Run {run_id}").first.wait_for(timeout=30_000)
        first = await page_tick(page)
    await asyncio.sleep(args.seconds)
    state = await call(client, "GET", f"/api/runs/{run_id}")
    measured: dict[str, Any] | None = None
    if page is not None and console_url is not None and name == "console, no 2D":
        last = None
    elif page is not None and console_url is not None:
        tick = await canvas_tick(page)
        last = (0, tick) if tick is not None else None
        measured = await page.evaluate("() => window.srlabView2d")
    else:
        last = await page_tick(page) if page is not None else None
    cpu = meter.report()
    await stop_run(client, run_id)
    live = state.get("live") or {}
    shown = (first[1], last[1]) if first and last else None
    return Phase(
        name,
        run_id,
        int(live.get("ticks_run", 0)),
        live_ms(live, "lateness_p99_ms"),
        live_ms(live, "lateness_max_ms"),
        int(live.get("overruns", 0)),
        shown,
        cpu,
        os.getloadavg()[0],
        measured,
    )


def spread(values: list[float]) -> str:
    """p50, p99 and max of page timings in ms."""
    if not values:
        return "-"
    return f"{statistics.median(values):.2f} / {percentile(values, 99):.2f} / {max(values):.2f}"


async def warm_up(client: RawClient) -> None:
    """Print the load, then run a realtime kp run for 2 s and stop it.

    The service's first run pays for what is loaded and compiled once; no measured run
    should.
    """
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    warm = await call(client, "POST", "/api/runs", {"condition": "kp", "mode": "realtime"})
    await call(client, "POST", f"/api/runs/{warm['id']}/start")
    await asyncio.sleep(2.0)
    await stop_run(client, int(warm["id"]))


async def launch_pinned(pw: Any, server: Server, args: argparse.Namespace) -> tuple[Any, int, bool]:
    """Chromium at `--nice`: the browser, its root process and whether it is pinned.

    Pinned (`--pin`, on two cores or more): the server on CPU 0 and Chromium on CPU 1.
    """
    pinned = bool(args.pin and (os.cpu_count() or 1) >= 2)
    if pinned:
        pin_process(server.pid, 0)
    before = descendants(os.getpid())
    browser = await pw.chromium.launch(
        executable_path=str(chromium_command(server.folder, args.nice, 1 if pinned else None)),
        args=FLAGS,
        headless=True,
    )
    return browser, browser_root(before, descendants(os.getpid())), pinned


async def end_phase(keeper: asyncio.Task[None] | None, page: Any | None) -> None:
    """Stop keeping Chromium's threads confined, and close the phase's page."""
    if keeper is not None:
        keeper.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await keeper
    if page is not None:
        await page.close()


PHASES = ("none", "viewer", "viewer, small page", "viewer, shared cores")
SMALL = (64, 64)
"""The small page's viewport: the same messages to handle, next to nothing to render."""


CONSOLE_PHASES = ("none", "console, no 2D", "console 2D")
"""'console, no 2D' is the console page with the 2D view's card taken out before the run:
what the rest of the console costs the service (its stream, its polls and reads)."""


async def bench_console(args: argparse.Namespace, server: Server) -> None:
    """None against the console with its 2D view open, side by side, `--rounds` times."""
    from playwright.async_api import async_playwright

    client = RawClient(server.port, 4, 30.0)
    try:
        await wait_healthy(client, server, 60.0)
        url = f"http://{HOST}:{server.port}"
        print(f"srlab serve on {HOST}:{server.port}, pid {server.pid}")
        await warm_up(client)
        phases: list[Phase] = []
        async with async_playwright() as pw:
            browser, root, pinned = await launch_pinned(pw, server, args)
            try:
                for r in range(args.rounds):
                    for name in CONSOLE_PHASES:
                        page = None
                        keeper: asyncio.Task[None] | None = None
                        moved: list[int] = []
                        if name != "none":
                            if pinned:
                                keeper = asyncio.create_task(
                                    confined(root, 1, args.nice, 0.5, moved)
                                )
                            page = await browser.new_page(
                                viewport={"width": args.width, "height": args.height}
                            )
                        phase = await measure(client, server, page, args, name, url)
                        await end_phase(keeper, page)
                        phases.append(phase)
                        print(
                            f"round {r + 1} {name:14} run {phase.run_id:3}: ticks {phase.ticks:5}"
                            f", lateness p99 {ms(phase.p99_s, 5)}, max {ms(phase.max_s, 5)}, "
                            f"overruns {phase.overruns}"
                        )
                        print(f"    CPU: {phase.cpu}; load average {phase.load:.2f}")
                        if phase.page is not None:
                            m = phase.page
                            print(
                                f"    page: {m['ticks']} tick events, {m['draws']} frames drawn;"
                                f" draw ms p50/p99/max {spread(m['drawMs'])}; tick-to-frame"
                                f" ms p50/p99/max {spread(m['delayMs'])}"
                            )
                        await asyncio.sleep(1.0)
            finally:
                await browser.close()
        report_console(phases, args)
    finally:
        await client.aclose()


def report_console(phases: list[Phase], args: argparse.Namespace) -> None:
    """The table: each phase's lateness p99 (median of rounds), and the page's timings."""

    def of(name: str) -> list[Phase]:
        return [p for p in phases if p.name == name and p.p99_s is not None]

    none, console, bare = of("none"), of("console 2D"), of("console, no 2D")
    print()
    print(
        f"realtime kp runs at {args.hz:g} Hz, {args.seconds:g} s each, {args.rounds} rounds; "
        f"the console at {args.width}x{args.height}"
        + (f", server on CPU 0, Chromium on CPU 1 at niceness {args.nice}" if args.pin else "")
    )
    if not none or not console:
        print("no figures")
        return
    a = statistics.median(p.p99_s for p in none if p.p99_s is not None)
    b = statistics.median(p.p99_s for p in console if p.p99_s is not None)
    draws = [x for p in console if p.page for x in p.page["drawMs"]]
    delays = [x for p in console if p.page for x in p.page["delayMs"]]
    got = sum(p.page["ticks"] for p in console if p.page)
    drawn = sum(p.page["draws"] for p in console if p.page)
    print("| phase | lateness p99 ms | max ms | overruns |")
    print("|---|---|---|---|")
    for p in phases:
        print(f"| {p.name} (run {p.run_id}) | {ms(p.p99_s)} | {ms(p.max_s)} | {p.overruns} |")
    verdict = "within" if b - a <= 0.0005 else "NOT within"
    print(
        f"median p99: none {ms(a)}, console 2D {ms(b)}, difference {ms(b - a, 5)} "
        f"({verdict} 0.5 ms)"
    )
    if bare:
        c = statistics.median(p.p99_s for p in bare if p.p99_s is not None)
        print(
            f"median p99: console without the 2D view {ms(c)}: the 2D view's own share "
            f"{ms(b - c, 5)}, the rest of the console's {ms(c - a, 5)}"
        )
    print(
        f"page: {got} tick events, {drawn} frames; draw ms p50/p99/max {spread(draws)}; "
        f"tick-to-frame ms p50/p99/max {spread(delays)}"
    )
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


async def bench(args: argparse.Namespace, server: Server) -> None:
    from playwright.async_api import async_playwright

    client = RawClient(server.port, 4, 30.0)
    try:
        health = await wait_healthy(client, server, 60.0)
        port = health["viser_port"]
        if port is None:
            raise RuntimeError("the service runs without its 3D view (SRLAB_VISER=false?)")
        print(f"srlab serve on {HOST}:{server.port}, 3D view on port {port}, pid {server.pid}")
        await warm_up(client)
        phases: list[Phase] = []
        async with async_playwright() as pw:
            pinned_browser, root, pinned = await launch_pinned(pw, server, args)
            browsers = {"viewer": pinned_browser}
            browsers["viewer, shared cores"] = await pw.chromium.launch(
                executable_path=str(chromium_command(server.folder, 0, None)),
                args=FLAGS,
                headless=True,
            )
            try:
                for r in range(args.rounds):
                    for name in PHASES:
                        page = None
                        keeper: asyncio.Task[None] | None = None
                        moved: list[int] = []
                        if pinned and name in ("viewer", "viewer, small page"):
                            keeper = asyncio.create_task(confined(root, 1, args.nice, 0.5, moved))
                        if name != "none":
                            width, height = (
                                SMALL if name.endswith("small page") else (args.width, args.height)
                            )
                            key = "viewer, shared cores" if "shared" in name else "viewer"
                            page = await browsers[key].new_page(
                                viewport={"width": width, "height": height}
                            )
                            await page.goto(f"http://{HOST}:{port}/")
                            await page.get_by_text("srlab 3D view").wait_for(timeout=60_000)
                            await asyncio.sleep(3.0)  # the page settles before the run
                        phase = await measure(client, server, page, args, name)
                        await end_phase(keeper, page)
                        phases.append(phase)
                        shown = (
                            f", the page showed ticks {phase.shown[0]}..{phase.shown[1]}"
                            if phase.shown
                            else ""
                        )
                        print(
                            f"round {r + 1} {name:21} run {phase.run_id:3}: ticks {phase.ticks:5}"
                            f", lateness p99 {ms(phase.p99_s, 5)}, max {ms(phase.max_s, 5)}, "
                            f"overruns {phase.overruns}{shown}"
                        )
                        print(f"    CPU: {phase.cpu}; load average {phase.load:.2f}")
                        if moved:
                            print(
                                f"    Chromium threads put back on CPU 1 at niceness {args.nice}:"
                                f" {sum(moved[:1])} at the page's start, {sum(moved[1:])} later"
                            )
                        await asyncio.sleep(1.0)
            finally:
                for b in browsers.values():
                    await b.close()
        report(phases, args)
    finally:
        await client.aclose()


def report(phases: list[Phase], args: argparse.Namespace) -> None:
    """The medians over rounds of each phase's lateness p99, against none's."""

    def p99s(name: str) -> list[float]:
        return [p.p99_s for p in phases if p.name == name and p.p99_s is not None]

    print()
    print(
        f"realtime kp runs at {args.hz:g} Hz, {args.seconds:g} s each, {args.rounds} rounds; "
        f"Chromium {args.width}x{args.height}; "
        + (
            f"the server on CPU 0, 'viewer' runs Chromium on CPU 1 at niceness {args.nice}"
            if args.pin
            else f"'viewer' runs Chromium at niceness {args.nice}"
        )
    )
    base = p99s("none")
    if not base:
        print("no figures")
        return
    a = statistics.median(base)
    print(f"  {'none':23} lateness p99 {ms(a)} (median of rounds)")
    for name in PHASES[1:]:
        values = p99s(name)
        if not values:
            continue
        b = statistics.median(values)
        diff = b - a
        verdict = "within" if diff <= 0.001 else "NOT within"
        pairs = ", ".join(ms(v - n, 5).strip() for n, v in zip(base, values, strict=False))
        print(
            f"  {name:23} lateness p99 {ms(b)}, difference {ms(diff, 5)} ({verdict} 1 ms); "
            f"per round {pairs}"
        )
    if any(p.name != "none" and not p.shown for p in phases):
        print("  WARNING: a viewer phase's page showed no ticks")
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=40.0, help="each phase (40)")
    parser.add_argument("--rounds", type=int, default=2, help="none/viewer pairs (2)")
    parser.add_argument("--hz", type=float, default=20.0, help="realtime tick rate (20)")
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--width", type=int, default=1280, help="page width (1280)")
    parser.add_argument("--height", type=int, default=800, help="page height (800)")
    parser.add_argument(
        "--no-pin",
        dest="pin",
        action="store_false",
        help="do not pin the server to CPU 0 and the 'viewer' phase's Chromium to CPU 1",
    )
    parser.add_argument(
        "--nice",
        type=int,
        default=19,
        help="niceness of the 'viewer' phase's Chromium (19); 'viewer, shared cores' runs it "
        "at 0 on any core",
    )
    parser.add_argument(
        "--console",
        action="store_true",
        help="measure the trainer console with its 2D view instead of the 3D view",
    )
    args = parser.parse_args()
    if args.seconds <= 0 or args.rounds < 1 or not 0 < args.hz <= 1000:
        parser.error("--seconds must be positive, --rounds at least 1, --hz in (0, 1000]")
    if not CHROMIUM.exists():
        sys.exit(f"bench.viewer: {CHROMIUM} is missing: apt-get install chromium")
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(128 + signal.SIGTERM))
    with tempfile.TemporaryDirectory(prefix="srlab-bench-viewer-") as tmp:
        server = Server(Path(tmp), env={"SRLAB_VISER_PORT": str(free_port())})
        started = time.perf_counter()
        try:
            server.start()
            asyncio.run(bench_console(args, server) if args.console else bench(args, server))
        finally:
            code = server.stop()
            print(
                f"srlab serve stopped, exit code {code}; took {time.perf_counter() - started:.0f} s"
            )


if __name__ == "__main__":
    try:
        main()
    except KeyboardInterrupt:
        sys.exit("bench.viewer: interrupted")
