"""`srlab outside`: srlab's brain on worlds srlab did not build (the srlab[worlds] extra).

`list` names the outside worlds; `check WORLD` measures a world's properties (no learning);
`experiment WORLD` measures them too, then runs the conditions and the declared comparisons
(kp against its ablation by default), and with `--out` writes summary.md (its first line the
command) and summary.json there.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import IO, Any

from rich.console import Console

from server.cli.common import command_line, non_negative_int, positive_int


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The `outside` command, its actions and their arguments."""
    out = sub.add_parser(
        "outside",
        help="srlab's brain on outside worlds (MiniGrid, ir-sim: the srlab[worlds] extra)",
        description="Run srlab's architecture on a world it did not build: logical sensors "
        "and behaviours as data over the world's channels and actions (docs/outside.md).",
    )
    actions = out.add_subparsers(dest="action", required=True, metavar="ACTION")
    ls = actions.add_parser("list", help="the outside worlds shipped")
    ls.set_defaults(handler=list_worlds)
    for name, helptext in (
        ("check", "the world's properties, no learning (reflex, earlier sight, the copy)"),
        ("experiment", "the properties, then the conditions and the declared comparisons"),
    ):
        p = actions.add_parser(name, help=helptext, description=helptext)
        p.add_argument("world", help="an outside world's name (srlab outside list) or folder")
        p.add_argument("--seeds", type=positive_int, default=20, help="seeds (20)")
        p.add_argument("--seed-base", type=non_negative_int, default=0, help="first seed (0)")
        p.add_argument(
            "--episodes", type=positive_int, help="training episodes a seed (the world's)"
        )
        p.add_argument("--jobs", type=positive_int, default=1, help="worker processes (1)")
        p.add_argument("--json", action="store_true", help="print one JSON object")
        p.add_argument(
            "--out", type=Path, help="also write summary.md and summary.json to this folder"
        )
        if name == "experiment":
            p.add_argument(
                "--held-out", type=positive_int, help="held-out episodes a seed (the world's)"
            )
            p.add_argument("--conditions", default="kp,sonar", help="conditions to run (kp,sonar)")
            p.add_argument(
                "--declare",
                default="kp-sonar",
                help="declared comparisons a-b, comma-separated, Holm-corrected (kp-sonar)",
            )
        p.set_defaults(handler=check if name == "check" else experiment)


def list_worlds(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """Run `srlab outside list`."""
    from core.outside.world import load_outside, outside_names

    for name in outside_names():
        w = load_outside(name)
        stdout.write(f"{name}: {w.description}\n")
    return 0


def _prepare(args: argparse.Namespace) -> Any:
    from core.outside.world import load_outside

    world = load_outside(args.world)
    world.make().close()  # the extra missing is one error here, before anything runs
    return world


def _write(
    args: argparse.Namespace, stdout: IO[str], report: dict[str, Any], md: list[str]
) -> None:
    command = command_line(args)
    report = {"command": command, **report}
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / "summary.json").write_text(json.dumps(report, indent=1) + "\n")
        (args.out / "summary.md").write_text(f"# `{command}`\n\n" + "\n".join(md) + "\n")
    if args.json:
        stdout.write(json.dumps(report) + "\n")
    else:
        Console(file=stdout).print("\n".join(md), markup=False, highlight=False)


def check(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """Run `srlab outside check`."""
    from core.outside import lab

    world = _prepare(args)
    seeds = range(args.seed_base, args.seed_base + args.seeds)
    report = lab.check(world, seeds, args.episodes, args.jobs)
    _write(args, stdout, report, lab.check_markdown(report))
    return 0


def experiment(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """Run `srlab outside experiment`."""
    from core.lab.analysis import parse_pairs
    from core.outside import lab

    world = _prepare(args)
    conditions = [c.strip() for c in args.conditions.split(",") if c.strip()]
    for c in conditions:
        world.condition(c)
    pairs = parse_pairs(args.declare, list(world.conditions))
    seeds = range(args.seed_base, args.seed_base + args.seeds)
    props = lab.check(world, seeds, args.episodes, args.jobs)
    report = lab.experiment(
        world, conditions, pairs, seeds, args.episodes, args.held_out, args.jobs
    )
    md = [
        *lab.reading(props, report), "",
        *lab.check_markdown(props), "",
        *lab.experiment_markdown(report),
    ]  # fmt: skip
    _write(args, stdout, {**report, "properties": props}, md)
    return 0
