"""`srlab noise`: every condition with exact and with noisy perception, and its report."""

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

CONDITIONS = "kp,sonar,rp,qlambda-hybrid,dp"


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The `noise` command and its arguments."""
    from core.sim.worlds import parse_perception

    p = sub.add_parser(
        "noise",
        help="run every condition with exact and with noisy perception on the same seeds, "
        "and say what the noise moves",
        description="Run every condition twice on each seed, with exact perception and with "
        "the noisy one --perception names (default noisy), then write summary.json, "
        "summary.md and noise.png to --out, with each perception's full experiment report "
        "beneath it (exact/, noisy/). The summary pairs every figure by seed across the two: "
        "what the noise costs each condition, the reference's lead over each other "
        "condition both ways, and how much the noise moves that lead.",
    )
    add_reference_study_arguments(p, CONDITIONS, Path("results/noise"))
    p.set_defaults(perception=parse_perception("noisy"))
    p.set_defaults(handler=noise_command)


def noise_command(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """Run `srlab noise`."""
    from core.lab.experiment import CAMERA_SENSOR, parse_conditions
    from core.lab.noise import PERCEPTIONS, NoiseStudy, summarise_noise
    from server.reports.noise import write_noise_report

    noise = args.perception
    if not noise:
        raise ValueError("--perception exact leaves nothing to compare: name a noisy one")
    # The study sets the perception of each side itself; the rest of the setup is shared.
    setup = replace(setup_of(args), world_settings=())
    study = NoiseStudy(
        tuple(parse_conditions(args.conditions)),
        noise,
        setup,
        args.reference,
        tuned=not args.untuned,
    )
    err = Console(file=stderr, stderr=True)
    results, ran = run_cells(args, err, "noise", study.cells())
    # What is correct is the world's: judged with exact perception, for both sides.
    probed = judge_learned(args, err, setup)
    catalog = setup.catalog()
    camera = [s.name for s in catalog.stimuli_of_sensor(CAMERA_SENSOR)]
    summary = summarise_noise(study, results, probed.correct() if probed else None, camera)
    params = {
        **ran,
        "conditions": list(study.conditions),
        "reference": study.reference,
        **setup_params(setup),
        "noise": dict(study.noise),
        "tuned": study.tuned,
        "probe": probed.as_dict() if probed is not None else None,
    }
    paths = write_noise_report(args.out, study, results, summary, catalog, params)
    table = Table(title="every condition both ways: success in training [held-out]")
    table.add_column("condition")
    for p in PERCEPTIONS:
        table.add_column(p, justify="right")
    table.add_column("noisy - exact, held-out", justify="right")
    for c, g in summary["grid"].items():
        figures = [
            f"{fmt(g[p]['success_rate'] or {}, pct=True)} [{fmt(g[p]['held_out'] or {}, pct=True)}]"
            for p in PERCEPTIONS
        ]
        table.add_row(c, *figures, diff(g["noise_effect"].get("held-out")))
    return finish_study(stdout, err, table, params, paths, results)
