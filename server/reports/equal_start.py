"""`srlab equal-start` outputs: the grid's summary and plot, and an experiment report per start."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from core.brain.catalog import Catalog
from core.lab.equal_start import START_NAMES, EqualStartStudy, label, own_start
from core.lab.experiment import TaskResult
from core.run.conditions import STARTS
from server.reports.base import diff, failed_lines, fmt, head, row
from server.reports.declared import declared_section
from server.reports.plots import grouped_bars, save, subplots, success_axes
from server.reports.study import Part, write_study

MEASURES = (("all", "training, all episodes"), ("held-out", "held-out, frozen"))
"""The figures the grid reports: the paired comparisons' keys and their titles."""
FIGURE_OF = {"all": "success_rate", "held-out": "held_out"}
START_COLOURS = {"table1": "#bbbbbb", "design": "#1f3fb4"}


def plot_grid(path: Path, study: EqualStartStudy, summary: dict[str, Any]) -> None:
    """Each method's success from each start, in training and held out (95% intervals)."""
    fig, axes = subplots(len(MEASURES), figsize=(12, 4.6), sharey=True)
    methods = list(study.methods)
    for ax, (measure, title) in zip(axes[0], MEASURES, strict=True):
        own = [summary["grid"][m]["own_start"] for m in methods]
        grouped_bars(
            ax,
            [f"{m}\n(own: {START_NAMES[o]})" for m, o in zip(methods, own, strict=True)],
            [
                (
                    f"from {START_NAMES[start]}",
                    START_COLOURS[start],
                    [summary["grid"][m][start][FIGURE_OF[measure]] for m in methods],
                )
                for start in STARTS
            ],
        )
        ax.tick_params(axis="x", labelsize=8)
        success_axes(ax, xlabel="", criterion=False)
        ax.set_title(title, fontsize=10)
    axes[0][0].set_ylabel("success rate (mean over seeds)")
    axes[0][0].legend(fontsize=8, loc="upper left")
    fig.suptitle("Every method from Table I and from kp's design (bars: 95% Student's t intervals)")
    save(fig, path)


def _split_lines(study: EqualStartStudy, summary: dict[str, Any], measure: str) -> list[str]:
    ref = study.reference
    lines = [
        *head(
            [
                "method (its own start)",
                f"headline: {ref} - it, each from its own",
                f"method: {ref} - it, both from {START_NAMES['design']}",
                f"start: it from {START_NAMES['design']} - from its own",
            ]
        )
    ]
    for m, parts in summary["decomposition"].items():
        own = START_NAMES[parts["own_start"]]
        cells = [diff(parts[k].get(measure)) for k in ("headline", "method", "start")]
        lines.append(row([f"{m} ({own})", *cells]))
    return lines


def summary_markdown(
    study: EqualStartStudy,
    summary: dict[str, Any],
    params: dict[str, Any],
    failed: Sequence[TaskResult],
) -> str:
    """The grid, the methods at equal start, and the headline split into method and start."""
    ref = study.reference
    grid_columns = ["method", "own start"]
    for s in STARTS:
        grid_columns += [f"from {START_NAMES[s]}: 1-10", "training", "held-out"]
    grid_columns += ["design - Table I, training", "held-out"]
    lines = [
        "# srlab equal-start",
        "",
        f"`{params['command']}`",
        "",
        f"{params['seeds']} seeds x {params['episodes']} episodes per cell, then "
        f"{params['eval_episodes']} held-out episodes frozen; {params['tasks']} tasks, "
        f"{params['ticks']:,} ticks in {params['elapsed_s']:.1f} s on {params['where']}. "
        f"World `{params['world']}`, camera stimuli `{params['sensors']}`, signal "
        f"{params['signal']}; every method with its tuned parameters, the same from either "
        "start" + (" (none: --untuned)." if not study.tuned else "."),
        "",
        "Every method runs from both starts (`srlab experiment --start`): *Table I* (the "
        "paper's innate knowledge: corner, walls, collision) and *kp's design* (Table I, "
        "lane keeping and the sonar's obstacle responses, Fig. 13). A DP condition keeps its "
        "programmed responses on top of either: `dp-rare` programs the signal and the "
        "left- and middle-lane camera stimuli and learns R-L, R-M and R-R, as the paper's "
        "DP; `dp` programs the side lanes and learns M-L, M-M and M-R (srlab's split). "
        "Success is the mean over seeds [95% Student's t interval]; differences are paired by "
        "seed, in points, with the sign-flip test's p.",
        "",
        *declared_section(
            summary["declared"],
            f"{ref} minus each other method with the starting knowledge equal (both from "
            f"{START_NAMES[own_start(ref)]}), in training and held out",
        ),
        "## Success from each start",
        "",
        *head(grid_columns),
    ]
    for m, g in summary["grid"].items():
        cells = [m, START_NAMES[g["own_start"]]]
        for s in STARTS:
            cells += [
                fmt(g[s][k] or {}, pct=True) for k in ("success_1_10", "success_rate", "held_out")
            ]
        cells += [diff(g["start_effect"].get(k)) for k, _ in MEASURES]
        lines.append(row(cells))
    lines += [
        "",
        "![Every method from each start](equal_start.png)",
        "",
        f"## The methods at equal start: {ref} minus each",
        "",
        *head(
            [
                "method",
                *(f"from {START_NAMES[s]}: {t}" for s in STARTS for _, t in MEASURES),
            ]
        ),
    ]
    for m in (m for m in study.methods if m != ref):
        cells = [diff(summary["method"][s][m].get(k)) for s in STARTS for k, _ in MEASURES]
        lines.append(row([m, *cells]))
    lines += [
        "",
        "## The headline's differences, split into the method's and the start's",
        "",
        f"Each method at its own start against {ref} at its own (what a comparison of the "
        "conditions as they are measures) is the sum, seed by seed, of the method's part "
        f"(both from {ref}'s start) and the start's part (the method moved to {ref}'s "
        "start). Training, all episodes:",
        "",
        *_split_lines(study, summary, "all"),
        "",
        "Held out, frozen:",
        "",
        *_split_lines(study, summary, "held-out"),
        "",
        "Each start's full experiment report (learning curves, what was learned judged by "
        "the probe, every pair): [from Table I](table1/summary.md), "
        "[from kp's design](design/summary.md).",
        "",
    ]
    if failed:
        lines += failed_lines(failed)
    return "\n".join(lines).rstrip() + "\n"


def write_equal_start_report(
    out: Path,
    study: EqualStartStudy,
    results: Sequence[TaskResult],
    summary: dict[str, Any],
    catalog: Catalog,
    params: dict[str, Any],
) -> list[Path]:
    """Write the study's summary and plot into `out`, and each start's report beneath it."""
    parts = [
        Part(
            start,
            [r for r in results if r.task.setup.start == start],
            {m: summary["cells"][label(m, start)] for m in study.methods},
            {**params, "start": start},
            f"srlab equal-start: every method from {START_NAMES[start]}",
        )
        for start in STARTS
    ]
    return write_study(
        out,
        params,
        summary,
        results,
        lambda failed: summary_markdown(study, summary, params, failed),
        ("equal_start.png", lambda path: plot_grid(path, study, summary)),
        catalog,
        parts,
    )
