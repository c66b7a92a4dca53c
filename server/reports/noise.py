"""`srlab noise` outputs: the study's summary and plot, and an experiment report per perception."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from core.brain.catalog import Catalog
from core.lab.experiment import TaskResult
from core.lab.noise import PERCEPTIONS, NoiseStudy, label
from core.sim.worlds import PERCEPTION_PREFIX
from server.reports.base import (
    diff,
    failed_lines,
    fmt,
    head,
    interval_line,
    row,
    settings_text,
)
from server.reports.declared import declared_section
from server.reports.plots import grouped_bars, save, subplots, success_axes
from server.reports.study import Part, write_study

MEASURES = (("all", "training, all episodes"), ("held-out", "held-out, frozen"))
"""The figures the study reports: the paired comparisons' keys and their titles."""
FIGURE_OF = {"all": "success_rate", "held-out": "held_out"}
COLOURS = {"exact": "#bbbbbb", "noisy": "#d95f02"}


def plot_noise(path: Path, study: NoiseStudy, summary: dict[str, Any]) -> None:
    """Each condition's success both ways, and the reference's lead both ways (95% intervals)."""
    fig, axes = subplots(len(MEASURES), 2, figsize=(12, 8.4))
    conditions = list(study.conditions)
    others = [c for c in conditions if c != study.reference]
    for col, (measure, title) in enumerate(MEASURES):
        top, bottom = axes[0][col], axes[1][col]
        grouped_bars(
            top,
            conditions,
            [
                (p, COLOURS[p], [summary["grid"][c][p][FIGURE_OF[measure]] for c in conditions])
                for p in PERCEPTIONS
            ],
        )
        success_axes(top, xlabel="", criterion=False)
        top.set_title(f"success, {title}", fontsize=10)
        grouped_bars(
            bottom,
            [f"{study.reference} - {c}" for c in others],
            [
                (p, COLOURS[p], [summary["lead"][p][c].get(measure) for c in others])
                for p in PERCEPTIONS
            ],
            scale=100,
        )
        bottom.axhline(0, color="grey", linewidth=1)
        bottom.grid(alpha=0.3)
        bottom.set_title(f"{study.reference}'s lead, {title}", fontsize=10)
    axes[0][0].set_ylabel("success rate (mean over seeds)")
    axes[1][0].set_ylabel("difference, points (paired by seed)")
    axes[0][0].legend(fontsize=8, loc="upper right", title="perception")
    noise = ", ".join(f"{path.removeprefix(PERCEPTION_PREFIX)} {v:g}" for path, v in study.noise)
    fig.suptitle(
        f"Every condition with exact and with noisy perception, on the same seeds\n(noisy: "
        f"{noise}); bars: 95% Student's t intervals",
        fontsize=10,
    )
    save(fig, path)


def summary_markdown(
    study: NoiseStudy,
    summary: dict[str, Any],
    params: dict[str, Any],
    failed: Sequence[TaskResult],
) -> str:
    """Each condition both ways, the reference's leads both ways, and what noise moves."""
    ref = study.reference
    others = [c for c in study.conditions if c != ref]
    grid_columns = ["condition"]
    for p in PERCEPTIONS:
        grid_columns += [f"{p}: 1-10", "training", "held-out"]
    grid_columns += ["noisy - exact, training", "held-out"]
    lines = [
        "# srlab noise",
        "",
        f"`{params['command']}`",
        "",
        f"{params['seeds']} seeds x {params['episodes']} episodes per cell, then "
        f"{params['eval_episodes']} held-out episodes frozen; {params['tasks']} tasks, "
        f"{params['ticks']:,} ticks in {params['elapsed_s']:.1f} s on {params['where']}. "
        f"World `{params['world']}`"
        + (f" with {params['world_settings']}" if params.get("world_settings") else "")
        + f", camera stimuli `{params['sensors']}`, signal {params['signal']}; every condition "
        "with its tuned parameters, the same both ways"
        + (" (none: --untuned)." if not study.tuned else "."),
        "",
        f"Every condition runs twice on each seed: with **exact** perception (every stimulus "
        f"from the true pose and obstacle) and with **noisy** perception "
        f"({settings_text(study.noise)}: `core/sim/perception.py`), every stimulus computed "
        "from the camera's and the odometry's estimates. The noise draws from a stream of its "
        "own, so on a seed both meet the same obstacles and lamp cycles. Success is the mean "
        "over seeds [95% Student's t interval]; differences are paired by seed, in points, "
        "with the sign-flip test's p.",
        "",
        interval_line(),
        "",
        *declared_section(
            summary["declared"],
            f"{ref} minus each other condition with noisy perception, in training and held out",
        ),
        "## Success, exact and noisy",
        "",
        "What the noise costs each condition: noisy minus exact, seed by seed (exploratory).",
        "",
        *head(grid_columns),
    ]
    for c, g in summary["grid"].items():
        cells = [c]
        for p in PERCEPTIONS:
            cells += [
                fmt(g[p][k] or {}, pct=True) for k in ("success_1_10", "success_rate", "held_out")
            ]
        cells += [diff(g["noise_effect"].get(k)) for k, _ in MEASURES]
        lines.append(row(cells))
    lines += [
        "",
        "![Each condition exact and noisy, and the reference's lead](noise.png)",
        "",
        f"## {ref}'s lead over each, exact and noisy",
        "",
        f"{ref} minus each condition under each perception, and how much the noise moves "
        f"that lead: each seed's lead with noise minus its own lead without (exploratory; "
        "the declared comparisons above are the findings).",
        "",
    ]
    for measure, title in MEASURES:
        lines += [
            f"{title.capitalize()}:",
            "",
            *head(["condition", "exact", "noisy", "noisy - exact (the change of the lead)"]),
        ]
        for c in others:
            lines.append(
                row(
                    [
                        f"{ref} - {c}",
                        *(diff(summary["lead"][p][c].get(measure)) for p in PERCEPTIONS),
                        diff(summary["change"][c].get(measure)),
                    ]
                )
            )
        lines.append("")
    lines += [
        "Each perception's full experiment report (learning curves, what was learned judged "
        "by the probe in the exact world, every pair): [exact](exact/summary.md), "
        "[noisy](noisy/summary.md).",
        "",
    ]
    if failed:
        lines += failed_lines(failed)
    return "\n".join(lines).rstrip() + "\n"


def write_noise_report(
    out: Path,
    study: NoiseStudy,
    results: Sequence[TaskResult],
    summary: dict[str, Any],
    catalog: Catalog,
    params: dict[str, Any],
) -> list[Path]:
    """Write the study's summary and plot into `out`, and each perception's report beneath."""
    parts = []
    for p in PERCEPTIONS:
        setup = study.perception_setup(p)
        part_params = {k: v for k, v in params.items() if k != "world_settings"}
        if setup.world_settings:
            part_params["world_settings"] = settings_text(setup.world_settings)
        parts.append(
            Part(
                p,
                [r for r in results if r.task.setup == setup],
                {c: summary["cells"][label(c, p)] for c in study.conditions},
                part_params,
                f"srlab noise: every condition with {p} perception",
            )
        )
    return write_study(
        out,
        params,
        summary,
        results,
        lambda failed: summary_markdown(study, summary, params, failed),
        ("noise.png", lambda path: plot_noise(path, study, summary)),
        catalog,
        parts,
    )
