"""Phase diagram outputs: summary.json, summary.md, runs.jsonl and the two phase plots."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from core.lab.experiment import TaskResult
from core.lab.phase import REFLEXES, Phase, sign_of
from core.lab.stats import Estimate, pct
from core.params import format_value
from core.sim.worlds import get_world_parameter
from server.reports.base import (
    diff,
    failed_lines,
    head,
    interval_line,
    row,
    settings_text,
    write_summary,
)
from server.reports.plots import colours, save, subplots

FloatArray = npt.NDArray[np.float64]
SIGNS = (("+", "interval above 0"), ("0", "interval covers 0"), ("-", "interval below 0"))
LISTED = 6
"""Up to this many points a region lists them by name; beyond, it counts them."""


def write_phase_report(
    out: Path,
    phase: Phase,
    results: Sequence[TaskResult],
    summary: Mapping[str, Any],
    params: Mapping[str, Any],
) -> list[Path]:
    """Write the diagram's report into `out`; returns the paths written."""
    failed = [r for r in results if not r.ok]
    grid = {name: [float(v) for v in values] for name, values in phase.axes}
    doc = {
        "params": dict(params),
        "grid": grid,
        "base": {name: phase.base_value(name) for name, _ in phase.axes},
        **summary,
        "failed": [{"condition": r.task.condition, "seed": r.task.seed,
                    "world_settings": dict(r.task.setup.world_settings), "error": r.error}
                   for r in failed],
    }  # fmt: skip
    paths = write_summary(out, doc, markdown(phase, summary, params, failed), results)
    plot_phase(out / "phase.png", phase, summary)
    plot_by_parameter(out / "phase_by_parameter.png", phase, summary)
    return [*paths, out / "phase.png", out / "phase_by_parameter.png"]


def _rate(s: Mapping[str, Any] | None) -> str:
    return pct(Estimate.of(s)) if s else "-"


def _cell(d: Mapping[str, float] | None) -> str:
    """A difference's cell; bold when it survives Holm's correction over the diagram."""
    text = diff(dict(d) if d is not None else None)
    return f"**{text}**" if d is not None and d.get("p_holm", 1.0) < 0.05 else text


def _values(values: Sequence[float]) -> str:
    return ", ".join(format_value(v) for v in values)


