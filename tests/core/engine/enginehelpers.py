"""What the engine's tests share: run specs, a driver, the headless loop's LTM."""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Coroutine, Sequence
from typing import Any

from core.brain.catalog import Catalog, load_catalog
from core.commands import InjectReward, RewardSource
from core.engine import (
    RunEngine,
)
from core.ports import (
    Mode,
    RunSpec,
    RunStatus,
    StoredReward,
)
from core.run.conditions import get_condition
from core.run.simulation import Simulation, TickInputs

LtmByName = dict[tuple[str, str], float]


CATALOG: Catalog = load_catalog()


def fast(condition: str, seed: int, episodes: int, **params: Any) -> RunSpec:
    return RunSpec(condition, seed, episodes, Mode.FAST, params=params)


def realtime(condition: str, seed: int, hz: float = 200.0) -> RunSpec:
    return RunSpec(condition, seed, None, Mode.REALTIME, hz=hz)


async def drive(
    engine: RunEngine, script: Callable[[RunEngine], Coroutine[Any, Any, None]]
) -> RunStatus:
    """Run the engine and a script beside it; the script must stop the engine."""
    async with asyncio.TaskGroup() as tg:
        runner = tg.create_task(engine.run())
        tg.create_task(script(engine))
    return runner.result()


async def wait_ticks(engine: RunEngine, n: int) -> None:
    target = engine.sim.tick_count + n
    while engine.sim.tick_count < target:
        await asyncio.sleep(0.001)


def headless_ltm(condition: str, seed: int, rewards: Sequence[StoredReward]) -> LtmByName:
    """The LTM of the plain headless loop given a run's log up to its last stamp.

    Trainers' rewards go in at the boundaries they were stamped with; the run's own come
    from the ticks, as in a resumed run's replay.
    """
    sim = Simulation(get_condition(condition), seed, catalog=CATALOG)
    sim.reset()
    last = max(r.record.tick for r in rewards)
    while sim.tick_count < last:
        if sim.snapshot.done:
            sim.reset()
        boundary = sim.tick_count + 1
        due = tuple(
            InjectReward(r.record.value, note=r.record.note, source=r.record.source)
            for r in rewards
            if r.record.source is RewardSource.TRAINER and r.record.tick == boundary
        )
        sim.tick(TickInputs(rewards=due))
    cat = sim.brain.catalog
    return {(cat.stimuli[s].name, cat.behaviours[b].name): v for (s, b), v in sim.brain.ltm.items()}
