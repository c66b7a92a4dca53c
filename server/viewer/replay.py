"""Replay of stored episodes: loading one from the database and the playback clock."""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace

from core.brain.catalog import Catalog
from core.errors import UnknownNameError
from core.ports import NetworkPair, RunQueries
from core.run.trace import TraceRow, unpack
from core.sim.types import build_geometry
from core.sim.world import EpisodeLayout, LampColor, WorldConfig, episode_layout
from core.sim.worlds import load_world
from server.viewer.scene import TickView

log = logging.getLogger("srlab.viewer")

SPEEDS: tuple[float, ...] = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0)
"""Playback speeds the panel offers, as multiples of the recorded time."""


def run_world(name: str) -> WorldConfig:
    """The world of a run's preset (`name` "" for the default: a run stored before runs kept it).

    A preset since removed from the data shows as the default world.
    """
    try:
        return load_world(name or None).config
    except UnknownNameError:
        log.warning("the world preset %r is gone: the 3D view draws the default world", name)
        return load_world().config


@dataclass(frozen=True, slots=True)
class ReplayClock:
    """Where playback stands: a tick index that advances with time while playing.

    Immutable: every control returns a new clock anchored at `now` (seconds, any
    monotonic clock), so the index at any later time is `at(now)`.

    Attributes:
        ticks: how many ticks the episode has (the index runs 0..ticks-1).
        dt_s: recorded seconds per tick.
        anchor_index: the (fractional) index at `anchor_s`.
        anchor_s: when the clock was last changed.
        speed: playback speed (1.0: as recorded).
        playing: whether the index advances.
    """

    ticks: int
    dt_s: float = 0.1
    anchor_index: float = 0.0
    anchor_s: float = 0.0
    speed: float = 1.0
    playing: bool = False

    def __post_init__(self) -> None:
        if self.ticks < 1:
            raise ValueError("an episode to replay has at least one tick")
        if not (self.speed > 0 and math.isfinite(self.speed)):
            raise ValueError("the playback speed must be positive")

    def position(self, now: float) -> float:
        """The fractional index at `now`, clamped to the episode."""
        p = self.anchor_index
        if self.playing:
            p += (now - self.anchor_s) * self.speed / self.dt_s
        return min(max(p, 0.0), float(self.ticks - 1))

    def at(self, now: float) -> int:
        """The tick index shown at `now`."""
        return int(self.position(now))

    def finished(self, now: float) -> bool:
        """Whether playback reached the last tick."""
        return self.position(now) >= self.ticks - 1

    def play(self, now: float) -> ReplayClock:
        """Start (again from the beginning when at the end)."""
        start = 0.0 if self.finished(now) else self.position(now)
        return replace(self, anchor_index=start, anchor_s=now, playing=True)

    def pause(self, now: float) -> ReplayClock:
        """Hold the current tick."""
        return replace(self, anchor_index=float(self.at(now)), anchor_s=now, playing=False)

    def seek(self, index: int, now: float) -> ReplayClock:
        """Jump to a tick (clamped), playing on if it was playing."""
        i = min(max(index, 0), self.ticks - 1)
        return replace(self, anchor_index=float(i), anchor_s=now)

    def with_speed(self, speed: float, now: float) -> ReplayClock:
        """Change speed without a jump."""
        return replace(self, anchor_index=self.position(now), anchor_s=now, speed=speed)

    def settle(self, now: float) -> ReplayClock:
        """Stop playing once the end is reached (so the panel shows play, not pause)."""
        if self.playing and self.finished(now):
            return replace(self, anchor_index=float(self.ticks - 1), anchor_s=now, playing=False)
        return self


@dataclass(frozen=True, slots=True)
class Replay:
    """A stored episode ready to show: its ticks as views and its layout."""

    run_id: int
    episode: int
    outcome: str
    cause: str | None
    views: tuple[TickView, ...]
    layout: EpisodeLayout
    world: WorldConfig = field(default_factory=WorldConfig)
    """The world the run ran in (its preset)."""

    @property
    def ticks(self) -> int:
        """How many ticks it has."""
        return len(self.views)

    def heading(self) -> str:
        """The panel's title line for this replay."""
        cause = f", {self.cause.replace('_', ' ')}" if self.cause else ""
        return (
            f"**Replay** of run {self.run_id}, episode {self.episode}: "
            f"{self.outcome}{cause}, {self.ticks} ticks"
        )


def replay_views(
    run_id: int,
    episode: int,
    rows: list[TraceRow],
    stimuli: list[str],
    behaviours: list[str],
    kp_pairs: set[tuple[str, str]],
) -> tuple[TickView, ...]:
    """The views of a trace's rows, with names and the KP flag resolved."""
    views = []
    start = rows[0].tick - 1 if rows else 0
    for r in rows:
        names = tuple(stimuli[i] for i in r.stimuli if i < len(stimuli))
        b = behaviours[r.behaviour] if 0 <= r.behaviour < len(behaviours) else None
        kp = r.how == "released" and b is not None and any((s, b) in kp_pairs for s in names)
        views.append(
            TickView(
                run_id=run_id,
                episode=episode,
                tick=r.tick,
                episode_tick=r.tick - start,
                x=r.x,
                y=r.y,
                heading_rad=r.heading_rad,
                lamp=LampColor(r.lamp),
                stimuli=names,
                behaviour=b,
                how=r.how,
                kp=kp,
                origin=r.origin,
                released_by=(stimuli[r.released_by] if 0 <= r.released_by < len(stimuli) else None),
            )
        )
    return tuple(views)


def kp_pairs(network: tuple[NetworkPair, ...]) -> set[tuple[str, str]]:
    """The (stimulus, behaviour) associations knowledge propagation made."""
    return {(p.stimulus, p.behaviour) for p in network if p.source == "kp"}


def load_replay(
    store: RunQueries,
    catalog: Catalog,
    run_id: int,
    episode: int,
    world: WorldConfig | None = None,
) -> Replay:
    """A stored episode of a run (blocking: call it from a worker thread).

    The obstacle's place comes from the run's seed and the episode's number, as the world
    drew it: the run's world preset, unless `world` is given. KP-made associations are
    those of the run's network as stored now.

    Raises:
        UnknownRunError: no such run.
        LookupError: the run has no such episode, or it was stored without a trace.
    """
    run = store.load_run(run_id)
    record = store.episode(run_id, episode)
    if record is None:
        raise LookupError(f"run {run_id} has no episode {episode}")
    if not record.trace:
        raise LookupError(f"episode {episode} of run {run_id} was stored without a trace")
    rows = unpack(record.trace)
    if not rows:
        raise LookupError(f"episode {episode} of run {run_id} has an empty trace")
    world = world or run_world(run.spec.world)
    layout = episode_layout(world, build_geometry(world.track), run.spec.seed, episode)
    stimuli = [s.name for s in catalog.stimuli]
    behaviours = [b.name for b in catalog.behaviours] + [b.name for b in store.behaviours(run_id)]
    views = replay_views(
        run_id, episode, rows, stimuli, behaviours, kp_pairs(store.network(run_id))
    )
    return Replay(run_id, episode, record.outcome, record.cause, views, layout, world)


__all__ = [
    "SPEEDS",
    "Replay",
    "ReplayClock",
    "kp_pairs",
    "load_replay",
    "replay_views",
    "run_world",
]
