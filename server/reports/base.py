"""What every report writes alike: figures with their intervals, markdown tables, JSON files.

Nothing here imports matplotlib (`server.reports.plots` does), so a command that only
formats figures or writes JSON starts without it.
"""

from __future__ import annotations

import json
import math
import resource
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from core.lab.stats import Estimate, interval_name
from core.lab.stats import pct as stats_pct
from core.params import point_label

if TYPE_CHECKING:
    from core.lab.experiment import TaskResult
    from core.run.setup import Setup


def fmt(stat: dict[str, float], pct: bool = False, digits: int = 2) -> str:
    """A figure over seeds with its interval: a rate as ``5% [0, 15]``, else ``0.12 ± 0.03``.

    A rate's interval is the summary's (`core.lab.stats.mean_interval`, within the values'
    range, so within [0, 1]; clipped there all the same) when it has one: a mean ± Student's
    t half-width alone ran past 0% and 100% with few seeds ("5% ± 64%").
    """
    mean, ci = stat.get("mean", math.nan), stat.get("ci95", math.nan)
    if mean is None or math.isnan(mean):
        return "-"
    if pct:
        low, high = stat.get("low", math.nan), stat.get("high", math.nan)
        if math.isnan(low) or math.isnan(high):
            return f"{mean:.0%}"
        return stats_pct(Estimate(mean, max(0.0, low), min(1.0, high), int(stat.get("n", 0))))
    return f"{mean:.{digits}f} ± {ci:.{digits}f}" if not math.isnan(ci) else f"{mean:.{digits}f}"


def interval_line() -> str:
    """What every summary's intervals are, and why that method (its header states it)."""
    return (
        f"Intervals: the {interval_name()}, clipped to the values' range: it covers the "
        "true mean 93-97% of the time on synthetic samples shaped like srlab's at 20 and "
        "40 seeds, where the percentile bootstrap covers 92-93% at 20 "
        "(`tests/core/lab/test_stats.py`)."
    )


def cpu_seconds() -> float:
    """CPU time of this process and its waited-for children (a study's workers), in seconds.

    A study's cost beside its wall time: on a shared machine the wall time depends on
    what else runs, the CPU time much less.
    """
    own, kids = (resource.getrusage(w) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def diff(d: dict[str, float] | None) -> str:
    """A paired difference in points with its interval and p."""
    if d is None:
        return "-"
    p = d["p"]
    ptxt = "p < 0.001" if p < 0.001 else f"p {p:.3f}"
    return f"{100 * d['mean']:+.1f} [{100 * d['low']:+.1f}, {100 * d['high']:+.1f}], {ptxt}"


def row(cells: Iterable[str]) -> str:
    """A markdown table's row."""
    return "| " + " | ".join(cells) + " |"


def head(cells: Sequence[str]) -> list[str]:
    """A markdown table's header row and the line under it."""
    return [row(cells), "|---" * len(cells) + "|"]


def setup_params(setup: Setup) -> dict[str, str]:
    """The setup as a report's parameters (its start and network only when chosen)."""
    params = {"world": setup.world_name, "sensors": setup.sensors_name, "signal": setup.signal}
    if setup.world_settings:
        params["world_settings"] = settings_text(setup.world_settings)
    if setup.network:
        params["network"] = setup.network
    return params | ({"start": setup.start} if setup.start else {})


def settings_text(settings: Sequence[tuple[str, float]]) -> str:
    """World settings in words: ``perception.camera_miss_rate 0.2, ...``."""
    return ", ".join(f"{path} {value:g}" for path, value in settings)


def first_line(error: str | None) -> str:
    """The first line of a failed task's error (its traceback follows)."""
    return (error or "").splitlines()[0]


def failed_lines(failed: Sequence[TaskResult], *, params: bool = False) -> list[str]:
    """The summary's section on the tasks that failed, each with its error's first line.

    With `params`, each task's parameters follow its seed (a sweep's tasks differ by them).
    """
    lines = ["## Failed tasks", ""]
    for r in failed:
        where = point_label(dict(r.task.params)) if params else ""
        task = f"{r.task.condition} seed {r.task.seed}{' ' + where if where else ''}"
        lines.append(f"- {task}: {first_line(r.error)}")
    return lines


def clean_json(value: Any) -> Any:
    """JSON has no NaN: undefined figures (a CI over one seed) become null."""
    if isinstance(value, float) and math.isnan(value):
        return None
    if isinstance(value, dict):
        return {k: clean_json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [clean_json(v) for v in value]
    return value


def write_runs(path: Path, results: Sequence[TaskResult], *, params: bool = False) -> None:
    """Every episode of every task, one JSON object a line; with `params`, the task's too.

    A task run with world settings (a phase diagram's point) carries them.
    """
    with path.open("w", encoding="utf-8") as f:
        for r in results:
            for e in r.episodes:
                line: dict[str, Any] = {"condition": r.task.condition}
                if params:
                    line["params"] = dict(r.task.params)
                if r.task.setup.world_settings:
                    line["world_settings"] = dict(r.task.setup.world_settings)
                line |= {
                    "seed": r.task.seed,
                    "episode": e.episode,
                    "outcome": e.outcome.value,
                    "cause": e.cause.value if e.cause else None,
                    "ticks": e.ticks,
                    "rewards": e.rewards,
                }
                f.write(json.dumps(line) + "\n")


def write_summary(
    out: Path,
    doc: dict[str, Any],
    markdown: str,
    results: Sequence[TaskResult],
    *,
    params: bool = False,
) -> list[Path]:
    """summary.json (`doc`), summary.md and runs.jsonl into `out`; returns their paths."""
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / n for n in ("summary.json", "summary.md", "runs.jsonl")]
    paths[0].write_text(json.dumps(clean_json(doc), indent=2, allow_nan=False) + "\n")
    paths[1].write_text(markdown)
    write_runs(paths[2], results, params=params)
    return paths


HEAVY = (
    "success_curve",
    "success_curve_ci95",
    "success_by_seed",
    "correctness",
    "camera_reliability",
)
"""A cell's per-episode and per-pair figures, left out of a study's summary.json (an
experiment's report keeps them: `srlab equal-start` writes one per start)."""


def study_document(
    params: dict[str, Any], summary: dict[str, Any], results: Sequence[TaskResult]
) -> dict[str, Any]:
    """A study's summary.json: its parameters, its figures, each cell's, and what failed."""
    return {
        "params": params,
        **{k: v for k, v in summary.items() if k != "cells"},
        "cells": {
            name: {k: v for k, v in s.items() if k not in HEAVY}
            for name, s in summary["cells"].items()
        },
        "failed": [
            {"condition": r.task.condition, "params": dict(r.task.params),
             "start": r.task.setup.start, "seed": r.task.seed, "error": r.error}
            for r in results
            if not r.ok
        ],
    }  # fmt: skip
