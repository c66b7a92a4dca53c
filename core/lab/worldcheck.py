"""Does a world pose the paper's problem? Properties of the world alone, never of a learner.

With the traffic signal's correct responses given (so that success measures the obstacle),
and no learning anywhere:

- (a) a robot with no obstacle knowledge (`unaware`) fails: success <= 20%;
- (b) the low-level reflexes alone (`reflexes`: lane keeping and the sonar responses)
  avoid the obstacle only in part: success between 40% and 80%;
- (c) the expert's camera responses on top of them (`expert`) succeed: >= 95%;

and, as the paper's Table II, (d) Table I's innate knowledge alone, the signal not given
(`innate`), succeeds in <= 10%.

A world with a stop-line beacon and no obstacle (`stop-line`) poses the signal's problem
instead, the signal learned (not given) and no learning anywhere (`SIGNAL_PROPERTIES`):

- (a) a robot with no signal knowledge (`reflexes`) obeys only as often as the lamp
  happens to let it: success <= 65%;
- (b) the beacon's reflexes alone (`beacon-reflexes`) obey more often but only in part:
  65-90%;
- (c) the expert's camera responses (`expert`) obey: >= 95%.
 Each figure is a mean over seeds with its 95% interval
(`core.lab.stats.mean_interval`); a property holds when its mean is within its bounds.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from core.events import Outcome
from core.lab.experiment import Backend, LocalBackend, Task, TaskResult, run_tasks
from core.lab.stats import Estimate, mean_interval
from core.run.setup import Setup
from core.sim.worlds import load_world


@dataclass(frozen=True, slots=True)
class WorldProperty:
    """One property: which condition, with or without the signal given, and its bounds."""

    key: str
    label: str
    condition: str
    signal_given: bool
    low: float
    high: float


PROPERTIES: tuple[WorldProperty, ...] = (
    WorldProperty("a", "no obstacle knowledge fails", "unaware", True, 0.0, 0.20),
    WorldProperty("b", "the sonar reflexes alone pass only in part", "reflexes", True, 0.40, 0.80),
    WorldProperty("c", "the expert camera responses pass", "expert", True, 0.95, 1.0),
    WorldProperty("d", "innate knowledge fails (Table II)", "innate", False, 0.0, 0.10),
)

SIGNAL_PROPERTIES: tuple[WorldProperty, ...] = (
    WorldProperty("a", "no signal knowledge obeys by chance", "reflexes", False, 0.0, 0.65),
    WorldProperty(
        "b", "the beacon reflexes alone obey only in part", "beacon-reflexes", False, 0.65, 0.90
    ),
    WorldProperty("c", "the expert camera responses obey", "expert", False, 0.95, 1.0),
)


def properties_for(world: str) -> tuple[WorldProperty, ...]:
    """The properties a world preset is checked on: the signal's where it has a beacon."""
    beacon = load_world(world or None).config.track.signal.beacon
    return SIGNAL_PROPERTIES if beacon else PROPERTIES


@dataclass(frozen=True, slots=True)
class PropertyResult:
    """A property's measured success over seeds, and whether it holds."""

    prop: WorldProperty
    success: Estimate
    failures: dict[str, float]
    """Failed episodes per episode, by cause, means over seeds."""

    @property
    def holds(self) -> bool:
        """Whether the mean success is within the property's bounds."""
        return self.prop.low <= self.success.mean <= self.prop.high


def check_tasks(
    world: str, sensors: str, seeds: Sequence[int], episodes: int
) -> list[tuple[WorldProperty, list[Task]]]:
    """The tasks that measure each property."""
    out = []
    for p in properties_for(world):
        setup = Setup(world, sensors, "given" if p.signal_given else "learned").resolved()
        out.append((p, [Task(p.condition, s, episodes, setup=setup) for s in seeds]))
    return out


def world_check(
    world: str,
    sensors: str = "",
    seeds: Sequence[int] = tuple(range(20)),
    episodes: int = 50,
    backend: Backend | None = None,
    on_result: Callable[[TaskResult], None] | None = None,
) -> list[PropertyResult]:
    """Measure (a)-(d) for a world preset (and a sensor definition, which (c) depends on)."""
    plan = check_tasks(world, sensors, seeds, episodes)
    tasks = [t for _, ts in plan for t in ts]
    results = {r.task: r for r in run_tasks(tasks, backend or LocalBackend(), on_result)}
    out = []
    for p, ts in plan:
        rs = [results[t] for t in ts]
        bad = [r for r in rs if not r.ok]
        if bad:
            raise RuntimeError(f"world-check task {bad[0].task} failed: {bad[0].error}")
        rates = [np.mean([e.outcome is Outcome.SUCCESS for e in r.episodes]) for r in rs]
        causes: dict[str, float] = {}
        for r in rs:
            for e in r.episodes:
                if e.cause is not None:
                    causes[e.cause.value] = causes.get(e.cause.value, 0.0) + 1.0 / len(
                        r.episodes
                    ) / len(rs)
        out.append(PropertyResult(p, mean_interval([float(x) for x in rates]), causes))
    return out
