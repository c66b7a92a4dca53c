"""What a study of cells writes: its summary and plot, and an experiment report per part.

A study runs cells (`core.lab.cells`); its summary compares them, and each part of it (the
cells from one start, or sensing one way) is also an experiment of its own, reported as
`srlab experiment` reports one in a folder beneath the study's.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from core.brain.catalog import Catalog
from core.lab.experiment import TaskResult
from server.reports.base import study_document, write_summary
from server.reports.experiment import write_report


@dataclass(frozen=True, slots=True)
class Part:
    """A part of a study reported as an experiment in the folder `name` beneath it.

    Attributes:
        name: its folder.
        results: its tasks' results.
        summary: its conditions' summaries, by condition (as `core.lab.analysis.summarise`).
        params: its report's parameters.
        title: its summary's title.
    """

    name: str
    results: Sequence[TaskResult]
    summary: dict[str, Any]
    params: dict[str, Any]
    title: str


def write_study(
    out: Path,
    params: dict[str, Any],
    summary: dict[str, Any],
    results: Sequence[TaskResult],
    markdown: Callable[[Sequence[TaskResult]], str],
    plot: tuple[str, Callable[[Path], None]],
    catalog: Catalog,
    parts: Sequence[Part],
) -> list[Path]:
    """Write a study into `out`, then each part's report beneath it; returns the paths.

    Into `out`: summary.json, summary.md (`markdown` of the failed tasks), runs.jsonl and
    the plot (`plot`: its file's name, and what draws it there).
    """
    failed = [r for r in results if not r.ok]
    doc = study_document(params, summary, results)
    paths = write_summary(out, doc, markdown(failed), results)
    name, draw = plot
    draw(out / name)
    paths.append(out / name)
    for part in parts:
        paths += write_report(
            out / part.name, part.results, part.summary, catalog, part.params, part.title
        )
    return paths