def markdown(
    phase: Phase,
    summary: Mapping[str, Any],
    params: Mapping[str, Any],
    failed: Sequence[TaskResult],
) -> str:
    """summary.md: the command, the declared grid, where each difference holds, per parameter."""
    names = list(summary["regions"])
    points = summary["points"]
    seeds = phase.seeds
    where = params.get("grid_file")
    setup = phase.setup
    signal = (
        "signal given: its correct responses given to every condition, so success measures "
        "the obstacle"
        if setup.signal == "given"
        else "signal learned"
    )
    lines = [
        "# srlab phase",
        "",
        f"`{params['command']}`",
        "",
        "## The grid, declared before running",
        "",
        (f"Declared in `{where}`" if where else "Declared on the command line")
        + (
            f" and run as a star around world `{setup.world_name}`"
            + (f" with {settings_text(setup.world_settings)}" if setup.world_settings else "")
            + " (camera stimuli "
            f"`{setup.sensors_name}`, {signal}): each parameter varied alone, the others at "
            "the base world's values; the base point is run once and belongs to every "
            f"parameter's row. {len(points)} points."
        ),
        "",
        *head(["parameter", "world setting", "unit", "base", "values", "what it is"]),
    ]
    for name, values in phase.axes:
        wp = get_world_parameter(name)
        lines.append(
            row([
                f"`{name}`", f"`{wp.path}`", wp.unit, format_value(phase.base_value(name)),
                _values([float(v) for v in values]), wp.parameter.description,
            ])
        )  # fmt: skip
    tuned = (
        "each with its tuned parameters (`core/data/tuned.toml`, tuned on the base world "
        "only: the same on every point)"
        if phase.tuned
        else "each with its default parameters"
    )
    lines += [
        "",
        f"On every point: `{REFLEXES}` (the sonar reflexes alone, world-check's (b)) and "
        + ", ".join(f"`{c}`" for c in phase.conditions)
        + f", on the same {len(seeds)} seeds ({seeds[0]}-{seeds[-1]}) x {phase.episodes} "
        f"episodes, {tuned}. {params['tasks']:,} tasks, {params['ticks']:,} ticks in "
        f"{params['elapsed_s']:.0f} s on {params['where']}.",
        "",
        f"Success: a seed's share of successful episodes over all {phase.episodes}, the "
        "mean over seeds with its 95% interval. A difference is paired by seed "
        "(on a point every condition meets the same obstacles and lamp cycles on a seed), "
        "in points, with its interval and the sign-flip test's p. The diagram is "
        f"exploratory: its {summary['tests']} (point, difference) tests were not declared "
        "one by one; **bold**: p < 0.05 after Holm's correction over all of them.",
        "",
        interval_line(),
        "",
        "## Where each difference holds",
        "",
        "![Each difference against the reflexes' success, per point](phase.png)",
        "",
        f"x: the success of `{REFLEXES}` on the point; y: the difference; bars: 95% "
        "intervals; one colour per parameter, its points joined in order of value (the value "
        "beside each), the base world a black star.",
        "",
        *head(["difference", *(label for _, label in SIGNS)]),
    ]
    for n in names:
        region = summary["regions"][n]
        lines.append(row([n, *(_region(region[sign], len(points)) for sign, _ in SIGNS)]))
    lines += ["", "## By parameter", ""]
    for name, _ in phase.axes:
        lines += _parameter_section(name, summary, names)
    lines += [
        "![Each difference against each parameter's value](phase_by_parameter.png)",
        "",
        "## Success per point",
        "",
        f"Over all {phase.episodes} episodes; obstacle collisions per episode of `{REFLEXES}` "
        "in the last column.",
        "",
        *head(["point", *phase.all_conditions, f"{REFLEXES}: obstacle collisions / episode"]),
    ]
    for p in points:
        conds = p["conditions"]
        hits = conds[REFLEXES].get("obstacle_collisions_per_episode")
        lines.append(
            row([
                p["label"], *(_rate(conds[c]["success_rate"]) for c in phase.all_conditions),
                "-" if not hits else f"{hits['mean']:.2f}",
            ])
        )  # fmt: skip
    if failed:
        lines += ["", *failed_lines(failed, params=True)]
    return "\n".join(lines) + "\n"


def _region(region: Mapping[str, Any], total: int) -> str:
    labels = region["points"]
    if not labels:
        return "nowhere"
    low, high = region["reflexes_low"], region["reflexes_high"]
    lo, hi = (f"{100 * x:.0f}" for x in (low, high)) if low is not None else ("", "")
    span = "" if low is None else f"reflexes {lo}%" if lo == hi else f"reflexes {lo}-{hi}%"
    if len(labels) == total:
        return f"every point ({span})"
    listed = ", ".join(labels) if len(labels) <= LISTED else ""
    text = f"{len(labels)} of {total} points ({span})"
    return f"{text}: {listed}" if listed else text


def _parameter_section(name: str, summary: Mapping[str, Any], names: Sequence[str]) -> list[str]:
    wp = get_world_parameter(name)
    axis = summary["axes"][name]
    points = summary["points"]
    lines = [
        f"### `{name}` ({wp.unit}): {wp.parameter.description}",
        "",
        *head([f"{name} ({wp.unit})", f"{REFLEXES}' success", *names]),
    ]
    for value, i in zip(axis["values"], axis["points"], strict=True):
        p = points[i]
        label = format_value(value) + (" (base)" if p["varies"] is None else "")
        lines.append(
            row([
                label, _rate(p["conditions"][REFLEXES]["success_rate"]),
                *(_cell(p["differences"][n]) for n in names),
            ])
        )  # fmt: skip
    lines += ["", "Where the sign changes, in order of value:", ""]
    for n in names:
        changes = axis["changes"][n]
        if not changes:
            signs = {sign_of(points[i]["differences"][n]) for i in axis["points"]}
            state = {"+": "interval above 0", "-": "interval below 0", "0": "interval covers 0"}
            what = (
                f"{state[next(iter(signs))]} at every value"
                if len(signs) == 1 and next(iter(signs)) in state
                else "no change"
            )
            lines.append(f"- {n}: no flip ({what}).")
            continue
        parts = [
            f"between {format_value(c['from'])} and {format_value(c['to'])}, from "
            f"{100 * c['mean_from']:+.1f} (interval {_word(c['sign_from'])}) to "
            f"{100 * c['mean_to']:+.1f} (interval {_word(c['sign_to'])})"
            f"{': the mean flips sign' if c['flips'] else ''}"
            for c in changes
        ]
        lines.append(f"- {n}: " + "; ".join(parts) + ".")
    return [*lines, ""]


