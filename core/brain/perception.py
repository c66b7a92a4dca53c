"""The perception module: stimulus recognition filters that weight each stimulus."""

from __future__ import annotations

from collections.abc import Mapping

from core.brain.catalog import Catalog


class Perception:
    """Weights each active stimulus by its logical sensor's filter: strength in [0, 1].

    Filters can be re-weighted per sensor (for example to deafen a noisy sensor), and a
    stimulus whose weight is 0 is filtered out entirely.
    """

    def __init__(self, catalog: Catalog, weights: Mapping[str, float] | None = None) -> None:
        by_sensor = {s.name: s.weight for s in catalog.sensors}
        for name, w in (weights or {}).items():
            if name not in by_sensor:
                raise ValueError(f"unknown logical sensor {name!r}")
            if not 0.0 <= w <= 1.0:
                raise ValueError(f"weight of {name!r} must be in [0, 1]")
            by_sensor[name] = w
        self.strength: tuple[float, ...] = tuple(by_sensor[s.sensor] for s in catalog.stimuli)

    def filter(self, active: list[int]) -> list[int]:
        """Drop the stimuli whose filter weight is zero."""
        strength = self.strength
        return [s for s in active if strength[s] > 0.0]
