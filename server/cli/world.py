"""`srlab probe`, `srlab world-check` and `srlab world`: what a world poses, and the worlds.

`probe` and `world-check` measure a world with no learning anywhere; `world` lists the
presets and world files, checks one and draws it.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import IO, Any

from rich.console import Console
from rich.table import Table

from server.cli.common import (
    add_batch_arguments,
    add_setup_arguments,
    command_line,
    non_negative_int,
    open_backend,
    positive_int,
    print_table,
    setup_of,
    task_progress,
)


def add_probe_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The `probe` command and its arguments."""
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
        "--placements", type=positive_int, default=20, help="placements per stimulus (20)"
    )
    pr.add_argument(
        "--seed", type=non_negative_int, default=0, help="seed of the placements (default 0)"
    )
    pr.add_argument("--json", action="store_true", help="print one JSON object")
    pr.set_defaults(handler=probe)


def probe(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """Run `srlab probe`."""
    from server.services.probe_cache import cached_probe

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
        good = sorted(p.correct, key=lambda b: (-p.passed[b], b))  # ties by name: stable
        cells = ", ".join(f"{b} {p.passed[b]:.0%}" for b in good) or "[red]none[/]"
        best, share = p.best
        table.add_row(name, cells, f"{best} {share:.0%}")
    print_table(stdout, table)
    return 0


def add_world_check_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The `world-check` command and its arguments."""
    check = sub.add_parser(
        "world-check",
        help="does a world preset pose the paper's problem? (properties of the world alone)",
        description="With the signal's responses given and no learning anywhere: (a) no "
        "obstacle knowledge succeeds <= 20%%, (b) the sonar reflexes alone 40-80%%, (c) the "
        "expert's camera responses >= 95%%; and (d) innate knowledge alone <= 10%% (Table "
        "II). A world with a stop-line beacon (stop-line) is checked on the signal instead: "
        "(a) no signal knowledge <= 65%%, (b) the beacon's reflexes alone 65-90%%, (c) the "
        "expert's >= 95%%. Prints each with its 95%% Student's t interval over seeds.",
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
    add_batch_arguments(check)
    check.add_argument("--json", action="store_true", help="print one JSON object")
    check.add_argument(
        "--out", type=Path, help="also write world-check.json and world-check.md to this folder"
    )
    check.add_argument("--quiet", action="store_true", help="no progress display")
    check.set_defaults(handler=world_check)


def world_check(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """Run `srlab world-check`."""
    from core.brain.catalog import sensor_definitions
    from core.lab.stats import pct
    from core.lab.worldcheck import properties_for
    from core.lab.worldcheck import world_check as check_world
    from core.sim.worlds import load_world, world_names

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
                total = len(properties_for(w)) * len(seeds)
                progress, on_result = task_progress(
                    err, f"world-check {w} ({d})", total, args.quiet
                )
                with progress:
                    results = check_world(w, d, seeds, args.episodes, backend, on_result)
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


def add_world_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The `world` command (list, check, show) and its arguments."""
    w = sub.add_parser(
        "world",
        help="world presets and world files: list them, check a file, draw a picture, the schema",
        description="The world presets (core/data/worlds.toml and core/data/worlds/*.toml) "
        "and any world file (docs/worlds.md): list them, load one and report its errors, "
        "or draw it from above.",
    )
    actions = w.add_subparsers(dest="action", required=True, metavar="ACTION")
    ls = actions.add_parser("list", help="the world presets, one a line")
    ls.add_argument("--json", action="store_true", help="print one JSON object")
    ls.set_defaults(handler=world_list)
    check = actions.add_parser(
        "check", help="load a world (a preset's name or a file) and report its first error"
    )
    check.add_argument("world", metavar="NAME|FILE")
    check.set_defaults(handler=world_file_check)
    show = actions.add_parser(
        "show",
        help="draw a world from above: walls, centre line, start, signal, obstacles",
    )
    show.add_argument("world", metavar="NAME|FILE")
    show.add_argument("--png", type=Path, required=True, metavar="OUT", help="the picture")
    show.set_defaults(handler=world_show)
    schema = actions.add_parser(
        "schema", help="print the world file format's JSON Schema (docs/schemas/world.schema.json)"
    )
    schema.set_defaults(handler=world_schema)


def _named_world(text: str) -> Any:
    """The preset called `text`, or the world file at path `text`."""
    from core.sim.worldfile import load_world_file
    from core.sim.worlds import load_world, world_names

    if text in world_names():
        return load_world(text)
    path = Path(text)
    if path.suffix == ".toml" or path.exists():
        return load_world_file(path)
    known = ", ".join(world_names())
    raise ValueError(f"no world preset or world file {text!r} (presets: {known})")


def world_list(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """Run `srlab world list`."""
    from core.sim.corridor import CorridorConfig
    from core.sim.worlds import default_world, load_world, world_names

    rows: list[dict[str, str]] = []
    for name in world_names():
        preset = load_world(name)
        kind = "corridor" if isinstance(preset.config.track, CorridorConfig) else "ring"
        default = " (default)" if name == default_world() else ""
        rows.append({"name": name, "track": kind, "description": preset.description,
                     "default": default})  # fmt: skip
    if args.json:
        stdout.write(json.dumps({"worlds": rows}) + "\n")
        return 0
    table = Table(title="srlab world presets")
    for col in ("name", "track", "description"):
        table.add_column(col)
    for r in rows:
        table.add_row(r["name"] + r["default"], r["track"], r["description"])
    print_table(stdout, table)
    return 0


def world_file_check(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """Run `srlab world check`."""
    from core.sim.types import build_geometry

    preset = _named_world(args.world)
    geo = build_geometry(preset.config.track)
    stdout.write(
        f"{args.world}: world {preset.name!r} loads: {len(geo.leg_lengths_m)} segments, "
        f"a lap of {geo.lap_length_m:.2f} m, {len(geo.wall_segments())} wall segments\n"
    )
    return 0


def world_show(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """Run `srlab world show`."""
    from server.reports.world_picture import draw_world

    preset = _named_world(args.world)
    args.png.parent.mkdir(parents=True, exist_ok=True)
    draw_world(preset, args.png)
    stdout.write(f"wrote {args.png}\n")
    return 0


def world_schema(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """Run `srlab world schema`."""
    from core.sim.worldfile import json_schema

    stdout.write(json.dumps(json_schema(), indent=2) + "\n")
    return 0
