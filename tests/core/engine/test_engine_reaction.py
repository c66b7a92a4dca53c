"""The engine and a trainer's seen tick: the reaction window, an episode's end, a resume."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable

import pytest
from enginehelpers import CATALOG, drive
from fakes import InMemoryRunStore

from core.brain.memory import ReactionWindow
from core.engine import RunEngine
from core.errors import SeenTickError
from core.events import RewardApplied
from core.ports import Mode, RunSpec, RunStatus
from core.run.trace import TraceRow, unpack

HZ = 500.0
WINDOW_S = (0.004, 0.02)
"""1..10 ticks at `HZ`; a paused run's ends at the seen tick."""
WINDOW = ReactionWindow(1, 10)


def spec(seed: int = 3) -> RunSpec:
    return RunSpec("kp", seed, None, Mode.REALTIME, hz=HZ, params={"reaction_window_s": WINDOW_S})


class Trainer:
    """Drives a paused run a tick at a time and reads back each reward's application."""

    def __init__(self, engine: RunEngine) -> None:
        self.e = engine
        self.sub = engine.subscribe(maxsize=100_000)

    async def pause(self) -> None:
        async with asyncio.timeout(30):  # a bound for a hang, not a speed test
            while self.e.status is not RunStatus.PAUSED:
                self.e.pause()  # once it runs
                await asyncio.sleep(0.001)

    async def applied(self) -> RewardApplied:
        async with asyncio.timeout(30):  # a bound for a hang, not a speed test
            while True:
                for ev in self.sub.drain():
                    if isinstance(ev, RewardApplied) and ev.source == "trainer":
                        return ev
                await asyncio.sleep(0.001)

    async def reward(self, value: float, tick_seen: int | None) -> RewardApplied:
        await self.e.reward(value, tick_seen=tick_seen)
        if self.e.sim.snapshot.done:
            await self.e.step()  # due after the reset: applied at the next boundary
        return await self.applied()

    async def to_a_crash(self) -> int:
        """Step to an episode's end with STM records in its last window; its last tick."""
        e = self.e
        for _ in range(20_000):
            await e.step()
            if e.sim.snapshot.done and any(
                t >= e.sim.tick_count - WINDOW.hi_ticks for t, _, _ in e.sim.brain.stm
            ):
                return e.sim.tick_count
        raise AssertionError("no episode ended")


def run(engine: RunEngine, script: Callable[[Trainer], Awaitable[None]]) -> None:
    async def main(e: RunEngine) -> None:
        t = Trainer(e)
        await t.pause()
        await script(t)
        e.stop()

    assert asyncio.run(drive(engine, main)) is RunStatus.STOPPED


def test_a_reward_with_a_seen_tick_credits_the_window_before_it() -> None:
    engine = RunEngine.create(spec(), InMemoryRunStore(CATALOG), catalog=CATALOG)
    events: list[RewardApplied] = []

    async def script(t: Trainer) -> None:
        while t.e.sim.tick_count < 30:
            await t.e.step()
        events.append(await t.reward(1.0, tick_seen=25))

    run(engine, script)
    (ev,) = events
    # Paused: the window ends at the seen tick, which the person looked at at leisure.
    assert (ev.tick_seen, ev.window) == (25, (15, 25))
    assert ev.credits and all(15 <= c.tick <= 25 for c in ev.credits)
    assert all(c.d_k == 25 - c.tick + 1 for c in ev.credits)
    # The records after the window's end stay in STM for the next reward.
    assert [t for t, _, _ in engine.sim.brain.stm if t > 25] == list(range(26, 31))


