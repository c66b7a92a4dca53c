"""`srlab equal-start`: every method from Table I and from kp's design, and its report."""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path
from typing import IO

from rich.console import Console
from rich.table import Table

from server.cli.common import (
    add_reference_study_arguments,
    finish_study,
    judge_learned,
    run_cells,
    setup_of,
)
from server.reports.base import diff, fmt, setup_params

METHODS = "dp-rare,dp,rp,kp,qlambda-hybrid"


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The `equal-start` command and its arguments."""
    p = sub.add_parser(
        "equal-start",
        help="run every method from Table I and from kp's design, and split each difference "
        "into the method's and the start's",
        description="Run every method from both starts, Table I and kp's design (lane "
        "keeping and the sonar's obstacle responses), on the same seeds; then write "
        "summary.json, summary.md and equal_start.png to --out, with each start's full "
        "experiment report beneath it (table1/, design/). The summary compares the methods "
        "at equal start and splits each difference of the conditions as they are into the "
        "method's part and the start's.",
    )
    add_reference_study_arguments(
        p, METHODS, Path("results/equal-start"), "; each must start from Table I or kp's design"
    )
    p.set_defaults(handler=equal_start_command)


def equal_start_command(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """Run `srlab equal-start`."""
    from core.lab.equal_start import START_NAMES, EqualStartStudy, summarise_equal_start
    from core.lab.experiment import CAMERA_SENSOR, parse_conditions
    from core.run.conditions import STARTS
    from server.reports.equal_start import write_equal_start_report

    setup = setup_of(args)
    study = EqualStartStudy(
        tuple(parse_conditions(args.conditions)), setup, args.reference, tuned=not args.untuned
    )
    err = Console(file=stderr, stderr=True)
    results, ran = run_cells(args, err, "equal-start", study.cells())
    probed = judge_learned(args, err, replace(setup, start=""))
    catalog = setup.catalog()
    camera = [s.name for s in catalog.stimuli_of_sensor(CAMERA_SENSOR)]
    summary = summarise_equal_start(study, results, probed.correct() if probed else None, camera)
    params = {
        **ran,
        "conditions": list(study.methods),
        "reference": study.reference,
        **setup_params(setup),
        "tuned": study.tuned,
        "probe": probed.as_dict() if probed is not None else None,
    }
    paths = write_equal_start_report(args.out, study, results, summary, catalog, params)
    table = Table(title="every method from each start: success in training [held-out]")
    table.add_column("method")
    for s in STARTS:
        table.add_column(f"from {START_NAMES[s]}", justify="right")
    table.add_column(f"{study.reference} - it, equal start (design), held-out", justify="right")
    for m, g in summary["grid"].items():
        figures = [
            f"{fmt(g[s]['success_rate'], pct=True)} [{fmt(g[s]['held_out'] or {}, pct=True)}]"
            for s in STARTS
        ]
        vs = summary["method"]["design"].get(m, {}).get("held-out")
        table.add_row(m, *figures, diff(vs) if m != study.reference else "")
    return finish_study(stdout, err, table, params, paths, results)
