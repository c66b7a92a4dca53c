"""Sweep outputs: summary.json, summary.md, runs.jsonl, learning curves and a plot per parameter."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from core.lab.experiment import TaskResult
from core.lab.sweep import Sweep
from core.params import Params, ParamValue, format_value, point_label
from server.reports.base import diff, failed_lines, fmt, head, interval_line, row, write_summary
from server.reports.plots import ROLLING, rolling_success, save, subplots, success_axes


def distinct_settings(sweep: Sweep, condition: str) -> list[tuple[int, dict[str, ParamValue]]]:
    """The grid points that give `condition` distinct tasks: (point index, its settings)."""
    seen: set[Params] = set()
    out = []
    for i, point in enumerate(sweep.points()):
        key = sweep.task(point, condition, sweep.seeds[0]).params
        if key in seen:
            continue
        seen.add(key)
        out.append((i, {n: v for n, v in point.items() if sweep.applies(n, condition)}))
    return out


def plot_parameter(path: Path, name: str, entry: dict[str, Any]) -> None:
    """Success (all episodes, and the last 10) against one parameter's values, per condition."""
    fig, axes = subplots(1, figsize=(7, 4.5))
    ax = axes[0][0]
    labels: list[str] = []
    for cond, rows in entry["conditions"].items():
        values = [r["value"] for r in rows]
        labels = [format_value(v) for v in values]
        numeric = all(not isinstance(v, bool) for v in values)
        x = np.asarray(values, dtype=float) if numeric else np.arange(len(values), dtype=float)
        color = None
        for figure, style, what in (
            ("success_rate", "-", "all episodes"),
            ("success_last10", "--", "last 10"),
        ):
            y = np.array([r[figure]["mean"] for r in rows], dtype=float)
            ci = np.array([r[figure]["ci95"] for r in rows], dtype=float)
            ci = np.where(np.isnan(ci), 0.0, ci)
            bars = ax.errorbar(
                x,
                y,
                yerr=ci,
                linestyle=style,
                marker="o" if style == "-" else "s",
                capsize=3,
                color=color,
                alpha=1.0 if style == "-" else 0.6,
                label=f"{cond}, {what}",
            )
            color = bars.lines[0].get_color()
        if not numeric:
            ax.set_xticks(x, labels)
    success_axes(ax, xlabel=name, criterion=False)
    ax.set_ylabel("success rate (mean over seeds)")
    ax.set_title(f"{name}: {entry['description']}", fontsize=9)
    ax.legend(fontsize=8, loc="best")
    fig.text(
        0.01,
        0.01,
        "bars: 95% CI over seeds; other swept parameters averaged",
        fontsize=7,
        color="grey",
    )
    save(fig, path)


def plot_sweep_curves(path: Path, sweep: Sweep, summary: dict[str, Any]) -> None:
    """Learning curves, one panel per condition, one line per distinct setting."""
    cols = len(sweep.conditions)
    fig, axes = subplots(cols, figsize=(6 * cols, 4.8), sharey=True)
    for ax, cond in zip(axes[0], sweep.conditions, strict=True):
        for i, setting in distinct_settings(sweep, cond):
            s = summary["points"][i]["conditions"][cond]
            if not s.get("seeds"):
                continue
            rolled = rolling_success(s["success_by_seed"])
            label = point_label(setting) or "defaults"
            ax.plot(np.arange(1, rolled.shape[1] + 1), rolled.mean(axis=0), label=label)
        ax.set_title(cond)
        success_axes(ax)
        ax.legend(fontsize=7, loc="best")
    axes[0][0].set_ylabel(f"success rate (rolling {ROLLING}, mean over seeds)")
    fig.suptitle("Learning curves per setting")
    save(fig, path)


def _row_cells(s: dict[str, Any]) -> list[str]:
    crit = s["episodes_to_criterion"]
    median = "-" if crit["median"] is None else f"{crit['median']:.0f}"
    return [
        fmt(s["success_rate"], pct=True),
        fmt(s["success_last10"], pct=True),
        f"{median} ({crit['reached']}/{crit['never']})",
        fmt(s["collisions_per_episode"]),
        fmt(s["violations_per_episode"]),
    ]