def test_a_seen_tick_the_run_has_not_reached_or_no_longer_holds_is_refused() -> None:
    store = InMemoryRunStore(CATALOG)
    engine = RunEngine.create(spec(), store, catalog=CATALOG)
    errors: list[SeenTickError] = []

    async def script(t: Trainer) -> None:
        while t.e.sim.tick_count < 10:
            await t.e.step()
        for seen, episode in ((11, None), (5, 3), (9, 1)):
            with pytest.raises(SeenTickError) as caught:
                await t.e.reward(1.0, tick_seen=seen, seen_episode=episode)
            errors.append(caught.value)

    run(engine, script)
    assert [(e.field, e.message) for e in errors] == [
        ("tick_seen", "tick 11 is in the future: run 1 has reached tick 10"),
        ("episode", "episode 3 is not one a seen tick may lie in: 0"),
        ("episode", "episode 1 is not one a seen tick may lie in: 0"),
    ]
    assert store.rewards(engine.run_id) == []


@pytest.mark.parametrize("after", [1, 2, 3])
def test_a_reward_pressed_just_after_a_crash_credits_the_ended_episode(after: int) -> None:
    """The issue's case: a trainer reacts to a crash; the reward arrives 1-3 ticks into the
    next episode, seen at the crash. It credits the ended episode's last records."""
    engine = RunEngine.create(spec(), InMemoryRunStore(CATALOG), catalog=CATALOG)
    out: list[tuple[int, RewardApplied, dict[tuple[int, int], float]]] = []

    async def script(t: Trainer) -> None:
        end = await t.to_a_crash()
        for _ in range(after):
            await t.e.step()
        before = t.e.sim.brain.ltm.as_dict()
        out.append((end, await t.reward(-1.0, tick_seen=end), before))

    run(engine, script)
    ((end, ev, before),) = out
    assert ev.window == (end - 10, end)
    assert ev.credits and all(end - 10 <= c.tick <= end for c in ev.credits)
    assert engine.sim.brain.ltm.as_dict() != before


def test_a_reward_pressed_after_the_window_credits_nothing() -> None:
    engine = RunEngine.create(spec(), InMemoryRunStore(CATALOG), catalog=CATALOG)
    out: list[RewardApplied] = []

    async def script(t: Trainer) -> None:
        end = await t.to_a_crash()
        while t.e.sim.tick_count < end + WINDOW.hi_ticks + 1:
            await t.e.step()
        out.append(await t.reward(-1.0, tick_seen=end))

    run(engine, script)
    assert out[0].credits == ()


def test_a_resumed_run_applies_seen_ticks_as_the_run_did() -> None:
    """Rewards seen mid-episode and at a crash (after its checkpoint), then a resume from
    the log: the same LTM as the run that was never interrupted."""
    store = InMemoryRunStore(CATALOG)
    engine = RunEngine.create(spec(5), store, catalog=CATALOG)

    async def script(t: Trainer) -> None:
        while t.e.sim.tick_count < 20:
            await t.e.step()
        await t.reward(1.0, tick_seen=18)
        end = await t.to_a_crash()
        await t.e.step()
        crash = await t.reward(-1.0, tick_seen=end)
        assert crash.credits
        await t.reward(0.5, tick_seen=end)
        for _ in range(5):
            await t.e.step()
        await t.reward(1.0, tick_seen=t.e.sim.tick_count)

    run(engine, script)
    ticks = engine.sim.tick_count
    rewards = store.rewards(engine.run_id)
    assert [r.record.tick_seen is not None for r in rewards if r.record.source == "trainer"] == [
        True
    ] * 4
    store.set_status(engine.run_id, RunStatus.INTERRUPTED)
    again = RunEngine.restore(engine.run_id, store, catalog=CATALOG, mode=Mode.FAST)
    assert again.sim.brain.window == WINDOW
    # The last reward was applied paused, at the boundary after the last tick: the
    # resumed run reaches that boundary by running the tick after it.
    assert asyncio.run(again.run(until_tick=ticks + 1)) is RunStatus.STOPPED
    assert again.sim.brain.ltm.as_dict() == engine.sim.brain.ltm.as_dict()


