"""The asyncio engine: two tasks, stamped rewards and commands, replay, shutdown, storage."""

from __future__ import annotations

import asyncio
import gc
import weakref
from dataclasses import replace

import pytest
from enginehelpers import CATALOG, drive, fast, headless_ltm, realtime, wait_ticks
from fakes import InMemoryRunStore, ManualPacer

from core.commands import EditAssociation
from core.engine import (
    RewardAck,
    RunEngine,
    StatusChanged,
    TickPublished,
)
from core.errors import RunStateError
from core.events import EpisodeEnded, RewardApplied
from core.ports import (
    LearningUpdate,
    Mode,
    RunStatus,
)
from core.run.conditions import get_condition
from core.run.runner import run as headless_run
from core.run.simulation import Snapshot
from core.run.trace import unpack


@pytest.mark.parametrize("condition", ["kp", "rp", "delayed", "dp"])
def test_fast_mode_gives_the_same_ltm_as_the_headless_loop(condition: str) -> None:
    store = InMemoryRunStore(CATALOG)
    engine = RunEngine.create(fast(condition, 3, 12), store, catalog=CATALOG)
    assert asyncio.run(engine.run()) is RunStatus.FINISHED
    plain = headless_run(get_condition(condition), 3, 12, catalog=CATALOG)
    assert engine.sim.brain.ltm.as_dict() == plain.ltm
    assert engine.totals.ticks == plain.ticks
    assert engine.totals.successes == plain.successes
    stored = store.ltm(engine.run_id)
    names = engine.sim.brain.catalog
    expected = {
        (names.stimuli[s].name, names.behaviours[b].name): v for (s, b), v in plain.ltm.items()
    }
    assert stored == expected
    assert len(store.episodes(engine.run_id)) == 12
    assert all(r.applied for r in store.rewards(engine.run_id))


def test_each_stored_episode_traces_exactly_its_ticks_as_the_headless_loop_ran_them() -> None:
    # The engine hands each episode's rows to its writer, which compresses them off the
    # tick task: what is stored must still be that episode's ticks, in order.
    ticks: list[Snapshot] = []
    plain = headless_run(get_condition("kp"), 5, 4, catalog=CATALOG, on_tick=ticks.append)
    store = InMemoryRunStore(CATALOG)
    engine = RunEngine.create(fast("kp", 5, 4), store, catalog=CATALOG)
    assert asyncio.run(engine.run()) is RunStatus.FINISHED
    stored = store.episodes(engine.run_id)
    assert [e.ticks for e in stored] == [e.ticks for e in plain.episodes]
    for record in stored:
        rows = unpack(record.trace)
        expected = [s for s in ticks if s.episode == record.episode and s.episode_tick > 0]
        assert len(rows) == record.ticks == len(expected)
        assert [
            (r.tick, r.behaviour, r.how, r.lamp, r.stimuli, r.origin, r.released_by) for r in rows
        ] == [
            (
                s.tick,
                s.behaviour,
                str(s.how),
                int(s.lamp),
                tuple(sorted(s.stimuli)),
                s.origin,
                s.released_by,
            )
            for s in expected
        ]
        # float32 in the trace: positions and headings to well under a millimetre (radian).
        assert (
            max(
                abs(r.x - s.x) + abs(r.y - s.y) + abs(r.heading_rad - s.heading_rad)
                for r, s in zip(rows, expected, strict=True)
            )
            < 1e-4
        )


def test_a_watched_fast_run_ticks_as_an_unwatched_one() -> None:
    # Unwatched, fast mode ticks in a loop that checks subscribers and held rewards once
    # per burst (`TickTask.burst`); watched, every tick goes through `_tick`. Both must
    # store the same run and count every tick.
    plain = headless_run(get_condition("kp"), 6, 5, catalog=CATALOG)
    runs = []
    for watched in (False, True):
        store = InMemoryRunStore(CATALOG)
        engine = RunEngine.create(fast("kp", 6, 5), store, catalog=CATALOG)
        sub = engine.subscribe(maxsize=100_000, tick_hz=1e6) if watched else None
        assert asyncio.run(engine.run()) is RunStatus.FINISHED
        assert engine.stats.ticks == engine.totals.ticks == plain.ticks
        assert engine.sim.brain.ltm.as_dict() == plain.ltm
        if sub is not None:
            assert any(isinstance(ev, TickPublished) for ev in sub.drain())
        runs.append(
            [(e.episode, e.ticks, e.outcome, e.trace) for e in store.episodes(engine.run_id)]
        )
    assert runs[0] == runs[1]
    assert len(runs[0]) == 5


