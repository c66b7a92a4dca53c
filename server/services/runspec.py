"""The one place the server builds a `RunSpec`: from a request, the command line or a row."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from core.ports import Mode, RunSpec


def run_spec(
    *,
    condition: str,
    seed: int,
    episodes: int | None,
    mode: str,
    hz: float,
    network: str | None = None,
    params: Mapping[str, Any] | None = None,
    world: str | None = None,
    sensors: str | None = None,
    network_id: int | None = None,
) -> RunSpec:
    """A run's spec: `mode` parsed, `params` copied, no world or sensors ("") the defaults."""
    return RunSpec(
        condition=condition,
        seed=seed,
        episodes=episodes,
        mode=Mode(mode),
        hz=hz,
        network=network,
        params=dict(params or {}),
        world=world or "",
        sensors=sensors or "",
        network_id=network_id,
    )
