"""Experiment outputs: summary.json, summary.md, runs.jsonl and the plots."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from core.brain.catalog import Catalog
from core.lab.analysis import DECLARED, declared_comparisons, paired_table
from core.lab.experiment import TaskResult
from server.reports.base import write_summary
from server.reports.experiment_markdown import summary_markdown
from server.reports.experiment_plots import plot_knowledge, plot_learning_curves, plot_reliability


def write_report(
    out: Path,
    results: Sequence[TaskResult],
    summary: dict[str, Any],
    catalog: Catalog,
    params: dict[str, Any],
    title: str = "srlab experiment",
) -> list[Path]:
    """Write every output file into `out` (summary.md under `title`); returns their paths."""
    failed = [r for r in results if not r.ok]
    doc = {
        "params": params,
        "conditions": {
            n: {
                k: v
                for k, v in s.items()
                if k not in ("success_curve_ci95", "success_by_seed", "seed_ids")
            }
            for n, s in summary.items()
        },
        "failed": [
            {"condition": r.task.condition, "seed": r.task.seed, "error": r.error} for r in failed
        ],
    }
    doc["paired"] = paired_table(summary)
    pairs = [(str(a), str(b)) for a, b in params.get("declared") or DECLARED]
    declared = declared_comparisons(summary, pairs)
    doc["declared"] = declared
    markdown = summary_markdown(summary, catalog, params, failed, declared, title)
    paths = write_summary(out, doc, markdown, results)
    curves = out / "learning_curves.png"
    plot_learning_curves(curves, summary)
    reliability = out / "reliability.png"
    plot_reliability(reliability, summary, catalog, params.get("probe"))
    written = [*paths, curves, reliability]
    if any(s.get("correctness") for s in summary.values()):
        knowledge = out / "knowledge.png"
        plot_knowledge(knowledge, summary)
        written.append(knowledge)
    return written
