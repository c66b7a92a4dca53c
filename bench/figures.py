"""Figures the benchmarks share: percentiles read as the engine's histograms read them, ms."""

from __future__ import annotations

import math
from typing import Any


def percentile(values: list[float], q: float) -> float:
    """The q-th percentile (nearest rank, as the engine's), nan if none."""
    if not values:
        return math.nan
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, max(0, math.ceil(q / 100 * len(ordered)) - 1))]


def ms(x: float | None, width: int = 8) -> str:
    """Seconds in milliseconds, right-aligned in `width`; a dash for none."""
    if x is None or math.isnan(x):
        return f"{'-':>{width}}   "
    return f"{x * 1000:{width}.2f} ms"


def live_ms(live: dict[str, Any] | None, key: str) -> float | None:
    """A figure of a run's live dict (GET /api/runs/{id}'s ``live``) in seconds, from ms."""
    value = None if live is None else live.get(key)
    return None if value is None else float(value) / 1000