def test_a_reward_mid_episode_credits_exactly_the_records_before_it() -> None:
    store = InMemoryRunStore(CATALOG)
    engine = RunEngine.create(realtime("kp", 1, hz=500.0), store, catalog=CATALOG)
    sub = engine.subscribe(maxsize=10_000)
    acks = []

    async def script(e: RunEngine) -> None:
        await wait_ticks(e, 30)
        acks.append(await e.reward(1.0, note="good"))
        await wait_ticks(e, 5)
        e.stop()

    asyncio.run(drive(engine, script))
    ack = acks[0]
    applied = [ev for ev in sub.drain() if isinstance(ev, RewardApplied) and ev.source == "trainer"]
    assert len(applied) == 1
    event = applied[0]
    assert event.tick == ack.tick
    assert event.credits, "the reward found STM records"
    assert all(c.tick < ack.tick for c in event.credits)
    assert all(c.d_k == ack.tick - c.tick for c in event.credits)
    assert min(c.d_k for c in event.credits) == 1
    # Records made after the reward's stamp stay in STM for the next reward.
    assert all(t >= ack.tick for t, _, _ in engine.sim.brain.stm)
    logged = store.rewards(engine.run_id)
    assert [(r.id, r.record.tick, r.record.note, r.applied) for r in logged] == [
        (ack.id, ack.tick, "good", True)
    ]


def test_a_run_replays_from_its_seed_and_command_log() -> None:
    """Rewards and edits at arbitrary moments of a realtime run, replayed in fast mode."""
    store = InMemoryRunStore(CATALOG)
    engine = RunEngine.create(realtime("rp", 7, hz=1000.0), store, catalog=CATALOG)

    async def script(e: RunEngine) -> None:
        for i in range(6):
            await wait_ticks(e, 40 + 13 * i)
            await e.reward(1.0 if i % 2 else -0.5)
        await e.edit(EditAssociation("Obstacle_M_M", "rightturn30", 1.0, "dp", locked=True))
        await wait_ticks(e, 50)
        e.stop()

    asyncio.run(drive(engine, script))
    ticks = engine.sim.tick_count
    # A second store holding only the first run's spec and its log of trainer commands.
    replay_store = InMemoryRunStore(CATALOG)
    spec = replace(store.load_run(engine.run_id).spec, mode=Mode.FAST)
    replay_id = replay_store.create_run(spec, ())
    for r in store.rewards(engine.run_id):
        if r.record.source == "trainer":
            replay_store.log_reward(replay_id, r.record)
    for c in store.commands(engine.run_id):
        replay_store.log_command(replay_id, c.record, LearningUpdate())
    replay_store.set_status(replay_id, RunStatus.INTERRUPTED)
    again = RunEngine.restore(replay_id, replay_store, catalog=CATALOG)
    assert asyncio.run(again.run(until_tick=ticks)) is RunStatus.STOPPED

    assert again.sim.tick_count == ticks
    assert again.sim.brain.ltm.as_dict() == engine.sim.brain.ltm.as_dict()
    assert list(again.sim.brain.network) == list(engine.sim.brain.network)
    assert engine.sim.brain.ltm.as_dict(), "the first run learned something"
    assert len(replay_store.rewards(replay_id)) == len(store.rewards(engine.run_id))


def test_shutdown_with_a_pending_reward_commits_it_and_leaves_no_task() -> None:
    store = InMemoryRunStore(CATALOG)
    engine = RunEngine.create(realtime("delayed", 2, hz=50.0), store, catalog=CATALOG)

    async def main() -> None:
        runner = asyncio.create_task(engine.run())
        await wait_ticks(engine, 3)
        reward = asyncio.create_task(engine.reward(0.5))
        await asyncio.sleep(0)
        engine.stop()
        ack = await reward
        assert await runner is RunStatus.STOPPED
        assert [t for t in asyncio.all_tasks() if t is not asyncio.current_task()] == []
        stored = store.rewards(engine.run_id)
        assert [(r.id, r.applied) for r in stored] == [(ack.id, True)]

    asyncio.run(main())
    assert store.load_run(engine.run_id).status is RunStatus.STOPPED