def _word(sign: str) -> str:
    return {"+": "above 0", "-": "below 0", "0": "covers 0"}.get(sign, "undefined")


MARKERS = ("o", "s", "^", "D", "v", "P", "X", "<", ">")


def _point_xy(p: Mapping[str, Any], name: str) -> list[float]:
    """[x, x_low, x_high, y, y_low, y_high] in percent and points; NaN when undefined."""
    s = p["conditions"][REFLEXES].get("success_rate")
    d = p["differences"][name]
    nan = math.nan
    x = (nan, nan, nan) if not s else (s["mean"], s["low"], s["high"])
    y = (nan, nan, nan) if d is None else (d["mean"], d["low"], d["high"])
    return [100 * float(v) if v is not None else nan for v in (*x, *y)]


def _err(mean: Sequence[float], low: Sequence[float], high: Sequence[float]) -> FloatArray:
    """Error bars' lengths below and above each mean (none where undefined)."""
    m, lo, hi = (np.asarray(a, dtype=float) for a in (mean, low, high))
    out: FloatArray = np.nan_to_num(np.vstack([m - lo, hi - m]), nan=0.0)
    return out


LABEL_OFFSETS = ((5, 6, "left"), (5, 6, "left"), (-6, 0, "right"), (6, -7, "left"))
"""Where each parameter's value labels go (points, alignment): apart where points gather."""


def _labels(
    axis: Mapping[str, Any],
    points: Sequence[Mapping[str, Any]],
    x: Sequence[float],
    y: Sequence[float],
) -> list[tuple[tuple[float, float], str]]:
    """Each of a parameter's points off the base, labelled with its value.

    Points within a point of each other share one label (``0.5, 0.6``).
    """
    out: list[tuple[tuple[float, float], list[str]]] = []
    for value, xi, yi, i in zip(axis["values"], x, y, axis["points"], strict=True):
        if points[i]["varies"] is None or math.isnan(xi + yi):
            continue
        near = [o for o in out if abs(o[0][0] - xi) < 1.0 and abs(o[0][1] - yi) < 1.0]
        if near:
            near[0][1].append(format_value(value))
        else:
            out.append(((xi, yi), [format_value(value)]))
    return [(at, ", ".join(texts)) for at, texts in out]