def test_a_reward_on_a_stored_episode_is_replayed_with_the_records_it_carried() -> None:
    """Feedback on replay: records from episode 0's stored trace, carried by the reward
    and logged, so a resumed run credits exactly them again."""
    store = InMemoryRunStore(CATALOG)
    engine = RunEngine.create(spec(7), store, catalog=CATALOG)
    seen_at: list[int] = []

    async def script(t: Trainer) -> None:
        await t.to_a_crash()
        await t.to_a_crash()
        await t.e.step()  # into episode 2: episode 0 is stored, and no longer held
        async with asyncio.timeout(30):
            while (stored := store.episode(t.e.run_id, 0)) is None:
                await asyncio.sleep(0.01)
        rows = [r for r in unpack(stored.trace) if r.released_by >= 0]
        seen = rows[len(rows) // 2].tick
        records = tuple((r.tick, r.released_by, r.behaviour) for r in rows)
        await t.e.reward(1.0, tick_seen=seen, seen_episode=0, records=records)
        ev = await t.applied()
        assert ev.window == (seen - WINDOW.hi_ticks, seen)
        assert [c.tick for c in ev.credits] == sorted(
            (r[0] for r in records if seen - WINDOW.hi_ticks <= r[0] <= seen), reverse=True
        )
        seen_at.append(seen)

    run(engine, script)
    assert seen_at
    (logged,) = (r for r in store.rewards(engine.run_id) if r.record.tick_seen is not None)
    assert logged.record.records and logged.record.seen_episode == 0
    ticks = engine.sim.tick_count
    store.set_status(engine.run_id, RunStatus.INTERRUPTED)
    again = RunEngine.restore(engine.run_id, store, catalog=CATALOG, mode=Mode.FAST)
    assert asyncio.run(again.run(until_tick=ticks + 1)) is RunStatus.STOPPED
    assert again.sim.brain.ltm.as_dict() == engine.sim.brain.ltm.as_dict()


async def stored_trace(store: InMemoryRunStore, run_id: int, episode: int) -> list[TraceRow]:
    """Episode `episode`'s stored trace, once the run's episode writer has stored it."""
    async with asyncio.timeout(30):  # a bound for a hang, not a speed test
        while (stored := store.episode(run_id, episode)) is None:
            await asyncio.sleep(0.01)
    return unpack(stored.trace)


def from_trace(rows: list[TraceRow]) -> tuple[tuple[int, int, int], ...]:
    """A trace's STM records: the ticks whose behaviour answered a stimulus."""
    return tuple((r.tick, r.released_by, r.behaviour) for r in rows if r.released_by >= 0)


def test_a_run_paused_at_an_episodes_end_credits_a_replay_reward_at_once() -> None:
    """The console's race: a fast run paused just as an episode ended held a reward on a
    stored episode's replay until it went on, so whether it was credited by the time the
    console looked depended on when the trainer resumed. Paused there, the run starts its
    next episode as the reward comes (its first tick not run) and credits it at once, after
    the reset, where a replay of the log applies it too."""
    store = InMemoryRunStore(CATALOG)
    engine = RunEngine.create(spec(7), store, catalog=CATALOG)
    seen: list[tuple[int, int]] = []

    async def script(t: Trainer) -> None:
        await t.to_a_crash()
        end = await t.to_a_crash()
        assert t.e.sim.snapshot.done and t.e.sim.episode == 1  # paused at episode 1's end
        records = from_trace(await stored_trace(store, t.e.run_id, 0))
        tick = records[len(records) // 2][0]
        await t.e.reward(1.0, tick_seen=tick, seen_episode=0, records=records)
        ev = await t.applied()  # no step, no resume: credited while paused
        assert t.e.status is RunStatus.PAUSED
        assert (t.e.sim.tick_count, t.e.sim.episode, ev.episode) == (end, 2, 2)
        assert ev.credits and all(tick - WINDOW.hi_ticks <= c.tick <= tick for c in ev.credits)
        seen.append((tick, end))

    run(engine, script)
    assert seen
    ticks = engine.sim.tick_count
    store.set_status(engine.run_id, RunStatus.INTERRUPTED)
    again = RunEngine.restore(engine.run_id, store, catalog=CATALOG, mode=Mode.FAST)
    assert asyncio.run(again.run(until_tick=ticks + 1)) is RunStatus.STOPPED
    assert again.sim.brain.ltm.as_dict() == engine.sim.brain.ltm.as_dict()


def credited(ev: RewardApplied) -> list[tuple[int, int, int, int]]:
    return [(c.tick, c.stimulus, c.behaviour, c.d_k) for c in ev.credits]


def ended_presses(pop_at: int | None) -> tuple[int, dict[str, list[tuple[int, int, int, int]]]]:
    """Presses on the replay of the first episode to end (seed 7): at its last tick while
    the run keeps its last records ("kept"), at that tick once they are let go and 3 ticks
    before it (from its stored trace, "stored 0" and "stored -3"). With `pop_at`, a reward
    worth 0 seen at that tick takes STM's records up to it first (as any reward pops what it
    credits). Returns the episode's last tick and each press's credits."""
    store = InMemoryRunStore(CATALOG)
    engine = RunEngine.create(spec(7), store, catalog=CATALOG)
    out: dict[str, list[tuple[int, int, int, int]]] = {}
    ends: list[int] = []

    async def script(t: Trainer) -> None:
        if pop_at is not None:
            while t.e.sim.tick_count < pop_at:
                await t.e.step()
            await t.e.reward(0.0, tick_seen=pop_at)
            await t.applied()
        while not t.e.sim.snapshot.done:
            await t.e.step()
        end = t.e.sim.tick_count
        ended = t.e.sim.episode
        ends.append(end)
        await t.e.reward(1.0, tick_seen=end, seen_episode=ended)  # paused at its end
        out["kept"] = credited(await t.applied())
        out["brain kept"] = [(r[0], r[1], r[2], 0) for r in t.e.sim.brain.ended]
        records = from_trace(await stored_trace(store, t.e.run_id, ended))
        out["trace"] = [(r[0], r[1], r[2], 0) for r in records]
        for tick in (end - 3, end):
            if tick == end:
                while t.e.sim.tick_count <= end + WINDOW.hi_ticks:
                    await t.e.step()  # the kept records are let go
            with pytest.raises(SeenTickError) as caught:
                await t.e.reward(1.0, tick_seen=tick, seen_episode=ended)
            assert caught.value.field == "episode"
            await t.e.reward(1.0, tick_seen=tick, seen_episode=ended, records=records)
            out[f"stored {tick - end}"] = credited(await t.applied())
        # A tick the run has not reached is refused, naming it.
        with pytest.raises(SeenTickError) as caught:
            await t.e.reward(1.0, tick_seen=t.e.sim.tick_count + 1, seen_episode=ended)
        assert caught.value.field == "tick_seen"

    run(engine, script)
    return ends[0], out


def test_a_replay_reward_on_the_ended_episode_credits_as_its_stored_trace_says() -> None:
    """The episode that ended last, scrubbed on its replay: at its last tick, while the
    records kept aside at its end hold the window, from them; at an earlier tick, or once
    they are let go, from its stored trace (the service's route falls back to it on
    `episode`). The same press on the same tick credits the same records either way, even
    when a reward took some of STM's records before the episode ended (the records kept
    aside for a reward on its replay are its trace's, not what STM still held)."""
    end, out = ended_presses(None)
    assert out["kept"] and out["kept"] == out["stored 0"]
    assert out["stored -3"] and out["stored -3"] != out["kept"]
    again, popped = ended_presses(end - 3)
    assert again == end  # the reward worth 0 changed nothing the robot did
    # STM lost the records up to end - 3 to the reward worth 0; the trace keeps them.
    assert {r[0] for r in popped["trace"]} & set(range(end - 10, end - 2))
    assert not {r[0] for r in popped["brain kept"]} & set(range(end - 10, end - 2))
    assert popped["kept"] == popped["stored 0"]