def test_pause_resume_and_rewards_need_a_running_or_paused_run() -> None:
    store = InMemoryRunStore(CATALOG)
    engine = RunEngine.create(realtime("delayed", 4, hz=500.0), store, catalog=CATALOG)
    sub = engine.subscribe(maxsize=1000)

    async def script(e: RunEngine) -> None:
        await wait_ticks(e, 5)
        e.pause()
        await asyncio.sleep(0.01)
        frozen = e.sim.tick_count
        ack = await e.reward(1.0)
        assert ack.tick == frozen + 1
        await asyncio.sleep(0.05)
        assert e.sim.tick_count == frozen
        e.resume()
        await wait_ticks(e, 5)
        e.stop()

    assert asyncio.run(drive(engine, script)) is RunStatus.STOPPED
    statuses = [ev.status for ev in sub.drain() if isinstance(ev, StatusChanged)]
    assert statuses == [
        RunStatus.RUNNING,
        RunStatus.PAUSED,
        RunStatus.RUNNING,
        RunStatus.STOPPED,
    ]

    async def not_running() -> None:
        with pytest.raises(RunStateError):
            await engine.reward(1.0)

    asyncio.run(not_running())


def test_a_paused_run_credits_a_reward_at_its_boundary_and_a_stepping_trainer_its_step() -> None:
    """Pause, reward what the robot did; step a tick, reward what it just did: each reward
    is applied while the run stays paused, crediting exactly the records before the
    boundary it is paused at, and a replay of the log learns the same."""
    store = InMemoryRunStore(CATALOG)
    engine = RunEngine.create(realtime("kp", 3, hz=500.0), store, catalog=CATALOG)
    sub = engine.subscribe(maxsize=100_000)
    seen: list[tuple[int, RewardApplied]] = []

    async def applied() -> RewardApplied:
        async with asyncio.timeout(30):  # a bound for a hang, not a speed test
            while True:
                for ev in sub.drain():
                    if isinstance(ev, RewardApplied) and ev.source == "trainer":
                        return ev
                await asyncio.sleep(0.001)

    async def script(e: RunEngine) -> None:
        await wait_ticks(e, 40)
        e.pause()
        while e.status is not RunStatus.PAUSED:
            await asyncio.sleep(0.001)
        await asyncio.sleep(0.02)
        frozen = e.sim.tick_count
        ack = await e.reward(1.0, note="paused")
        seen.append((ack.tick, await applied()))
        for value in (-0.5, 0.5, 1.0):
            tick = await e.step()
            ack = await e.reward(value)
            assert ack.tick == tick + 1
            seen.append((ack.tick, await applied()))
        assert e.sim.tick_count == frozen + 3 and e.status is RunStatus.PAUSED
        e.stop()

    asyncio.run(drive(engine, script))
    assert len(seen) == 4
    for stamp, event in seen:
        assert event.tick == stamp
        assert all(c.tick < stamp for c in event.credits)
    assert seen[0][1].credits, "the paused reward found the episode's records"
    assert sum(len(ev.credits) for _, ev in seen[1:]) >= 1, "a step's record was credited"
    assert all(c.d_k == 1 for _, ev in seen[1:] for c in ev.credits)
    assert [r.applied for r in store.rewards(engine.run_id)] == [True] * 4
    assert store.ltm(engine.run_id) == headless_ltm("kp", 3, store.rewards(engine.run_id))


def test_an_edit_reaches_the_robot_at_the_next_boundary_and_is_logged() -> None:
    store = InMemoryRunStore(CATALOG)
    engine = RunEngine.create(realtime("kp", 5, hz=500.0), store, catalog=CATALOG)
    red, stop = CATALOG.stimulus("Red").id, CATALOG.behaviour("stop").id

    async def script(e: RunEngine) -> None:
        await wait_ticks(e, 3)
        assert e.sim.brain.network.get(red, stop) is None
        command_id = await e.edit(EditAssociation("Red", "stop", 1.0, "dp", locked=True))
        assert command_id >= 1
        assoc = e.sim.brain.network.get(red, stop)
        assert assoc is not None and assoc.locked and assoc.source == "dp"
        await e.edit(EditAssociation("Red", "stop", None))
        assert e.sim.brain.network.get(red, stop) is None
        e.stop()

    asyncio.run(drive(engine, script))
    commands = store.commands(engine.run_id)
    assert [c.record.payload["strength"] for c in commands] == [1.0, None]
    assert ("Red", "stop") not in {(p.stimulus, p.behaviour) for p in store.network(engine.run_id)}


