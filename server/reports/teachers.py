"""`srlab teachers` outputs: summary.json, summary.md, runs.jsonl and a plot per imperfection."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes

from core.lab.experiment import TaskResult
from core.lab.teachers import MEASURES, TAUGHT, TeacherStudy
from core.params import TEACHER_PREFIX, format_value
from server.reports.base import (
    diff,
    failed_lines,
    fmt,
    head,
    row,
    study_document,
    write_summary,
)
from server.reports.declared import declared_section
from server.reports.experiment_plots import CONDITION_COLOURS
from server.reports.plots import save, subplots, success_axes

FIGURES = (("success_rate", "training, all episodes"), ("held_out", "held-out, frozen"))
"""The figures plotted against each imperfection: per measure, the key and its title."""


def _bounds(stat: dict[str, float] | None) -> tuple[float, float, float]:
    if not stat:
        return math.nan, math.nan, math.nan
    mean = stat["mean"]
    low, high = stat.get("low", math.nan), stat.get("high", math.nan)
    if low is None or high is None or math.isnan(low) or math.isnan(high):
        return mean, mean, mean
    return mean, low, high


def _reference_band(ax: Axes, name: str, stat: dict[str, float] | None) -> None:
    mean, low, high = _bounds(stat)
    if math.isnan(mean):
        return
    colour = CONDITION_COLOURS.get(name, "grey")
    ax.axhline(mean, color=colour, linewidth=1.4, label=f"{name} (no teacher)")
    ax.axhspan(low, high, color=colour, alpha=0.12)


def plot_imperfection(
    path: Path, name: str, entry: dict[str, Any], summary: dict[str, Any]
) -> None:
    """The taught robot's success against one imperfection's level, beside the references'.

    Two panels: success over the training episodes, and held out, frozen. Bars and bands
    are 95% Student's t intervals over seeds.
    """
    fig, axes = subplots(len(FIGURES), figsize=(11, 4.4), sharey=True)
    levels = entry["levels"]
    x = np.array([float(lv["value"]) for lv in levels])
    for ax, (key, title) in zip(axes[0], FIGURES, strict=True):
        for ref, figures in summary["references"].items():
            _reference_band(ax, ref, figures[key])
        stats = [_bounds(lv[key]) for lv in levels]
        y = np.array([s[0] for s in stats])
        err = np.array([[s[0] - s[1] for s in stats], [s[2] - s[0] for s in stats]])
        ax.errorbar(
            x, y, yerr=err, marker="o", capsize=3, color=CONDITION_COLOURS[TAUGHT],
            linewidth=1.8, label=f"{TAUGHT} (its teacher's {name.removeprefix(TEACHER_PREFIX)})",
        )  # fmt: skip
        success_axes(ax, xlabel=name.removeprefix(TEACHER_PREFIX), criterion=False)
        ax.set_title(title, fontsize=10)
    axes[0][0].set_ylabel("success rate (mean over seeds)")
    axes[0][-1].legend(fontsize=8, loc="lower left")
    fig.suptitle(f"{entry['description']}: rp as it rises, beside learners with no teacher")
    save(fig, path)


def _level(value: Any, name: str) -> str:
    unit = " s" if name.endswith("_s") else ""
    return f"{format_value(value)}{unit}"


def _verdict(entry: dict[str, Any], ref: str, name: str) -> str:
    """A sentence: where rp falls below `ref`, and where it stops being above it."""
    parts = []
    for measure, label in MEASURES:
        below = entry["below"][ref][measure]
        not_above = entry["not_above"][ref][measure]
        if below is not None:
            text = f"below it from {_level(below, name)}"
        elif not_above is not None:
            text = f"no longer above it from {_level(not_above, name)}, never below"
        else:
            text = "above it at every level"
        parts.append(f"{label}: {text}")
    return f"- rp against {ref}: " + "; ".join(parts) + "."


def _figures_row(label: str, figures: dict[str, Any], refs: Sequence[str]) -> list[str]:
    cells = [label, fmt(figures["success_rate"], pct=True), fmt(figures["held_out"], pct=True)]
    for ref in refs:
        vs = figures["vs"].get(ref, {})
        cells += [diff(vs.get("all")), diff(vs.get("held-out"))]
    return cells


def summary_markdown(
    study: TeacherStudy,
    summary: dict[str, Any],
    params: dict[str, Any],
    failed: Sequence[TaskResult],
) -> str:
    """The study's summary: per imperfection a table, the verdicts and its plot."""
    refs = list(study.references)
    columns = ["teacher", "rp, training", "rp, held-out"]
    for ref in refs:
        columns += [f"rp - {ref}, training", f"rp - {ref}, held-out"]
    ref_lines = [
        f"- `{ref}`: {fmt(f['success_rate'], pct=True)} in training, "
        f"{fmt(f['held_out'], pct=True)} held out."
        for ref, f in summary["references"].items()
    ]
    lines = [
        "# srlab teachers",
        "",
        f"`{params['command']}`",
        "",
        f"{params['seeds']} seeds x {params['episodes']} episodes per cell, then "
        f"{params['eval_episodes']} held-out episodes frozen; {params['tasks']} tasks, "
        f"{params['ticks']:,} ticks in {params['elapsed_s']:.1f} s on {params['where']}. "
        f"World `{params['world']}`, camera stimuli `{params['sensors']}`, signal "
        f"{params['signal']}; every condition with its tuned parameters"
        + (" (none: --untuned)." if not study.tuned else "."),
        "",
        "`rp` is the reinforcement program given by a simulated teacher: each imperfection "
        "below is raised alone, the others at the perfect teacher's 0 "
        "(`core.run.trainer.Imperfections`, `core/data/trainers/teachers.toml`). A late reward "
        "credits what STM holds when it arrives. Beside it, learners that need no teacher:",
        "",
        *ref_lines,
        "",
        "Success is the mean over seeds with its 95% Student's t interval; a difference is rp's "
        "minus the learner's, paired by seed (every cell meets the same obstacles and lamp "
        "cycles on a seed), in points, with the sign-flip test's p. *Below from* a level: the "
        "first level whose difference's interval lies under 0; *no longer above*: the first "
        "whose interval reaches 0. The levels were declared before the study ran; each "
        "level's comparison is one of many (5 imperfections x 5 levels x 2 learners x 2 "
        "measures), so a single p near 0.05 is exploratory.",
        "",
        *declared_section(
            summary["declared"],
            f"rp given by the perfect teacher and by each named teacher, minus `{refs[0]}`, "
            "in training and held out",
        ),
    ]
    for name, entry in summary["by_parameter"].items():
        short = name.removeprefix(TEACHER_PREFIX)
        lines += [f"## {short}: {entry['description']}", "", *head(columns)]
        for lv in entry["levels"]:
            label = f"{short} = {_level(lv['value'], name)}"
            lines.append(row(_figures_row(label, lv, refs)))
        lines += ["", *(_verdict(entry, ref, name) for ref in refs), ""]
        lines += [f"![rp as {short} rises]({name}.png)", ""]
    if summary["presets"]:
        lines += [
            "## Named teachers",
            "",
            "Several imperfections at once (`core/data/trainers/teachers.toml`).",
            "",
            *head(columns),
        ]
        for p, f in summary["presets"].items():
            what = ", ".join(f"{k} {format_value(v)}" for k, v in f["teacher"].items())
            lines.append(row(_figures_row(f"{p} ({what})", f, refs)))
        lines.append("")
    if failed:
        lines += failed_lines(failed, params=True)
    return "\n".join(lines).rstrip() + "\n"


def write_teachers_report(
    out: Path,
    study: TeacherStudy,
    results: Sequence[TaskResult],
    summary: dict[str, Any],
    params: dict[str, Any],
) -> list[Path]:
    """Write summary.json, summary.md, runs.jsonl and a plot per imperfection into `out`."""
    failed = [r for r in results if not r.ok]
    doc = study_document(params, summary, results)
    paths = write_summary(
        out, doc, summary_markdown(study, summary, params, failed), results, params=True
    )
    for name, entry in summary["by_parameter"].items():
        path = out / f"{name}.png"
        plot_imperfection(path, name, entry, summary)
        paths.append(path)
    return paths
