"""The engine and slow or failing storage: ticks never wait, failures answer every caller."""

from __future__ import annotations

import asyncio
import threading
from collections.abc import Sequence

import pytest
from enginehelpers import CATALOG, drive, fast, realtime, wait_ticks
from fakes import InMemoryRunStore

from core.commands import EditAssociation
from core.engine import (
    RewardAck,
    RunEngine,
)
from core.errors import StorageError
from core.ports import (
    CommandRecord,
    LearningUpdate,
    Mode,
    RewardCommit,
    RewardRecord,
    RunStatus,
)
from core.run.conditions import get_condition
from core.run.runner import run as headless_run


class FailingStore(InMemoryRunStore):
    """A store whose disk fills up at the n-th commit of rewards' learning."""

    def __init__(self, fail_at: int) -> None:
        super().__init__(CATALOG)
        self.fail_at = fail_at
        self.commits = 0
        self.committed = 0
        """Rewards in the commits that succeeded."""

    def commit_rewards(self, run_id: int, rewards: Sequence[RewardCommit]) -> tuple[int, ...]:
        self.commits += 1
        if self.commits >= self.fail_at:
            raise StorageError("database or disk is full")
        ids = super().commit_rewards(run_id, rewards)
        self.committed += len(ids)
        return ids


def test_a_storage_error_ends_the_run_with_a_clear_error_and_keeps_what_was_committed() -> None:
    store = FailingStore(fail_at=3)
    engine = RunEngine.create(fast("delayed", 1, 200), store, catalog=CATALOG)
    with pytest.raises(StorageError, match="disk is full"):
        asyncio.run(engine.run())
    assert engine.status is RunStatus.FAILED
    assert engine.error is not None and "disk is full" in engine.error
    # The two commits before the failing one are kept whole, however many rewards each held.
    applied = [r for r in store.rewards(engine.run_id) if r.applied]
    assert store.commits == 3 and len(applied) == store.committed > 0
    # Episodes are written behind in batches: what was committed is whole and consistent.
    stored = store.load_run(engine.run_id)
    assert stored.status is RunStatus.FAILED
    assert stored.totals.episodes == len(store.episodes(engine.run_id))


class SlowDiskStore(InMemoryRunStore):
    """A store whose first commit of rewards' learning waits until it is let go."""

    def __init__(self) -> None:
        super().__init__(CATALOG)
        self.go = threading.Event()
        self.batches: list[int] = []

    def commit_rewards(self, run_id: int, rewards: Sequence[RewardCommit]) -> tuple[int, ...]:
        if not self.batches:
            self.go.wait(30)
        self.batches.append(len(rewards))
        return super().commit_rewards(run_id, rewards)


def test_ticks_never_wait_for_a_commit_and_what_queued_meanwhile_goes_in_one() -> None:
    store = SlowDiskStore()
    engine = RunEngine.create(fast("rp", 4, 60), store, catalog=CATALOG)

    async def main() -> None:
        runner = asyncio.create_task(engine.run())
        try:
            async with asyncio.timeout(20):
                while engine.sim.tick_count < 4000:  # the first commit is still waiting
                    await asyncio.sleep(0.001)
        finally:
            store.go.set()
            await runner

    asyncio.run(main())
    plain = headless_run(get_condition("rp"), 4, 60, catalog=CATALOG)
    assert store.batches[1] > 1, store.batches
    assert sum(store.batches) == len(store.rewards(engine.run_id))
    assert len(store.rewards(engine.run_id)) == sum(e.rewards for e in plain.episodes)
    assert engine.sim.brain.ltm.as_dict() == plain.ltm


class CommandFailingStore(InMemoryRunStore):
    """A store that cannot log a command."""

    def log_command(self, run_id: int, command: CommandRecord, update: LearningUpdate) -> int:
        raise StorageError("database or disk is full")


def test_an_edit_that_cannot_be_stored_is_answered_with_the_error_not_left_waiting() -> None:
    engine = RunEngine.create(fast("kp", 2, 500), CommandFailingStore(CATALOG), catalog=CATALOG)
    answered: list[BaseException] = []

    async def main() -> None:
        runner = asyncio.create_task(engine.run())
        await wait_ticks(engine, 50)
        async with asyncio.timeout(30):  # a hang fails the test instead of stalling it
            try:
                await engine.edit(EditAssociation("Red", "stop", 1.0, "dp"))
            except StorageError as e:
                answered.append(e)
            with pytest.raises(StorageError, match="disk is full"):
                await runner

    asyncio.run(main())
    assert [str(e) for e in answered] == ["the edit was not stored: database or disk is full"]
    assert engine.status is RunStatus.FAILED


