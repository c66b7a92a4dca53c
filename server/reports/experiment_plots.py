"""The experiment's plots: learning curves, reliability beside Table III, knowledge over time."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import matplotlib.patches
import numpy as np

from core.brain.catalog import Catalog
from core.lab.stats import interval_name, mean_interval
from server.reports.experiment_markdown import camera_names
from server.reports.paper import PAPER_TABLE_III
from server.reports.plots import ROLLING, rolling_success, save, subplots, success_axes

CONDITION_COLOURS = {
    "innate": "#7f7f7f", "unaware": "#c7c7c7", "delayed": "#ff7f0e", "dp": "#2ca02c",
    "rp": "#d62728", "kp": "#1f3fb4", "sonar": "#8c564b", "reflexes": "#e377c2",
    "expert": "#000000", "qlambda": "#17becf", "qlambda-hybrid": "#9467bd",
    "dqn": "#bcbd22", "ppo": "#ff9896",
}  # fmt: skip
"""One colour per condition in every plot, so a condition is found at a glance."""
OUTSIDE_LEARNERS = ("qlambda", "qlambda-hybrid", "dqn", "ppo")
"""The baselines that learn through the Gymnasium environment, plotted in their own panel."""


def _rolling_curve(success_by_seed: list[list[int]]) -> tuple[Any, Any, Any]:
    """Per episode: the mean over seeds of the rolling success, and its 95% band."""
    rolled = rolling_success(success_by_seed)
    band = [mean_interval(rolled[:, i].tolist()) for i in range(rolled.shape[1])]
    low = np.array([b.low if not math.isnan(b.low) else b.mean for b in band])
    high = np.array([b.high if not math.isnan(b.high) else b.mean for b in band])
    return rolled.mean(axis=0), low, high


def plot_learning_curves(path: Path, summary: dict[str, Any]) -> None:
    """Success per episode (rolling mean over 5 episodes) over seeds, with its 95% band.

    With outside learners among the conditions, two panels: the architecture's conditions,
    and the baselines beside kp and its ablation.
    """
    ran = [n for n, s in summary.items() if s.get("seeds")]
    outside = [n for n in ran if n in OUTSIDE_LEARNERS]
    panels = [[n for n in ran if n not in OUTSIDE_LEARNERS]]
    if outside:
        panels.append([n for n in ran if n in ("kp", "sonar")] + outside)
    fig, axes = subplots(len(panels), figsize=(9 if len(panels) == 1 else 14, 5))
    titles = ["the architecture's conditions", "the baselines beside kp"]
    for ax, names, title in zip(axes[0], panels, titles, strict=False):
        for name in names:
            s = summary[name]
            y, low, high = _rolling_curve(s["success_by_seed"])
            x = np.arange(1, len(y) + 1)
            colour = CONDITION_COLOURS.get(name)
            (line,) = ax.plot(x, y, label=f"{name} (n={s['seeds']})", linewidth=1.8, color=colour)
            ax.fill_between(x, low, high, color=line.get_color(), alpha=0.15)
        success_axes(ax)
        ax.legend(loc="lower right", fontsize=8)
        if len(panels) > 1:
            ax.set_title(title, fontsize=10)
    axes[0][0].set_ylabel(f"success rate (rolling {ROLLING} episodes)")
    fig.suptitle(f"Learning curves: mean over seeds, band = {interval_name()}")
    save(fig, path)


def plot_reliability(
    path: Path,
    summary: dict[str, Any],
    catalog: Catalog,
    probe: dict[str, Any] | None = None,
) -> None:
    """Heatmaps like Table III: behaviours x camera obstacle stimuli, one per condition.

    The paper's Table III is drawn beside them, for DP, RP and KP; with a probe, the cells
    of correct responses are outlined.
    """
    learned = [n for n, s in summary.items() if s.get("seeds") and s.get("learns_camera")]
    stimuli = camera_names(catalog)
    behaviours = [b.name for b in catalog.behaviours]
    extra = sorted(
        {
            k.split("/", 1)[1]
            for n in learned
            for k in summary[n]["camera_reliability"]
            if k.split("/", 1)[1] not in behaviours
        }
    )
    behaviours += extra
    panels: list[tuple[str, np.ndarray[Any, Any]]] = []
    for name in learned:
        rel = summary[name]["camera_reliability"]
        grid = np.array(
            [[rel.get(f"{s}/{b}", {}).get("mean", 0.0) for s in stimuli] for b in behaviours]
        )
        panels.append((f"{name} ({summary[name]['camera_memory'].upper()})", grid))
    for cname in ("dp", "rp", "kp"):
        paper = np.array(
            [
                [PAPER_TABLE_III.get(s, {}).get(b, {}).get(cname, 0.0) for s in stimuli]
                for b in behaviours
            ]
        )
        panels.append((f"paper {cname.upper()}", paper))
    correct = {s: set(v["correct"]) for s, v in (probe or {}).get("stimuli", {}).items()}
    cols = len(panels)
    fig, axes = subplots(cols, figsize=(2.4 * cols + 2.5, 7.5), sharey=True)
    im = None
    for ax, (title, grid) in zip(axes[0], panels, strict=True):
        im = ax.imshow(grid, vmin=0, vmax=1, cmap="viridis", aspect="auto")
        ax.set_xticks(range(len(stimuli)), [s.removeprefix("Obstacle_") for s in stimuli])
        ax.tick_params(axis="x", labelrotation=90, labelsize=7)
        ax.set_title(title, fontsize=9)
        for i, j in zip(*np.nonzero(grid >= 0.05), strict=True):
            ax.text(j, i, f"{grid[i, j]:.2f}", ha="center", va="center", fontsize=5, color="w")
        if not title.startswith("paper"):
            for j, s in enumerate(stimuli):
                for i, b in enumerate(behaviours):
                    if b in correct.get(s, ()):
                        ax.add_patch(
                            matplotlib.patches.Rectangle(
                                (j - 0.5, i - 0.5), 1, 1, fill=False, edgecolor="#ff9f1c",
                                linewidth=0.8,
                            )
                        )  # fmt: skip
    axes[0][0].set_yticks(range(len(behaviours)), behaviours, fontsize=7)
    if im is not None:
        fig.colorbar(im, ax=axes[0].tolist(), shrink=0.6, label="reliability (mean over seeds)")
    meaning = "where in the view" if catalog.definition == "paper" else "obstacle side"
    outlined = "; outlined: correct by the placement probe" if correct else ""
    fig.suptitle(f"Reliability of camera obstacle S-R pairs (robot lane _ {meaning}){outlined}")
    save(fig, path, layout=False, bbox_inches="tight")


def plot_knowledge(path: Path, summary: dict[str, Any], stimuli: int = 3) -> None:
    """The knowledge criterion over episodes, for the camera stimuli met most.

    The share of seeds whose answer is correct and stays correct from that episode on.
    """
    judged = {n: s for n, s in summary.items() if s.get("correctness")}
    met: dict[str, float] = {}
    for s in judged.values():
        for stim, m in s.get("camera_stimuli_met", {}).items():
            met[stim] = met.get(stim, 0.0) + m["encounters_per_seed"]
    names = sorted(met, key=lambda k: -met[k])[:stimuli]
    fig, axes = subplots(max(1, len(names)), figsize=(4.2 * max(1, len(names)), 3.8), sharey=True)
    for ax, stim in zip(axes[0], names, strict=False):
        for name, s in judged.items():
            survival = s["correctness"]["criterion"].get(stim, {}).get("survival")
            if not survival:
                continue
            x = np.arange(1, len(survival) + 1)
            ax.step(x, 1.0 - np.asarray(survival), where="post", label=name, linewidth=1.6)
        ax.set_title(stim.removeprefix("Obstacle_"), fontsize=10)
        success_axes(ax, criterion=False)
    axes[0][0].set_ylabel("share of seeds correct from here on")
    axes[0][-1].legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    fig.suptitle("Knowledge criterion: the answer is correct and stays correct (probe)")
    save(fig, path, bbox_inches="tight")
