"""What a query reads of a live run: `RunView`, a read-only window on one engine.

The service reads a run through the queries its host answers on this view and through the
`RunState` built from it (`core.engine.messages`), and controls it through commands; none
reaches into the simulation. A view reads the live state, not a copy: read it on the
engine's event loop, where the tick and reward tasks change that state only between awaits,
so what is read between two awaits is one consistent state.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol

from core.brain.catalog import Catalog
from core.brain.network import BehaviourNetwork
from core.brain.propagation import KnowledgePropagation
from core.brain.selection import Selector
from core.engine.bus import EventBus
from core.engine.stats import EngineStats
from core.ports import RunSpec, RunStatus, RunTotals
from core.run.simulation import Simulation, Snapshot
from core.sim.world import WorldConfig


class Viewed(Protocol):
    """What a view reads of an engine (`core.engine.engine.RunEngine` is one)."""

    @property
    def run_id(self) -> int:
        """The run's id."""
        ...

    @property
    def spec(self) -> RunSpec:
        """What the run was started with."""
        ...

    @property
    def status(self) -> RunStatus:
        """The run's status."""
        ...

    @property
    def error(self) -> str | None:
        """Why it failed (None: it has not)."""
        ...

    @property
    def hz(self) -> float:
        """The realtime tick rate."""
        ...

    @property
    def totals(self) -> RunTotals:
        """Episodes, successes and ticks so far."""
        ...

    @property
    def stats(self) -> EngineStats:
        """Pacing and storage figures."""
        ...

    @property
    def sim(self) -> Simulation:
        """The run's simulation."""
        ...

    @property
    def bus(self) -> EventBus:
        """The run's subscriptions."""
        ...


class RunView:
    """A read-only window on a running engine (see the module's docstring)."""

    __slots__ = ("_engine",)

    def __init__(self, engine: Viewed) -> None:
        self._engine = engine

    @property
    def run_id(self) -> int:
        """The run's id."""
        return self._engine.run_id

    @property
    def spec(self) -> RunSpec:
        """What the run was created with (its mode as it runs now)."""
        return self._engine.spec

    @property
    def status(self) -> RunStatus:
        """The run's status."""
        return self._engine.status

    @property
    def error(self) -> str | None:
        """Why the run failed (None: it has not)."""
        return self._engine.error

    @property
    def hz(self) -> float:
        """The realtime tick rate."""
        return self._engine.hz

    @property
    def totals(self) -> RunTotals:
        """Episodes, successes and ticks so far."""
        return self._engine.totals

    @property
    def stats(self) -> EngineStats:
        """Pacing and storage figures."""
        return self._engine.stats

    @property
    def tick(self) -> int:
        """Ticks run so far."""
        return self._engine.sim.tick_count

    @property
    def episode(self) -> int:
        """The current episode's number (0: none started yet)."""
        return max(self._engine.sim.episode, 0)

    @property
    def ticks_by_origin(self) -> Mapping[str, int]:
        """Ticks so far by what made the behaviour run (a copy)."""
        return dict(self._engine.sim.ticks_by_origin)

    @property
    def snapshot(self) -> Snapshot:
        """The latest tick's snapshot (`SimulationStateError` before the first episode)."""
        return self._engine.sim.snapshot

    @property
    def world_config(self) -> WorldConfig:
        """The world the run ticks in."""
        return self._engine.sim.world.config

    @property
    def catalog(self) -> Catalog:
        """The brain's catalogue of now: it grows when KP synthesises a behaviour."""
        return self._engine.sim.brain.catalog

    @property
    def network(self) -> BehaviourNetwork:
        """The behaviour network the robot runs (read it, change it with `RunEngine.edit`)."""
        return self._engine.sim.brain.network

    @property
    def selector(self) -> Selector:
        """The behaviour selection, for the competition among released behaviours."""
        return self._engine.sim.brain.selector

    @property
    def kp(self) -> KnowledgePropagation | None:
        """Knowledge propagation's state (None: the condition does not propagate)."""
        return self._engine.sim.brain.kp

    def released_by_kp(self, snap: Snapshot) -> bool:
        """Whether `snap`'s behaviour was released through an association KP taught."""
        return released_by_kp(self._engine.sim.brain.network, snap)

    @property
    def tick_watchers(self) -> int:
        """How many subscriptions take tick snapshots (0: a tick publishes nothing)."""
        return self._engine.bus.tick_subscribers


def released_by_kp(network: BehaviourNetwork, snap: Snapshot) -> bool:
    """Whether `snap`'s behaviour was released through an association of `network` KP taught."""
    if snap.how.value != "released":
        return False
    b = snap.behaviour
    for s in snap.stimuli:
        a = network.get(s, b)
        if a is not None and a.source == "kp":
            return True
    return False