def test_edit_of_an_unknown_stimulus_is_refused() -> None:
    engine = RunEngine.create(realtime("kp", 5), InMemoryRunStore(CATALOG), catalog=CATALOG)

    async def script(e: RunEngine) -> None:
        await wait_ticks(e, 1)
        with pytest.raises(Exception, match="unknown stimulus"):
            await e.edit(EditAssociation("Purple", "stop", 1.0))
        e.stop()

    asyncio.run(drive(engine, script))


def test_an_interrupted_run_resumes_from_its_last_committed_state() -> None:
    store = InMemoryRunStore(CATALOG)
    spec = fast("kp", 9, 16)
    engine = RunEngine.create(spec, store, catalog=CATALOG)

    async def stop_midway(e: RunEngine) -> None:
        while e.totals.episodes < 7:
            await asyncio.sleep(0)
        e.interrupt()

    assert asyncio.run(drive(engine, stop_midway)) is RunStatus.INTERRUPTED
    assert store.load_run(engine.run_id).status is RunStatus.INTERRUPTED
    resumed = RunEngine.restore(engine.run_id, store, catalog=CATALOG)
    assert asyncio.run(resumed.run()) is RunStatus.FINISHED
    whole = RunEngine.create(spec, InMemoryRunStore(CATALOG), catalog=CATALOG)
    asyncio.run(whole.run())
    assert resumed.sim.brain.ltm.as_dict() == whole.sim.brain.ltm.as_dict()
    assert resumed.totals == whole.totals
    assert len(store.episodes(engine.run_id)) == 16


@pytest.mark.parametrize("arrival", ["after the end", "while the end settles"])
def test_a_stop_right_after_an_episode_ends_stores_what_the_log_replays(arrival: str) -> None:
    """A trainer's reward arriving after an episode's last tick is due at a boundary after
    the reset: the next one, or the one after if it arrives while the episode's own rewards
    settle. A resumed run and a replay of the log apply it there, so a run stopped before
    that boundary must reach it on the way out; it used to apply the reward to the ended
    episode's STM, and the stored LTM disagreed with the log's replay (the PostgreSQL fault
    test's "LTM != replay"). The first case fails without the fix; the second (the stop
    ticks once more to the reward's stamp) pins the other path, which this seed's
    episode ends happen not to tell apart from the old one (the episode's own rewards
    leave STM empty)."""
    pacer = ManualPacer()
    store = InMemoryRunStore(CATALOG)
    hz = 100.0
    engine = RunEngine.create(realtime("rp", 11, hz=hz), store, catalog=CATALOG, pacer=pacer)
    settling = arrival == "while the end settles"
    episodes = 0

    def ending() -> bool:
        """The last tick ended its episode, whose own rewards are being applied."""
        return engine.sim.snapshot.done and engine.totals.episodes == episodes

    async def main() -> tuple[RewardAck, int]:
        nonlocal episodes
        task = asyncio.create_task(engine.run())
        ticks = 0
        while True:  # tick by tick, to an episode whose end leaves records in STM
            while not (engine.stats.ticks > ticks and pacer.sleeping == 1):
                if settling and engine.stats.ticks > ticks and ending():
                    break
                await asyncio.sleep(0)
            ticks = engine.stats.ticks
            if settling and ending() and pacer.sleeping == 0:
                break
            if not settling and engine.totals.episodes > episodes and list(engine.sim.brain.stm):
                break
            episodes = engine.totals.episodes
            assert ticks < 20_000, "no such episode end"
            pacer.advance(1.0 / hz)
        end = engine.sim.tick_count
        ack = await engine.reward(1.0, note="late")
        engine.stop()
        async with asyncio.timeout(30):
            assert await task is RunStatus.STOPPED
        return ack, end

    ack, end = asyncio.run(main())
    assert ack.tick == end + (2 if settling else 1)
    rewards = store.rewards(engine.run_id)
    (late,) = (r for r in rewards if r.record.note == "late")
    assert late.applied
    assert store.ltm(engine.run_id) == headless_ltm("rp", 11, rewards)


