"""The crash tests' replay follows the order rewards apply, not the order of their ids.

A trainer's reward gets its log id when it arrives; the run's own reward (the task's, the
program's) gets its id when its learning is committed. So a trainer's reward arriving
between an own reward's application and its commit has the smaller id and is applied
after it, and a crash between the two commits leaves it unapplied behind an applied one.
That is the engine's rule (learning committed in the order it happened), and the
kill -9 tests' replay (`harness.replay_ltm`) must take it as such: it once asserted the
applied rewards were a prefix of the log, which failed a crash test beside busy processes.
This builds that state through the engine, deterministically, on the in-memory store.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Sequence

import pytest
from fakes import InMemoryRunStore
from harness import INTERNAL, replay_ltm

from core.brain.catalog import load_catalog
from core.engine import RunEngine
from core.errors import StorageError
from core.ports import Mode, RewardCommit, RunSpec

CATALOG = load_catalog()
SEED = 11


class HeldOwnCommit(InMemoryRunStore):
    """Holds the first commit of the run's own rewards until released, then fails every
    commit of a trainer's reward: a process killed between the two."""

    def __init__(self) -> None:
        super().__init__(CATALOG)
        self.stuck = threading.Event()
        self.release = threading.Event()
        self.failing = False

    def commit_rewards(self, run_id: int, rewards: Sequence[RewardCommit]) -> tuple[int, ...]:
        own_only = all(r.logged_id is None for r in rewards)  # a trainer's has its id here
        if own_only and not self.stuck.is_set():
            self.stuck.set()
            self.release.wait(30)
            self.failing = True
        elif self.failing and not own_only:
            raise StorageError("the process died here")
        return super().commit_rewards(run_id, rewards)


def test_a_trainers_reward_logged_before_an_own_one_and_applied_after_it_replays() -> None:
    store = HeldOwnCommit()
    engine = RunEngine.create(
        RunSpec("rp", SEED, None, Mode.REALTIME, hz=1000.0), store, catalog=CATALOG
    )

    async def scenario() -> None:
        run = asyncio.create_task(engine.run())
        async with asyncio.timeout(30):  # a guard against hanging, not a speed goal
            while not store.stuck.is_set():
                await asyncio.sleep(0.001)
        await engine.reward(1.0, note="arrived while an own reward's commit was held")
        store.release.set()
        with pytest.raises(StorageError):
            await run

    asyncio.run(scenario())
    rewards = store.rewards(engine.run_id)
    own_applied = [r.id for r in rewards if r.record.source in INTERNAL and r.applied]
    trainer_unapplied = [r.id for r in rewards if r.record.source not in INTERNAL and not r.applied]
    assert trainer_unapplied and own_applied, "the state the test is about"
    assert min(trainer_unapplied) < max(own_applied), "an unapplied id before an applied one"
    assert replay_ltm(rewards, "rp", SEED) == store.ltm(engine.run_id)
