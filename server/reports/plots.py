"""What every report's plots share: matplotlib set up for files, success axes, saving.

Importing this module chooses matplotlib's file-only backend (Agg) before pyplot loads,
so a report never opens a window or needs a display.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import numpy.typing as npt
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from core.lab.analysis import CRITERION_RATE

ROLLING = 5
"""Episodes in the rolling mean of a learning curve."""


def subplots(cols: int, rows: int = 1, **kwargs: Any) -> tuple[Figure, Any]:
    """A figure of `rows` x `cols` panels (axes always 2-D: ``axes[row][col]``)."""
    fig, axes = plt.subplots(rows, cols, dpi=110, squeeze=False, **kwargs)
    return fig, axes


def colours(name: str = "tab10") -> tuple[Any, ...]:
    """A qualitative colour map's colours."""
    return tuple(matplotlib.colormaps[name].colors)  # type: ignore[attr-defined]


def save(fig: Figure, path: Path, *, layout: bool = True, bbox_inches: str | None = None) -> None:
    """Lay the figure out (unless `layout` is False), write it to `path` and free it."""
    if layout:
        fig.tight_layout()
    fig.savefig(path, bbox_inches=bbox_inches)
    plt.close(fig)


def rolling_success(success_by_seed: list[list[int]]) -> npt.NDArray[np.float64]:
    """Each seed's success per episode as a rolling mean over `ROLLING` episodes.

    The first episodes average over as many as there are so far.
    """
    runs = np.asarray(success_by_seed, dtype=float)
    kernel = np.ones(ROLLING)
    counts = np.convolve(np.ones(runs.shape[1]), kernel)[: runs.shape[1]]
    return np.array([np.convolve(r, kernel)[: len(r)] / counts for r in runs])


def success_axes(ax: Axes, *, xlabel: str = "episode", criterion: bool = True) -> None:
    """A success-rate panel: y in [0, 1], a light grid, and the success criterion's line."""
    ax.set_xlabel(xlabel)
    ax.set_ylim(-0.02, 1.02)
    if criterion:
        ax.axhline(CRITERION_RATE, color="grey", linestyle=":", linewidth=1)
    ax.grid(alpha=0.3)


def grouped_bars(
    ax: Axes,
    groups: Sequence[str],
    series: Sequence[tuple[str, str, Sequence[Mapping[str, float] | None]]],
    *,
    scale: float = 1.0,
) -> None:
    """One bar per group and series, each with its 95% interval, the series side by side.

    `series` are (label, colour, a figure per group with ``mean``, ``low`` and ``high``;
    None or NaN: no bar); the figures are multiplied by `scale` (100: rates in points).
    """
    x = np.arange(len(groups), dtype=float)
    width = 0.76 / len(series)
    for i, (name, colour, stats) in enumerate(series):
        figs = [s or {} for s in stats]
        y = scale * np.array([s.get("mean", math.nan) for s in figs])
        low = scale * np.array([s.get("low", math.nan) for s in figs])
        high = scale * np.array([s.get("high", math.nan) for s in figs])
        err = np.nan_to_num(np.array([y - low, high - y]))
        offset = (i - (len(series) - 1) / 2) * width
        ax.bar(x + offset, y, width, yerr=err, capsize=3, color=colour, label=name)
    ax.set_xticks(x, list(groups))