def plot_phase(path: Path, phase: Phase, summary: Mapping[str, Any]) -> None:
    """Each difference against the reflexes' success, one panel per difference."""
    names = list(summary["regions"])
    points = summary["points"]
    cols = min(2, len(names))
    rows = math.ceil(len(names) / cols)
    fig, axes = subplots(cols, rows, figsize=(6.4 * cols, 4.8 * rows), sharex=True)
    palette = colours("tab10")
    for k, n in enumerate(names):
        ax = axes[k // cols][k % cols]
        ax.axhline(0.0, color="grey", linewidth=1)
        for j, (name, _) in enumerate(phase.axes):
            axis = summary["axes"][name]
            xy = [_point_xy(points[i], n) for i in axis["points"]]
            x, xl, xh, y, yl, yh = (list(c) for c in zip(*xy, strict=True))
            ax.errorbar(
                x, y, xerr=_err(x, xl, xh), yerr=_err(y, yl, yh), color=palette[j % len(palette)],
                marker=MARKERS[j % len(MARKERS)], markersize=5, capsize=2, linewidth=1,
                elinewidth=0.8, alpha=0.9,
                label=f"{name} ({get_world_parameter(name).unit})" if k == 0 else None,
            )  # fmt: skip
            dx, dy, align = LABEL_OFFSETS[j % len(LABEL_OFFSETS)]
            for (xi, yi), text in _labels(axis, points, x, y):
                ax.annotate(
                    text, (xi, yi), textcoords="offset points", xytext=(dx, dy),
                    ha=align, va="center", fontsize=7, color=palette[j % len(palette)],
                )  # fmt: skip
        base = _point_xy(points[0], n)
        ax.plot(
            base[0], base[3], marker="*", color="black", markersize=13, linestyle="none",
            zorder=5, label="base world" if k == 0 else None,
        )  # fmt: skip
        ax.set_title(n, fontsize=11)
        if k % cols == 0:
            ax.set_ylabel("success difference (points)")
        ax.set_xlim(-2, 102)
        ax.grid(alpha=0.3)
        if k // cols == rows - 1:
            ax.set_xlabel(f"success of {REFLEXES} (the sonar reflexes alone), %")
    for k in range(len(names), rows * cols):
        axes[k // cols][k % cols].set_visible(False)
    fig.legend(loc="lower center", ncol=len(phase.axes) + 1, fontsize=9, frameon=False)
    fig.suptitle(
        f"Where each difference holds: {len(phase.seeds)} seeds x {phase.episodes} episodes a "
        f"point, around world {phase.setup.world_name}; bars: 95% intervals",
        fontsize=11,
    )
    fig.tight_layout(rect=(0, 0.05, 1, 0.97))
    save(fig, path, layout=False)


def plot_by_parameter(path: Path, phase: Phase, summary: Mapping[str, Any]) -> None:
    """Each difference against each parameter's value, one panel per parameter."""
    names = list(summary["regions"])
    points = summary["points"]
    cols = min(2, len(phase.axes))
    rows = math.ceil(len(phase.axes) / cols)
    fig, axes = subplots(cols, rows, figsize=(6.4 * cols, 4.4 * rows))
    palette = colours("Dark2")
    for j, (name, _) in enumerate(phase.axes):
        ax = axes[j // cols][j % cols]
        axis = summary["axes"][name]
        values = axis["values"]
        ax.axhline(0.0, color="grey", linewidth=1)
        ax.axvline(axis["base"], color="black", linestyle=":", linewidth=1)
        for k, n in enumerate(names):
            y = [_point_xy(points[i], n)[3:] for i in axis["points"]]
            m, lo, hi = (list(c) for c in zip(*y, strict=True))
            ax.errorbar(
                values, m, yerr=_err(m, lo, hi), color=palette[k % len(palette)], marker="o",
                markersize=4, capsize=2, linewidth=1.2, label=n if j == 0 else None,
            )  # fmt: skip
        twin = ax.twinx()
        x = [_point_xy(points[i], names[0])[:3] for i in axis["points"]]
        twin.plot(
            values, [v[0] for v in x], color="grey", linestyle="--", marker=".",
            label=f"{REFLEXES}' success (right axis)" if j == 0 else None,
        )  # fmt: skip
        twin.set_ylim(-2, 102)
        twin.set_ylabel(f"{REFLEXES}' success, %", color="grey", fontsize=8)
        twin.tick_params(axis="y", colors="grey", labelsize=8)
        wp = get_world_parameter(name)
        ax.set_xlabel(f"{name} ({wp.unit}); dotted: the base world")
        ax.set_ylabel("difference (points)")
        ax.grid(alpha=0.3)
        if j == 0:
            handles, labels = ax.get_legend_handles_labels()
            h2, l2 = twin.get_legend_handles_labels()
            fig.legend(
                handles + h2, labels + l2, loc="lower center", ncol=len(names) + 1, fontsize=9,
                frameon=False,
            )  # fmt: skip
    for k in range(len(phase.axes), rows * cols):
        axes[k // cols][k % cols].set_visible(False)
    fig.suptitle("Each difference (bars: 95% intervals) along each parameter", fontsize=11)
    fig.tight_layout(rect=(0, 0.05, 1, 0.97))
    save(fig, path, layout=False)
