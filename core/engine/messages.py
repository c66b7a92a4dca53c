"""The closed set of messages between the service and the runs it hosts.

Nothing else crosses between the two, whether the runs tick in the service's process or
in a process of their own (`server.runtime`), so every message is a frozen value that
pickles as it is and no function ever travels:

- **commands** to one run (`InjectReward` and `EditAssociation` from `core.commands`, and
  the controls below), each applied by `perform` with the status check that goes with it;
- **queries** of one run, answered with values: `Latest` here, and those the service
  defines over the same `RunView` (the KP inspector), each a subclass of `Query`;
- **`RunState`**, published by the host after tick boundaries at a bounded rate, on every
  status change and before every answer, from which the service answers what a run is
  without asking it;
- the run's **events** (`core.events`, `core.engine.bus`), on subscriptions.
"""

from __future__ import annotations

import asyncio
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from core.commands import EditAssociation, InjectReward
from core.errors import RunStateError, SimulationStateError
from core.ports import Mode, RunStatus, RunTotals
from core.run.simulation import Snapshot

if TYPE_CHECKING:
    from core.engine.engine import RunEngine
    from core.engine.jobs import RewardAck
    from core.engine.view import RunView


@dataclass(frozen=True, slots=True)
class Pause:
    """Stop ticking at the next boundary until `Resume` (a running run only)."""


@dataclass(frozen=True, slots=True)
class Resume:
    """Tick again after a pause (a paused run only)."""


@dataclass(frozen=True, slots=True)
class Step:
    """Run exactly one tick of a paused realtime run; answered with the tick it ran."""


@dataclass(frozen=True, slots=True)
class Stop:
    """End the run at the boundary after its current tick (a running or paused run)."""


@dataclass(frozen=True, slots=True)
class SetRate:
    """A realtime run's tick rate from its next tick (a running or paused run)."""

    hz: float


@dataclass(frozen=True, slots=True)
class EditBatch:
    """Edits queued together, so that they land at one tick boundary, in order.

    Answered with each edit's log id, or the error that refused it, in order.
    """

    edits: tuple[EditAssociation, ...]


Command = InjectReward | EditAssociation | EditBatch | Pause | Resume | Step | Stop | SetRate
"""Every change the service can ask of a run."""

_ALLOWED: dict[type, tuple[RunStatus, ...]] = {
    Pause: (RunStatus.RUNNING,),
    Resume: (RunStatus.PAUSED,),
    Stop: (RunStatus.RUNNING, RunStatus.PAUSED),
    SetRate: (RunStatus.RUNNING, RunStatus.PAUSED),
}
"""The statuses a control applies in; in any other, `perform` refuses it."""


async def perform(
    engine: RunEngine, command: Command
) -> RewardAck | int | list[int | BaseException] | None:
    """Apply `command` to `engine`; its answer (`RunStateError` when the status forbids it).

    The status is checked and the control applied in one step of the engine's loop, so the
    run cannot change status in between.
    """
    allowed = _ALLOWED.get(type(command))
    if allowed is not None and engine.status not in allowed:
        raise RunStateError(f"run {engine.run_id} is {engine.status.value}")
    match command:
        case InjectReward():
            r = command
            return await engine.reward(
                r.value,
                note=r.note,
                source=r.source,
                uid=r.uid,
                tick_seen=r.tick_seen,
                seen_episode=r.seen_episode,
                records=r.records,
            )
        case EditAssociation():
            return await engine.edit(command)
        case EditBatch(edits=edits):
            return list(
                await asyncio.gather(*(engine.edit(e) for e in edits), return_exceptions=True)
            )
        case Step():
            return await engine.step()
        case Pause():
            engine.pause()
        case Resume():
            engine.resume()
        case Stop():
            engine.stop()
        case SetRate(hz=hz):
            if engine.spec.mode is not Mode.REALTIME:
                raise RunStateError(f"run {engine.run_id} is fast: it has no rate")
            engine.set_rate(hz)
    return None


class Query:
    """A read of one run, answered with a value: subclasses are frozen dataclasses."""


@dataclass(frozen=True, slots=True)
class Latest(Query):
    """The run's latest tick: its snapshot, the totals and whether KP released it.

    Answered with a `LatestTick`, or None before the run's first episode.
    """


@dataclass(frozen=True, slots=True)
class LatestTick:
    """A run's latest tick, as `Latest` answers it."""

    snapshot: Snapshot
    totals: RunTotals
    kp: bool


def latest(view: RunView) -> LatestTick | None:
    """`Latest`'s answer."""
    try:
        snap = view.snapshot
    except SimulationStateError:  # not reset yet
        return None
    return LatestTick(snap, view.totals, view.released_by_kp(snap))


@dataclass(frozen=True, slots=True)
class LiveFigures:
    """A ticking run's pacing and storage figures (NaN: nothing measured yet)."""

    ticks_run: int
    lateness_p99_s: float
    lateness_max_s: float
    overruns: int
    reward_ack_p99_s: float

    @classmethod
    def none(cls) -> LiveFigures:
        """Figures of a run that has not ticked here."""
        return cls(0, math.nan, math.nan, 0, math.nan)


@dataclass(frozen=True, slots=True)
class RunState:
    """What a hosted run is now, published by its host (see the module's docstring).

    `catalog_version` counts the brain's catalogues (KP's growth replaces the catalogue):
    the host sends the catalogue itself with the first state that names a new version.
    """

    run_id: int
    status: RunStatus
    error: str | None
    hz: float
    tick: int
    episode: int
    totals: RunTotals
    figures: LiveFigures
    ticks_by_origin: tuple[tuple[str, int], ...]
    catalog_version: int


def state_of(view: RunView, catalog_version: int) -> RunState:
    """A run's `RunState` from its view (on the engine's loop: one state of the run)."""
    stats = view.stats
    figures = LiveFigures(
        stats.ticks,
        stats.lateness_s.percentile(99),
        stats.lateness_s.max,
        stats.overruns,
        stats.reward_ack_s.percentile(99),
    )
    return RunState(
        view.run_id,
        view.status,
        view.error,
        view.hz,
        view.tick,
        view.episode,
        view.totals,
        figures,
        tuple(sorted(view.ticks_by_origin.items())),
        catalog_version,
    )


__all__ = [
    "Command",
    "EditBatch",
    "Latest",
    "LatestTick",
    "LiveFigures",
    "Pause",
    "Query",
    "Resume",
    "RunState",
    "SetRate",
    "Step",
    "Stop",
    "latest",
    "perform",
    "state_of",
]