def test_a_finished_run_cannot_be_resumed_and_unknown_params_are_refused() -> None:
    store = InMemoryRunStore(CATALOG)
    engine = RunEngine.create(fast("innate", 1, 1), store, catalog=CATALOG)
    asyncio.run(engine.run())
    with pytest.raises(RunStateError, match="finished"):
        RunEngine.restore(engine.run_id, store, catalog=CATALOG)
    with pytest.raises(ValueError, match="unknown learning parameters: gamma"):
        RunEngine.create(fast("kp", 1, 1, gamma=0.5), store, catalog=CATALOG)
    with pytest.raises(RunStateError, match="qlambda"):
        RunEngine.create(fast("qlambda", 1, 1), store, catalog=CATALOG)


def test_episode_end_events_reach_subscribers() -> None:
    engine = RunEngine.create(fast("expert", 2, 3), InMemoryRunStore(CATALOG), catalog=CATALOG)
    sub = engine.subscribe(maxsize=100)
    asyncio.run(engine.run())
    ended = [ev for ev in sub.drain() if isinstance(ev, EpisodeEnded)]
    assert [e.episode for e in ended] == [0, 1, 2]


def test_acknowledgements_do_not_wait_for_tick_boundaries() -> None:
    """Trainer rewards are acknowledged once logged, not after the previous one applies."""
    store = InMemoryRunStore(CATALOG)
    engine = RunEngine.create(realtime("delayed", 3, hz=2.0), store, catalog=CATALOG)

    async def script(e: RunEngine) -> None:
        await wait_ticks(e, 1)
        before = e.sim.tick_count
        acks = [await e.reward(0.5, note=str(i)) for i in range(3)]
        # Three acknowledgements within one 500 ms tick period: none waited for a boundary.
        assert e.sim.tick_count - before <= 1
        assert [a.tick for a in acks] == [acks[0].tick] * 3
        e.stop()

    asyncio.run(drive(engine, script))
    assert [r.record.note for r in store.rewards(engine.run_id)] == ["0", "1", "2"]
    assert all(r.applied for r in store.rewards(engine.run_id))


def test_a_stream_of_rewards_never_holds_a_boundary_open() -> None:
    store = InMemoryRunStore(CATALOG)
    engine = RunEngine.create(realtime("delayed", 3, hz=200.0), store, catalog=CATALOG)

    async def trainer(e: RunEngine) -> None:
        while e.status is RunStatus.RUNNING:
            try:
                await e.reward(0.1)
            except RunStateError:
                return

    async def script(e: RunEngine) -> None:
        await wait_ticks(e, 1)
        async with asyncio.TaskGroup() as tg:
            for _ in range(8):
                tg.create_task(trainer(e))
            start = e.sim.tick_count
            await wait_ticks(e, 30)  # ticks go on while rewards keep arriving
            assert e.sim.tick_count >= start + 30
            e.stop()

    asyncio.run(drive(engine, script))
    stamps = [r.record.tick for r in store.rewards(engine.run_id)]
    assert stamps == sorted(stamps)


def test_next_status_answers_each_change_and_a_cancelled_wait_is_skipped() -> None:
    engine = RunEngine.create(realtime("delayed", 5, hz=500.0), InMemoryRunStore(CATALOG))

    async def main() -> list[RunStatus]:
        given_up = engine.next_status()
        given_up.cancel()
        first = engine.next_status()
        runner = asyncio.create_task(engine.run())
        seen = [await first]
        second = engine.next_status()
        engine.pause()
        seen.append(await second)
        third = engine.next_status()
        engine.stop()
        seen.append(await third)
        await runner
        return seen

    assert asyncio.run(main()) == [RunStatus.RUNNING, RunStatus.PAUSED, RunStatus.STOPPED]


def test_a_finished_engine_is_freed_without_the_garbage_collector() -> None:
    """No reference cycle keeps a run's simulation alive: the service makes many runs, and
    cyclic garbage waits for a full collection while it slows everything else."""
    gc.collect()
    gc.disable()
    try:
        engine = RunEngine.create(fast("kp", 1, 3), InMemoryRunStore(CATALOG), catalog=CATALOG)
        assert asyncio.run(engine.run()) is RunStatus.FINISHED
        assert engine.view().tick == engine.totals.ticks
        freed = weakref.ref(engine), weakref.ref(engine.sim)
        del engine
        assert [ref() for ref in freed] == [None, None]
    finally:
        gc.enable()