class HeldLog(InMemoryRunStore):
    """A store whose second reward log write waits until released, then fails if `fail`."""

    def __init__(self, fail: bool) -> None:
        super().__init__(CATALOG)
        self.fail = fail
        self.calls = 0
        self.stuck = threading.Event()
        self.release = threading.Event()

    def log_reward(self, run_id: int, reward: RewardRecord) -> int:
        self.calls += 1
        if self.calls == 2:
            self.stuck.set()
            self.release.wait(30)
            if self.fail:
                raise StorageError("database is locked")
        return super().log_reward(run_id, reward)


def test_an_episode_ending_while_a_reward_waits_for_its_log_resumes_to_the_same_ltm() -> None:
    """The reward is in the episode's state before it has a log id: its checkpoint waits
    for the log entry and names it, so a resumed run does not apply the reward twice."""
    store = HeldLog(fail=False)
    engine = RunEngine.create(realtime("rp", 7, hz=1000.0), store, catalog=CATALOG)
    held: list[int] = []

    async def script(e: RunEngine) -> None:
        await wait_ticks(e, 40)
        await e.reward(1.0)
        slow = asyncio.create_task(e.reward(-0.5))
        while not store.stuck.is_set():
            await asyncio.sleep(0.001)
        stored = len(store.episodes(e.run_id))
        ended = e.totals.episodes
        while e.totals.episodes == ended:  # an episode ends while the reward waits
            await asyncio.sleep(0.001)
        await asyncio.sleep(0.3)  # the episode writer gathers for 50 ms, then writes
        held.append(len(store.episodes(e.run_id)) - stored)
        store.release.set()
        await slow
        await wait_ticks(e, 20)
        e.stop()

    assert asyncio.run(drive(engine, script)) is RunStatus.STOPPED
    assert held == [0], "the episode's checkpoint waited for the reward's log entry"
    ticks = engine.sim.tick_count
    store.set_status(engine.run_id, RunStatus.INTERRUPTED)
    again = RunEngine.restore(engine.run_id, store, catalog=CATALOG, mode=Mode.FAST)
    assert asyncio.run(again.run(until_tick=ticks)) is RunStatus.STOPPED
    assert again.sim.tick_count == ticks
    assert again.sim.brain.ltm.as_dict() == engine.sim.brain.ltm.as_dict()


def test_ticks_go_on_while_the_log_is_stuck_and_its_failure_answers_every_reward() -> None:
    """A reward is applied at its boundary though its log entry is not written yet (a slow
    disk must not hold the ticks), and is committed only as that entry: when the write
    fails, the run fails, the reward and those acknowledged after it get the error, and
    nothing of it is stored."""
    store = HeldLog(fail=True)
    engine = RunEngine.create(realtime("rp", 1), store, catalog=CATALOG)

    async def scenario() -> tuple[int, list[RewardAck | BaseException]]:
        run = asyncio.create_task(engine.run())
        await wait_ticks(engine, 5)
        await engine.reward(1.0, note="first")
        stuck = asyncio.create_task(engine.reward(1.0, note="stuck"))
        while not store.stuck.is_set():
            await asyncio.sleep(0.001)
        at = engine.sim.tick_count
        after = [asyncio.create_task(engine.reward(0.5, note=f"after {i}")) for i in range(3)]
        await wait_ticks(engine, 5)  # the ticks go on past the stuck reward's boundary
        ticked = engine.sim.tick_count - at
        store.release.set()
        with pytest.raises(StorageError):
            await run
        async with asyncio.timeout(10):  # a guard against hanging, not a speed goal
            answers = await asyncio.gather(stuck, *after, return_exceptions=True)
        return ticked, answers

    ticked, answers = asyncio.run(scenario())
    assert ticked >= 5
    assert engine.status is RunStatus.FAILED
    assert all(isinstance(a, StorageError) for a in answers), answers
    assert [r.record.note for r in store.rewards(engine.run_id)] == ["first"]
