"""`srlab experiment`: the paper's comparison, conditions x seeds, and its report."""

from __future__ import annotations

import argparse
import time
from contextlib import nullcontext
from pathlib import Path
from typing import IO

from rich.console import Console
from rich.table import Table

from core.run.conditions import CONDITIONS
from server.cli.common import (
    UsageError,
    add_task_arguments,
    command_line,
    non_negative_int,
    open_backend,
    print_table,
    report_failures,
    setup_of,
    task_progress,
)
from server.cli.conditions import add_network_arguments, with_conditions
from server.reports.base import setup_params


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The `experiment` command and its arguments."""
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
        help=f"comma-separated, from: {', '.join(CONDITIONS)}, or condition files (.toml, "
        "docs/conditions.md; FILE.toml:NAME for one of a file's) (default: the paper's "
        "four, innate and qlambda)",
    )
    add_task_arguments(exp, Path("results"))
    add_network_arguments(exp)
    exp.add_argument(
        "--eval-episodes",
        type=non_negative_int,
        default=0,
        metavar="N",
        help="after training, N episodes of frozen evaluation on held-out seeds, and N of "
        "the camera-only transfer test (default 0: none)",
    )
    exp.add_argument(
        "--teacher",
        metavar="TEACHER",
        help="who gives rp's judgements: a preset of core/data/trainers/teachers.toml "
        "(perfect, the default; mistaken, distracted, slow, lenient, tiring, human), "
        "imperfections as NAME=VALUE (mistake, skip, delay_s, delay_cv, bias, fatigue), or "
        "a preset then changes: human,skip=0 (see srlab teachers)",
    )
    exp.add_argument(
        "--untuned",
        action="store_true",
        help="run every condition with its default parameters, not the tuned ones "
        "(core/data/tuned.toml, written by srlab tune)",
    )
    exp.add_argument(
        "--declare",
        metavar="A-B,...",
        help="the comparisons the conclusions rest on, declared before running: pairs of "
        "conditions (kp-sonar), each tested on all episodes and held out, Holm-corrected "
        "together in the summary; every other comparison is marked exploratory (default: "
        "kp-sonar,kp-rp,kp-qlambda-hybrid,kp-dp, those whose conditions run)",
    )
    exp.add_argument(
        "--no-probe",
        action="store_true",
        help="do not judge what was learned with the placement probe (srlab probe)",
    )
    exp.set_defaults(handler=experiment)


def experiment(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """Run `srlab experiment`."""
    from core.lab.analysis import DECLARED, parse_pairs
    from core.lab.experiment import CAMERA_SENSOR, parse_conditions, run_experiment, summarise
    from core.lab.stats import Estimate, pct
    from core.params import teacher_params, tuned_params
    from core.run.trainer import parse_teacher
    from server.reports.experiment import write_report

    setup, named = with_conditions(
        setup_of(args), args.conditions.split(","), args.network, args.url
    )
    conditions = parse_conditions(",".join(named), setup)
    if args.declare is None:
        declared = [p for p in DECLARED if set(p) <= set(conditions)]
    else:
        declared = parse_pairs(args.declare, list(dict.fromkeys([*CONDITIONS, *conditions])))
        missing = sorted({c for p in declared for c in p} - set(conditions))
        if missing:
            raise UsageError(
                f"--declare: {', '.join(missing)} not among --conditions; a declared "
                "comparison needs both its conditions run"
            )
    teacher = parse_teacher(args.teacher) if args.teacher else None
    if teacher is not None and not any(setup.lookup(c).trainer for c in conditions):
        raise UsageError(f"--teacher: none of {', '.join(conditions)} has a teacher (rp has)")
    seeds = list(range(args.seed_base, args.seed_base + args.seeds))
    catalog = setup.catalog()
    err = Console(file=stderr, stderr=True)
    with open_backend(args, err) as (backend, where):
        total = len(conditions) * len(seeds)
        progress, on_result = task_progress(err, "experiment", total, args.quiet)
        started = time.perf_counter()
        with progress:
            results = run_experiment(
                conditions,
                seeds,
                args.episodes,
                args.jobs,
                on_result,
                backend,
                setup,
                args.eval_episodes,
                tuned=not args.untuned,
                params=teacher_params(teacher) if teacher else None,
            )
        elapsed = time.perf_counter() - started
    probed = None
    if not args.no_probe:
        from server.services.probe_cache import cached_probe

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
        "declared": [list(p) for p in declared],
        "declared_given": args.declare is not None,
        **({"teacher": teacher.changed()} if teacher and not teacher.perfect else {}),
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
    return report_failures(err, results, params=False)
