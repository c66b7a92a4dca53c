"""The `srlab` command line."""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections.abc import Callable, Sequence
from contextlib import nullcontext
from pathlib import Path
from typing import IO, Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from core.brain.catalog import Catalog, sensor_definitions
from core.brain.selection import Strategy
from core.conditions import CONDITIONS, get_condition
from core.errors import CoreError
from core.events import Outcome
from core.runner import EpisodeSummary, RunSummary
from core.runner import run as run_headless
from core.setup import default_sensors
from core.simulation import Snapshot
from core.worlds import default_world, world_names
from server.backends import BackendError
from server.cli.common import print_table
from server.cli.sweep import (
    add_backend_arguments,
    add_setup_arguments,
    add_sweep_parser,
    add_task_arguments,
    command_line,
    on_result_updater,
    open_backend,
    progress_display,
    setup_of,
    sweep_command,
)
from server.reports.base import setup_params


def _number(
    cast: Callable[[str], float], low: float, high: float, closed_low: bool, what: str
) -> Callable[[str], Any]:
    """An argparse type: a number of `cast`'s kind within bounds, with a clear message."""
    kind = "whole number" if cast is int else "number"

    def parse(text: str) -> Any:
        try:
            value = cast(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a {kind}") from None
        if value > high or value < low or (value == low and not closed_low):
            raise argparse.ArgumentTypeError(f"must be {what}, got {value}")
        return value

    return parse


ENGINE_CONDITIONS = sorted(n for n, c in CONDITIONS.items() if c.agent == "brain")
"""The conditions `srlab run` and `srlab simulate` accept: the paper's architecture."""
OTHER_CONDITIONS = sorted(set(CONDITIONS) - set(ENGINE_CONDITIONS))
"""The baselines (Q(lambda), DQN, PPO...): `srlab experiment` runs them."""


def _engine_condition(text: str) -> str:
    """An argparse type: a condition of the paper's architecture, else where to run it."""
    if text in ENGINE_CONDITIONS:
        return text
    if text in OTHER_CONDITIONS:
        raise argparse.ArgumentTypeError(
            f"{text!r} is a baseline, not run by the engine (the paper's architecture): "
            "run it with "
            f"`srlab experiment --conditions {text}`"
        )
    raise argparse.ArgumentTypeError(
        f"invalid choice: {text!r} (choose from {', '.join(ENGINE_CONDITIONS)})"
    )


_CONDITION_METAVAR = "{" + ",".join(ENGINE_CONDITIONS) + "}"
_positive_int = _number(int, 1, math.inf, True, "at least 1")
_seed = _number(int, 0, math.inf, True, "0 or more")
_unit = _number(float, 0.0, 1.0, True, "in [0, 1]")
_rate = _number(float, 0.0, 1000.0, False, "in (0, 1000]")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every `srlab` command."""
    parser = argparse.ArgumentParser(
        prog="srlab",
        description="A behaviour-based control and learning architecture with knowledge "
        "propagation (Suh et al.), on a simulated AmigoBot.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    sim = sub.add_parser(
        "simulate",
        help="run a condition headless for some episodes and summarise the outcomes",
        description="Run a condition headless and summarise successes and failures.",
    )
    sim.add_argument(
        "--condition",
        required=True,
        type=_engine_condition,
        metavar=_CONDITION_METAVAR,
        help="which knowledge and learning the robot has (the baselines, "
        f"{', '.join(OTHER_CONDITIONS)}, run in srlab experiment)",
    )
    sim.add_argument("--episodes", type=_positive_int, default=50, help="episodes (default 50)")
    sim.add_argument("--seed", type=_seed, default=0, help="random seed (default 0)")
    sim.add_argument(
        "--strategy",
        choices=[s.value for s in Strategy],
        default=None,
        help="behaviour selection strategy (default: the condition's, competition)",
    )
    sim.add_argument("--json", action="store_true", help="print one JSON object, nothing else")
    sim.add_argument(
        "--trace",
        type=Path,
        metavar="FILE",
        help="write every tick (pose, stimuli, behaviour) as JSON lines to FILE",
    )
    sim.add_argument("--quiet", action="store_true", help="no progress bar (it goes to stderr)")
    add_setup_arguments(sim)

    exp = sub.add_parser(
        "experiment",
        help="run conditions x seeds x episodes in parallel and write a report",
        description="Run the paper's comparison: every condition for every seed, in "
        "parallel processes, then write summary.json, summary.md, runs.jsonl, "
        "learning_curves.png and reliability.png to --out.",
    )
    exp.add_argument(
        "--conditions",
        default="innate,delayed,dp,rp,kp,qlambda",
        help=f"comma-separated, from: {', '.join(CONDITIONS)} (default: the paper's four, "
        "innate and qlambda)",
    )
    add_task_arguments(exp, _positive_int, _seed, Path("results"))
    exp.add_argument(
        "--eval-episodes",
        type=_number(int, 0, math.inf, True, "0 or more"),
        default=0,
        metavar="N",
        help="after training, N episodes of frozen evaluation on held-out seeds, and N of "
        "the camera-only transfer test (default 0: none)",
    )
    exp.add_argument(
        "--untuned",
        action="store_true",
        help="run every condition with its default parameters, not the tuned ones "
        "(core/data/tuned.toml, written by srlab tune)",
    )
    exp.add_argument(
        "--no-probe",
        action="store_true",
        help="do not judge what was learned with the placement probe (srlab probe)",
    )
    add_sweep_parser(sub, _positive_int, _seed)

    tn = sub.add_parser(
        "tune",
        help="tune every learner with the same budget on seeds the experiments never use",
        description="Run each learning condition's 27-point grid (core/tune.py) on the "
        "tuning seeds, print every point best first, and with --write keep each learner's "
        "best in core/data/tuned.toml, which srlab experiment then runs with.",
    )
    tn.add_argument(
        "--conditions",
        default="delayed,dp,rp,kp,sonar,qlambda,qlambda-hybrid",
        help="comma-separated learners (default: every one with a grid)",
    )
    tn.add_argument("--seeds", type=_positive_int, default=5, help="tuning seeds (default 5)")
    tn.add_argument(
        "--seed-base", type=_seed, default=1000, help="first tuning seed (default 1000)"
    )
    tn.add_argument(
        "--episodes", type=_positive_int, default=50, help="episodes per seed (default 50)"
    )
    tn.add_argument("--jobs", type=_positive_int, default=os.cpu_count() or 1)
    add_backend_arguments(tn)
    add_setup_arguments(tn)
    tn.add_argument("--write", action="store_true", help="write core/data/tuned.toml")
    tn.add_argument("--out", type=Path, help="also write tuning.md and tuning.json here")
    tn.add_argument("--quiet", action="store_true", help="no progress display")

    pr = sub.add_parser(
        "probe",
        help="which responses to each camera obstacle stimulus are correct, from the world",
        description="Place robot and obstacle in K placements inside each camera obstacle "
        "stimulus's definition and run each behaviour as its response: a response is "
        "correct when it gets the robot past the obstacle in at least 75%% of them. "
        "Results are cached per world, sensor definition and settings (SRLAB_CACHE_DIR).",
    )
    add_setup_arguments(pr, signal=False)
    pr.add_argument(
        "--placements", type=_positive_int, default=20, help="placements per stimulus (20)"
    )
    pr.add_argument("--seed", type=_seed, default=0, help="seed of the placements (default 0)")
    pr.add_argument("--json", action="store_true", help="print one JSON object")

    check = sub.add_parser(
        "world-check",
        help="does a world preset pose the paper's problem? (properties of the world alone)",
        description="With the signal's responses given and no learning anywhere: (a) no "
        "obstacle knowledge succeeds <= 20%%, (b) the sonar reflexes alone 40-80%%, (c) the "
        "expert's camera responses >= 95%%; and (d) innate knowledge alone <= 10%% (Table "
        "II). Prints each with its 95%% bootstrap interval over seeds.",
    )
    check.add_argument(
        "--world",
        action="append",
        metavar="NAME",
        help="a world preset; repeat for several (default: every preset)",
    )
    check.add_argument(
        "--sensors",
        default="",
        help="sensor definition for (c) (default: the default one; 'all' for each)",
    )
    check.add_argument("--seeds", type=_positive_int, default=20, help="seeds (default 20)")
    check.add_argument("--seed-base", type=_seed, default=0, help="first seed (default 0)")
    check.add_argument(
        "--episodes", type=_positive_int, default=50, help="episodes per seed (default 50)"
    )
    check.add_argument("--jobs", type=_positive_int, default=os.cpu_count() or 1)
    add_backend_arguments(check)
    check.add_argument("--json", action="store_true", help="print one JSON object")
    check.add_argument(
        "--out", type=Path, help="also write world-check.json and world-check.md to this folder"
    )
    check.add_argument("--quiet", action="store_true", help="no progress display")

    sweep = sub.add_parser(
        "qlambda-sweep",
        help="tune Q(lambda)'s hyper-parameters on seeds the experiments do not use",
        description="Grid over alpha x lambda x epsilon; prints mean success over the last "
        "episodes per setting, best first.",
    )
    sweep.add_argument("--seeds", type=_positive_int, default=5)
    sweep.add_argument("--seed-base", type=_seed, default=1000)
    sweep.add_argument("--episodes", type=_positive_int, default=300)
    sweep.add_argument("--alphas", default="0.1,0.3,0.5")
    sweep.add_argument("--lambdas", default="0.5,0.9")
    sweep.add_argument("--epsilons", default="0.05,0.1,0.2")
    sweep.add_argument("--jobs", type=_positive_int, default=os.cpu_count() or 1)
    sweep.add_argument("--json", action="store_true", help="print one JSON object")

    db = sub.add_parser("db", help="the database: migrate and seed it")
    db_sub = db.add_subparsers(dest="db_command", required=True, metavar="ACTION")
    up = db_sub.add_parser(
        "upgrade",
        help="create or migrate the database to the newest schema and seed the catalogue",
        description="Create or migrate the database (SRLAB_DATABASE_URL, default "
        "sqlite:///var/srlab.db) to the newest schema, then seed stimuli, behaviours, "
        "logical sensors and the innate, dp, kp and expert networks.",
    )
    up.add_argument("--url", help="SQLAlchemy URL (default: SRLAB_DATABASE_URL)")
    down = db_sub.add_parser("downgrade", help="migrate the database down to a revision")
    down.add_argument("revision", help="an Alembic revision, or 'base' to empty it")
    down.add_argument("--url", help="SQLAlchemy URL (default: SRLAB_DATABASE_URL)")

    runp = sub.add_parser(
        "run",
        help="run a condition on the engine, stored in the database",
        description="Run a condition on the asyncio engine (a tick task and a reward "
        "task), storing its LTM, RLTM, network, episodes and rewards. Ctrl-C or SIGTERM "
        "stops it cleanly (status interrupted); --resume continues it.",
    )
    runp.add_argument(
        "--condition",
        type=_engine_condition,
        metavar=_CONDITION_METAVAR,
        help="which condition (the engine runs the paper's architecture; the baselines, "
        f"{', '.join(OTHER_CONDITIONS)}, run in srlab experiment)",
    )
    runp.add_argument("--seed", type=_seed, default=0, help="random seed (default 0)")
    runp.add_argument(
        "--episodes", type=_positive_int, help="episodes to run (default: until stopped)"
    )
    runp.add_argument("--mode", choices=["fast", "realtime"], default="fast")
    runp.add_argument("--hz", type=_rate, default=10.0, help="realtime tick rate (default 10)")
    runp.add_argument("--network", help="start from this knowledge set instead")
    runp.add_argument(
        "--world", choices=world_names(), help=f"world preset (default {default_world()})"
    )
    runp.add_argument(
        "--sensors",
        choices=list(sensor_definitions()),
        help=f"sensor definition (default {default_sensors()})",
    )
    runp.add_argument("--eta", type=_unit, help="Eq. (1)'s learning rate")
    runp.add_argument("--epsilon", type=_unit, help="exploration rate")
    runp.add_argument("--resume", type=_positive_int, metavar="RUN", help="resume a stored run")
    runp.add_argument("--url", help="SQLAlchemy URL (default: SRLAB_DATABASE_URL)")
    runp.add_argument("--quiet", action="store_true", help="no progress display")

    serve = sub.add_parser(
        "serve",
        help="serve the HTTP API and the editor (migrates the database first)",
        description="Serve the HTTP API, the S-R editor and trainer console with uvicorn "
        "(one worker). Settings come from SRLAB_* environment variables; beyond loopback "
        "SRLAB_TOKEN is required.",
    )
    serve.add_argument("--host", help="address to bind (default SRLAB_HOST or 127.0.0.1)")
    serve.add_argument("--port", type=int, help="port (default SRLAB_PORT or 8000)")

    runs = sub.add_parser("runs", help="list the stored runs")
    runs.add_argument("--json", action="store_true", help="print one JSON object")
    runs.add_argument("--url", help="SQLAlchemy URL (default: SRLAB_DATABASE_URL)")
    return parser


class _TraceWriter:
    """Writes one JSON line per tick with names instead of ids."""

    def __init__(self, out: IO[str], catalog: Catalog) -> None:
        self._out = out
        self._stimuli = [s.name for s in catalog.stimuli]
        self._behaviours = [b.name for b in catalog.behaviours]

    def __call__(self, s: Snapshot) -> None:
        row: dict[str, Any] = {
            "episode": s.episode,
            "tick": s.tick,
            "episode_tick": s.episode_tick,
            "x": round(s.x, 4),
            "y": round(s.y, 4),
            "heading_rad": round(s.heading_rad, 4),
            "stimuli": [self._stimuli[i] for i in s.stimuli],
            "behaviour": self._behaviours[s.behaviour] if s.behaviour >= 0 else None,
            "how": s.how.value,
            "released_by": self._stimuli[s.released_by] if s.released_by >= 0 else None,
            "source": s.origin,
            "lamp": s.lamp.name.lower(),
            "progress_m": round(s.progress_m, 3),
        }
        if s.outcome is not None:
            row["outcome"] = s.outcome.value
            row["cause"] = s.cause.value if s.cause else None
        self._out.write(json.dumps(row) + "\n")


def summary_dict(result: RunSummary) -> dict[str, Any]:
    """The `--json` form of a run's summary."""
    return {
        "condition": result.condition,
        "seed": result.seed,
        "episodes": len(result.episodes),
        "successes": result.successes,
        "success_rate": result.success_rate,
        "failures": result.failures(),
        "ticks": result.ticks,
        "ticks_by_source": dict(
            sorted(result.ticks_by_origin.items(), key=lambda kv: (-kv[1], kv[0]))
        ),
    }


def _simulate(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    setup = setup_of(args)
    condition = setup.condition(get_condition(args.condition))
    if condition.agent != "brain":
        raise ValueError(
            f"condition {condition.name!r} is not the paper's architecture: run it with "
            "`srlab experiment --conditions " + condition.name + "`"
        )
    catalog = setup.catalog()
    brain_config = None
    if args.strategy is not None:
        from dataclasses import replace

        base = condition.brain_config()
        brain_config = replace(
            base, selection=replace(base.selection, strategy=Strategy(args.strategy))
        )
    err_console = Console(file=stderr, stderr=True)
    progress = Progress(
        TextColumn(f"[bold]{condition.name}[/] seed {args.seed}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[ok]} ok"),
        TimeElapsedColumn(),
        console=err_console,
        transient=True,
        disable=args.quiet,
    )
    task = progress.add_task("episodes", total=args.episodes, ok=0)
    successes = 0

    def on_episode(e: EpisodeSummary) -> None:
        nonlocal successes
        successes += e.outcome is Outcome.SUCCESS
        progress.update(task, advance=1, ok=successes)

    trace_file = None
    try:
        if args.trace is not None:
            trace_file = args.trace.open("w", encoding="utf-8")
        started = time.perf_counter()
        with progress:
            result = run_headless(
                condition,
                args.seed,
                args.episodes,
                world_config=setup.world_config(),
                catalog=catalog,
                brain_config=brain_config,
                on_episode=on_episode,
                on_tick=_TraceWriter(trace_file, catalog) if trace_file else None,
            )
        elapsed = time.perf_counter() - started
    finally:
        if trace_file is not None:
            trace_file.close()

    if args.json:
        stdout.write(json.dumps({**summary_dict(result), **setup_params(setup)}) + "\n")
        return 0
    title = (
        f"srlab simulate: {condition.name}, seed {args.seed}, world {setup.world_name}, "
        f"sensors {setup.sensors_name}, signal {setup.signal}"
    )
    table = Table(title=title, show_header=False)
    table.add_column("what")
    table.add_column("value", justify="right")
    table.add_row("episodes", str(len(result.episodes)))
    table.add_row("successes", str(result.successes))
    table.add_row("success rate", f"{result.success_rate:.1%}")
    for cause, count in result.failures().items():
        table.add_row(f"  {cause.replace('_', ' ')}", str(count))
    table.add_row("ticks", f"{result.ticks:,}")
    for origin, n in sorted(result.ticks_by_origin.items(), key=lambda kv: -kv[1]):
        table.add_row(f"  run by {origin}", f"{n:,} ({n / max(result.ticks, 1):.1%})")
    table.add_row("ticks/s", f"{result.ticks / elapsed:,.0f}" if elapsed > 0 else "-")
    console = print_table(stdout, table)
    if args.trace is not None:
        console.print(f"trace written to {args.trace}")
    return 0


def _experiment(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    from core.experiment import CAMERA_SENSOR, parse_conditions, run_experiment, summarise
    from core.params import tuned_params
    from core.stats import Estimate, pct
    from server.reports.experiment import write_report

    conditions = parse_conditions(args.conditions)
    seeds = list(range(args.seed_base, args.seed_base + args.seeds))
    setup = setup_of(args)
    catalog = setup.catalog()
    err = Console(file=stderr, stderr=True)
    with open_backend(args, err) as (backend, where):
        total = len(conditions) * len(seeds)
        progress, bar = progress_display(err, "experiment", total, args.quiet)
        started = time.perf_counter()
        with progress:
            results = run_experiment(
                conditions,
                seeds,
                args.episodes,
                args.jobs,
                on_result_updater(progress, bar),
                backend,
                setup,
                args.eval_episodes,
                tuned=not args.untuned,
            )
        elapsed = time.perf_counter() - started
    probed = None
    if not args.no_probe:
        from server.probe_cache import cached_probe

        with (
            err.status("judging what was learned (srlab probe)")
            if not args.quiet
            else nullcontext()
        ):
            probed, _ = cached_probe(setup)
    camera = [s.name for s in catalog.stimuli_of_sensor(CAMERA_SENSOR)]
    summary = summarise(results, conditions, probed.correct() if probed else None, camera)
    params = {
        "command": command_line(args),
        "conditions": conditions,
        "seeds": len(seeds),
        "seed_base": args.seed_base,
        "episodes": args.episodes,
        **setup_params(setup),
        "jobs": args.jobs,
        "backend": args.backend,
        "address": args.address,
        "where": where,
        "elapsed_s": elapsed,
        "ticks": sum(r.ticks for r in results),
        "eval_episodes": args.eval_episodes,
        "tuned": {
            c: dict(tuned_params(c)) for c in conditions if not args.untuned and tuned_params(c)
        },
        "probe": probed.as_dict() if probed is not None else None,
    }
    paths = write_report(args.out, results, summary, catalog, params)
    table = Table(
        title=f"srlab experiment: {len(seeds)} seeds x {args.episodes} episodes, world "
        f"{setup.world_name}, sensors {setup.sensors_name}, signal {setup.signal}"
    )
    held_out = args.eval_episodes > 0
    cols = ["condition", "success [95% CI]", "episodes 1-10"]
    cols += ["held-out", "camera only"] if held_out else []
    cols += ["collisions/ep", "viol./ep"]
    for col in cols:
        table.add_column(col, justify="right" if col != "condition" else "left")
    for name, s in summary.items():
        if not s.get("seeds"):
            table.add_row(name, "failed", *([""] * (len(cols) - 2)))
            continue
        first10 = s["success_horizons"].get("1-10")
        row = [
            name,
            pct(Estimate.of(s["success_rate"])),
            "" if first10 is None else pct(Estimate.of(first10)),
        ]
        if held_out:
            ev = s.get("evaluation", {})
            row += [pct(Estimate.of(ev[k])) for k in ("frozen", "camera_only")] if ev else ["", ""]
        row += [
            f"{s['collisions_per_episode']['mean']:.2f}",
            f"{s['violations_per_episode']['mean']:.2f}",
        ]
        table.add_row(*row)
    console = print_table(stdout, table)
    ticks = params["ticks"]
    console.print(f"{ticks:,} ticks in {elapsed:.1f} s on {where} ({ticks / elapsed:,.0f} ticks/s)")
    for p in paths:
        console.print(f"wrote {p}")
    failed = [r for r in results if not r.ok]
    for r in failed:
        first = (r.error or "").splitlines()[0]
        err.print(f"[red]task {r.task.condition} seed {r.task.seed} failed:[/] {first}")
    return 1 if failed else 0


def _tune(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    from core.brain.catalog import data_dir
    from core.experiment import parse_conditions
    from core.tune import GRIDS, TUNING_SEED_BASE, describe, plan, tune, tuned_toml

    conditions = parse_conditions(args.conditions)
    if args.seed_base < TUNING_SEED_BASE:
        raise ValueError(
            f"--seed-base {args.seed_base}: tuning seeds start at {TUNING_SEED_BASE}, so the "
            "experiments' seeds are never tuned on"
        )
    seeds = list(range(args.seed_base, args.seed_base + args.seeds))
    setup = setup_of(args)
    total = sum(len(s.tasks()) for s in plan(conditions, seeds, args.episodes, setup).values())
    err = Console(file=stderr, stderr=True)
    started = time.perf_counter()
    with open_backend(args, err) as (backend, where):
        progress, bar = progress_display(err, "tune", total, args.quiet)
        with progress:
            rows = tune(
                conditions, seeds, args.episodes, setup, backend, on_result_updater(progress, bar)
            )
    elapsed = time.perf_counter() - started
    command = command_line(args)
    for c, points in rows.items():
        names = [n for n, _ in GRIDS[c]]
        table = Table(title=f"{c}: {len(points)} points, {len(seeds)} seeds x {args.episodes} "
                      f"episodes, best first")  # fmt: skip
        for n in (*names, "success"):
            table.add_column(n, justify="right")
        for p in points[:5]:
            table.add_row(*(f"{p.point[n]:g}" for n in names), f"{p.success:.1%}")
        print_table(stdout, table)
    best = {c: points[0] for c, points in rows.items()}
    out = stdout
    out.write(f"{total} tasks in {elapsed:.1f} s on {where}\n")
    for c, p in best.items():
        out.write(f"best for {c}: {describe(p.point)} ({p.success:.1%})\n")
    if args.write:
        path = data_dir() / "tuned.toml"
        previous = path.read_text() if path.is_file() else ""
        path.write_text(tuned_toml(best, command, setup, previous))
        out.write(f"wrote {path}\n")
    if args.out is not None:
        from server.reports.tuning import write_tuning

        write_tuning(args.out, rows, command=command, seeds=seeds, episodes=args.episodes,
                     elapsed_s=elapsed, setup=setup)  # fmt: skip
        out.write(f"wrote {args.out / 'tuning.md'} and tuning.json\n")
    return 0


def _probe(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    from server.probe_cache import cached_probe

    setup = setup_of(args)
    err = Console(file=stderr, stderr=True)
    with err.status(f"probing {setup.world_name} ({setup.sensors_name})"):
        result, cached = cached_probe(setup, args.placements, args.seed)
    if args.json:
        stdout.write(json.dumps(result.as_dict()) + "\n")
        return 0
    table = Table(
        title=f"srlab probe: world {result.world}, sensors {result.sensors}, "
        f"{result.k} placements a stimulus{' (cached)' if cached else ''}"
    )
    for col in ("stimulus", "correct responses (share of placements passed)", "best"):
        table.add_column(col)
    for name, p in result.stimuli.items():
        good = sorted(p.correct, key=lambda b: -p.passed[b])
        cells = ", ".join(f"{b} {p.passed[b]:.0%}" for b in good) or "[red]none[/]"
        best, share = p.best
        table.add_row(name, cells, f"{best} {share:.0%}")
    print_table(stdout, table)
    return 0


def _world_check(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    from core.brain.catalog import sensor_definitions
    from core.stats import pct
    from core.worldcheck import PROPERTIES, world_check
    from core.worlds import load_world, world_names

    worlds = list(dict.fromkeys(args.world or world_names()))
    for w in worlds:
        load_world(w)  # an unknown name is an error naming the known ones
    definitions = list(sensor_definitions())
    if args.sensors == "all":
        sensors = definitions
    elif args.sensors and args.sensors not in definitions:
        raise ValueError(
            f"unknown sensor definition {args.sensors!r} (known: {', '.join(definitions)}, all)"
        )
    else:
        sensors = [args.sensors or definitions[0]]
    seeds = list(range(args.seed_base, args.seed_base + args.seeds))
    err = Console(file=stderr, stderr=True)
    report: dict[str, Any] = {"seeds": len(seeds), "seed_base": args.seed_base,
                              "episodes": args.episodes, "checks": []}  # fmt: skip
    console = Console(file=stdout)
    all_hold = True
    with open_backend(args, err) as (backend, where):
        for w in worlds:
            for d in sensors:
                total = len(PROPERTIES) * len(seeds)
                progress, bar = progress_display(err, f"world-check {w} ({d})", total, args.quiet)
                with progress:
                    results = world_check(
                        w, d, seeds, args.episodes, backend, on_result_updater(progress, bar)
                    )
                preset = load_world(w)
                holds = all(r.holds for r in results)
                all_hold &= holds
                report["checks"].append({
                    "world": w, "sensors": d, "holds": holds, "reasons": preset.reasons,
                    "properties": [
                        {"key": r.prop.key, "label": r.prop.label, "condition": r.prop.condition,
                         "signal": "given" if r.prop.signal_given else "learned",
                         "bounds": [r.prop.low, r.prop.high], "success": r.success.as_dict(),
                         "holds": r.holds, "failures_per_episode": r.failures}
                        for r in results
                    ],
                })  # fmt: skip
                if args.json:
                    continue
                table = Table(
                    title=f"world {w} (sensors {d}): {len(seeds)} seeds x {args.episodes} "
                    f"episodes, on {where}"
                )
                for col in ("", "property", "condition", "success [95% CI]", "bounds", ""):
                    table.add_column(col)
                for r in results:
                    table.add_row(
                        f"({r.prop.key})",
                        r.prop.label,
                        r.prop.condition + (" + signal" if r.prop.signal_given else ""),
                        pct(r.success),
                        f"{r.prop.low:.0%}-{r.prop.high:.0%}",
                        "holds" if r.holds else "[red]does not hold[/]",
                    )
                print_table(stdout, table)
    if args.json:
        from server.reports.base import clean_json

        stdout.write(json.dumps(clean_json(report)) + "\n")
    if args.out is not None:
        from server.reports.world_check import write_world_check

        write_world_check(args.out, {**report, "command": command_line(args)})
        if not args.json:
            console.print(f"wrote {args.out / 'world-check.json'} and world-check.md")
    return 0 if all_hold else 1


def _floats(text: str, name: str) -> list[float]:
    try:
        values = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise ValueError(f"--{name} takes comma-separated numbers, got {text!r}") from None
    if not values or any(not 0.0 <= v <= 1.0 for v in values):
        raise ValueError(f"--{name} values must be in [0, 1], got {text!r}")
    return values


def _qlambda_sweep(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    from core.qlambda import QLambdaConfig, sweep

    grid = [
        QLambdaConfig(alpha=a, lam=lam, epsilon=e)
        for a in _floats(args.alphas, "alphas")
        for lam in _floats(args.lambdas, "lambdas")
        for e in _floats(args.epsilons, "epsilons")
    ]
    seeds = list(range(args.seed_base, args.seed_base + args.seeds))
    err = Console(file=stderr, stderr=True)
    with Progress(
        TextColumn("[bold]Q(lambda) sweep[/]"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=err,
        transient=True,
    ) as progress:
        bar = progress.add_task("runs", total=len(grid) * len(seeds))
        rows = sweep(grid, seeds, args.episodes, args.jobs, lambda: progress.advance(bar))
    if args.json:
        stdout.write(json.dumps({"seeds": seeds, "episodes": args.episodes, "rows": rows}) + "\n")
        return 0
    table = Table(title=f"Q(lambda) sweep: seeds {seeds[0]}..{seeds[-1]}, {args.episodes} episodes")
    for col in ("alpha", "lambda", "epsilon", "success, last 50", "success, all"):
        table.add_column(col, justify="right")
    for r in rows:
        table.add_row(
            f"{r['alpha']:g}",
            f"{r['lambda']:g}",
            f"{r['epsilon']:g}",
            f"{r['success_last50']:.1%}",
            f"{r['success_all']:.1%}",
        )
    Console(file=stdout).print(table)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `srlab` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    args.argv = list(argv) if argv is not None else sys.argv[1:]
    try:
        if args.command == "simulate":
            return _simulate(args, sys.stdout, sys.stderr)
        if args.command == "experiment":
            return _experiment(args, sys.stdout, sys.stderr)
        if args.command == "sweep":
            return sweep_command(args, sys.stdout, sys.stderr)
        if args.command == "world-check":
            return _world_check(args, sys.stdout, sys.stderr)
        if args.command == "probe":
            return _probe(args, sys.stdout, sys.stderr)
        if args.command == "tune":
            return _tune(args, sys.stdout, sys.stderr)
        if args.command == "qlambda-sweep":
            return _qlambda_sweep(args, sys.stdout, sys.stderr)
        if args.command == "db":
            from server.cli import run as run_cli

            return run_cli.db(args, sys.stdout)
        if args.command == "run":
            from server.cli import run as run_cli
            from server.tuning import configure_process

            configure_process()
            if args.resume is None and args.condition is None:
                parser.error("run needs --condition (or --resume RUN)")
            return run_cli.run(args, sys.stdout, sys.stderr)
        if args.command == "serve":
            from server.serve import serve

            return serve(args.host, args.port)
        if args.command == "runs":
            from server.cli import run as run_cli

            return run_cli.runs(args, sys.stdout)
    except (CoreError, ValueError, OSError, BackendError) as e:
        parser.exit(2, f"srlab: error: {e}\n")
    except KeyboardInterrupt:
        parser.exit(130, "srlab: interrupted\n")
    except Exception as e:
        # Anything else is a bug or an adapter's error (a database driver's, say): one line
        # for the person at the shell, and the traceback only when asked for.
        if os.environ.get("SRLAB_DEBUG"):
            raise
        first = (str(e).strip().splitlines() or [""])[0]
        parser.exit(
            1, f"srlab: error: {type(e).__name__}: {first} (SRLAB_DEBUG=1 shows the traceback)\n"
        )
    parser.error(f"unknown command {args.command!r}")
    return 2  # pragma: no cover - parser.error exits


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
