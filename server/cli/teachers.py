"""`srlab teachers`: rp as each of its teacher's imperfections rises, and its report."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import IO

from rich.console import Console
from rich.table import Table

from server.cli.common import (
    add_study_arguments,
    add_task_arguments,
    finish_study,
    run_cells,
    setup_of,
)
from server.reports.base import diff, fmt, setup_params


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The `teachers` command and its arguments."""
    from core.lab.teachers import LEVELS, PRESETS, REFERENCES
    from core.run.trainer import TEACHERS_FILE

    levels = "; ".join(f"{n}={','.join(f'{v:g}' for v in vs)}" for n, vs in LEVELS)
    p = sub.add_parser(
        "teachers",
        help="run rp as each imperfection of its teacher rises, beside learners with no "
        "teacher, and write a report",
        description="Run the reinforcement program (rp) with a simulated teacher whose "
        "imperfections (a mistake rate, a skip rate, a reaction delay, a bias toward positive "
        "reward, fatigue) are raised one at a time, beside learners that need no teacher, on "
        "the same seeds; then write summary.json, summary.md, runs.jsonl and a plot per "
        "imperfection to --out, saying at which level rp falls below each learner.",
    )
    p.add_argument(
        "--param",
        action="append",
        metavar="NAME=V1,V2,...",
        help=f"an imperfection and its levels; repeat for several (default: {levels})",
    )
    p.add_argument(
        "--conditions",
        default=",".join(REFERENCES),
        help=f"the learners without a teacher rp is compared with (default {','.join(REFERENCES)})",
    )
    p.add_argument(
        "--presets",
        default=",".join(PRESETS),
        help=f"named teachers (core/data/trainers/{TEACHERS_FILE}) run as they are, "
        f"comma-separated; '' for none (default {','.join(PRESETS)})",
    )
    add_task_arguments(p, Path("results/teachers"))
    add_study_arguments(p)
    p.set_defaults(handler=teachers_command)


def teachers_command(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """Run `srlab teachers`."""
    from core.lab.experiment import parse_conditions
    from core.lab.sweep import parse_grid
    from core.lab.teachers import LEVELS, TeacherStudy, summarise_teachers
    from core.params import TEACHER_PREFIX, format_value
    from server.reports.teachers import write_teachers_report

    study = TeacherStudy(
        parse_grid(args.param) if args.param else LEVELS,
        tuple(parse_conditions(args.conditions)),
        tuple(p.strip() for p in args.presets.split(",") if p.strip()),
        setup_of(args),
        tuned=not args.untuned,
    )
    err = Console(file=stderr, stderr=True)
    results, ran = run_cells(args, err, "teachers", study.cells())
    summary = summarise_teachers(study, results)
    params = {
        **ran,
        "references": list(study.references),
        "levels": {n: list(vs) for n, vs in study.axes},
        "presets": list(study.presets),
        **setup_params(study.setup),
        "tuned": study.tuned,
    }
    paths = write_teachers_report(args.out, study, results, summary, params)
    table = Table(title="rp with an imperfect teacher: success in training and held out")
    table.add_column("teacher")
    table.add_column("training", justify="right")
    table.add_column("held-out", justify="right")
    for ref in study.references:
        table.add_column(f"rp - {ref}, held-out", justify="right")
    for ref, f in summary["references"].items():
        row = [f"{ref} (no teacher)", fmt(f["success_rate"], pct=True)]
        table.add_row(*row, fmt(f["held_out"], pct=True), *[""] * len(study.references))
    for name, entry in summary["by_parameter"].items():
        for lv in entry["levels"]:
            table.add_row(
                f"{name.removeprefix(TEACHER_PREFIX)} {format_value(lv['value'])}",
                fmt(lv["success_rate"], pct=True),
                fmt(lv["held_out"], pct=True),
                *[diff(lv["vs"][ref].get("held-out")) for ref in study.references],
            )
    return finish_study(stdout, err, table, params, paths, results, with_params=True)