def sweep_markdown(
    sweep: Sweep,
    summary: dict[str, Any],
    params: dict[str, Any],
    failed: Sequence[TaskResult],
) -> str:
    """The sweep's summary as readable tables."""
    grid = " x ".join(f"{len(v)} {n}" for n, v in sweep.axes)
    lines = [
        "# srlab sweep",
        "",
        f"`{params['command']}`",
        "",
        f"{grid} = {len(sweep.points())} grid points, x {len(sweep.conditions)} conditions x "
        f"{len(sweep.seeds)} seeds x {sweep.episodes} episodes: {params['tasks']} distinct "
        f"tasks (a condition runs once for the points that differ only in parameters it does "
        f"not use); {params['ticks']:,} ticks in {params['elapsed_s']:.1f} s on "
        f"{params['where']}.",
        "",
        interval_line(),
        "",
        *head(["parameter", "values", "used by", "ignored by"]),
    ]
    for name, values in sweep.axes:
        entry = summary["by_parameter"][name]
        lines.append(
            f"| {name} | {', '.join(format_value(v) for v in values)} | "
            f"{', '.join(entry['conditions']) or '-'} | {', '.join(entry['ignored_by']) or '-'} |"
        )
    lines += [
        "",
        "## Each parameter's effect",
        "",
        "Per value: the mean over seeds (± 95% CI) of each seed's figures averaged over the "
        "grid points with that value, so the other swept parameters are averaged out; and "
        "its difference from the first value's success, seed by seed, in points with its 95% "
        "interval and sign-flip p. Exploratory: a sweep compares many points, and these "
        "p-values are not corrected for it.",
    ]
    for name in sweep.names:
        entry = summary["by_parameter"][name]
        lines += [
            "",
            f"### {name}",
            "",
            f"{entry['description'][:1].upper()}{entry['description'][1:]}.",
            "",
            f"| {name} | condition | success, all episodes | minus the first value, paired | "
            "success, last 10 | collisions / episode | violations / episode |",
            "|---|---|---|---|---|---|---|",
        ]
        for cond, rows in entry["conditions"].items():
            for r in rows:
                lines.append(
                    f"| {format_value(r['value'])} | {cond} | "
                    f"{fmt(r['success_rate'], pct=True)} | {diff(r.get('success_vs_first'))} | "
                    f"{fmt(r['success_last10'], pct=True)} | "
                    f"{fmt(r['collisions_per_episode'])} | {fmt(r['violations_per_episode'])} |"
                )
        lines += ["", f"![{name}](param_{name}.png)"]
    names = [n for n, _ in sweep.axes]
    lines += [
        "",
        "## Every setting",
        "",
        "One row per condition and distinct setting; `-` marks a parameter the condition does "
        "not use. Episodes to criterion: the first episode after which the success over the "
        "last 10 episodes is at least 80% (median; seeds reached/never).",
        "",
        *head(["condition", *names, "success, all episodes", "success, last 10",
                "episodes to criterion", "collisions / episode", "violations / episode"]),
    ]  # fmt: skip
    best: dict[str, tuple[float, str, dict[str, Any]]] = {}
    for cond in sweep.conditions:
        for i, setting in distinct_settings(sweep, cond):
            s = summary["points"][i]["conditions"][cond]
            cells = [format_value(setting[n]) if n in setting else "-" for n in names]
            if not s.get("seeds"):
                lines.append(f"| {cond} | " + " | ".join(cells) + " | failed | | | | |")
                continue
            lines.append(row([cond, *cells, *_row_cells(s)]))
            rate = s["success_rate"]["mean"]
            if cond not in best or rate > best[cond][0]:
                best[cond] = (rate, point_label(setting) or "defaults", s)
    lines += [
        "",
        "## Best setting per condition (by success over all episodes)",
        "",
        "| condition | setting | success, all episodes | success, last 10 |",
        "|---|---|---|---|",
    ]
    for cond, (_, label, s) in best.items():
        lines.append(
            f"| {cond} | {label} | {fmt(s['success_rate'], pct=True)} | "
            f"{fmt(s['success_last10'], pct=True)} |"
        )
    lines += [
        "",
        "Picking the best of many settings on the same seeds flatters it: confirm it with "
        "`srlab experiment` on other seeds (`--seed-base`).",
        "",
        "![learning curves](learning_curves.png)",
    ]
    if failed:
        lines += ["", *failed_lines(failed, params=True)]
    return "\n".join(lines) + "\n"


def write_sweep_report(
    out: Path,
    sweep: Sweep,
    results: Sequence[TaskResult],
    summary: dict[str, Any],
    params: dict[str, Any],
) -> list[Path]:
    """Write every output file into `out`; returns their paths."""
    failed = [r for r in results if not r.ok]
    doc = {
        "params": params,
        "grid": {n: list(v) for n, v in sweep.axes},
        "points": [
            {
                "params": p["params"],
                "conditions": {
                    c: {
                        k: v
                        for k, v in s.items()
                        if k not in ("success_curve_ci95", "success_by_seed")
                    }
                    for c, s in p["conditions"].items()
                },
            }
            for p in summary["points"]
        ],
        "by_parameter": summary["by_parameter"],
        "failed": [
            {
                "condition": r.task.condition,
                "seed": r.task.seed,
                "params": dict(r.task.params),
                "error": r.error,
            }
            for r in failed
        ],
    }
    markdown = sweep_markdown(sweep, summary, params, failed)
    paths = write_summary(out, doc, markdown, results, params=True)
    curves = out / "learning_curves.png"
    plot_sweep_curves(curves, sweep, summary)
    plots = [curves]
    for name, _ in sweep.axes:
        p = out / f"param_{name}.png"
        plot_parameter(p, name, summary["by_parameter"][name])
        plots.append(p)
    return [*paths, *plots]
