"""Where the runs tick (`server.engine_loop`): the service's loop, or a loop of their own.

What each placement guarantees, without timing anything: with ``engine_thread=True`` a
run's ticks, rewards and reads happen on the engines' thread, the service's loop blocked
solid does not stop a run from ticking (on the service's loop, the default, it does:
the bench measures what each costs), and the service stops with no engines' thread left
behind; in both, a control checks and acts in one step, subscriptions carry events to
the service's loop, and a read sees one state of the run.
"""

from __future__ import annotations

import asyncio
import threading
import time
from pathlib import Path

import pytest
from apphelpers import client_for, settings_for, started_realtime, until

from core.engine import RunView, StatusChanged, Subscription, SubscriptionClosed
from server.engines import EngineManager

pytestmark = pytest.mark.anyio
PLACEMENTS = pytest.mark.parametrize(
    "engine_thread", [True, False], ids=["own-thread", "service-loop"]
)

BLOCK_S = 0.5
"""How long a test holds the service's loop: many 50 Hz periods on any machine."""


def _manager(app: object) -> EngineManager:
    manager = app.state.srlab.engines  # type: ignore[attr-defined]
    assert isinstance(manager, EngineManager)
    return manager


async def test_a_runs_reads_and_rewards_happen_on_the_engines_thread(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path, engine_thread=True)) as (client, app):
        manager = _manager(app)
        run_id = await started_realtime(client)
        live = manager.get(run_id)
        assert live is not None
        there = await live.read(lambda _: threading.get_ident())
        assert there == manager.loop.thread_id != threading.get_ident()
        r = await client.post(f"/api/runs/{run_id}/rewards", json={"value": 1.0})
        assert r.status_code == 202, r.text
        assert (await client.post(f"/api/runs/{run_id}/stop")).json()["status"] == "stopped"


@PLACEMENTS
async def test_a_blocked_service_loop_stops_the_ticks_only_when_they_share_it(
    tmp_path: Path, engine_thread: bool
) -> None:
    async with client_for(settings_for(tmp_path, engine_thread=engine_thread)) as (client, app):
        run_id = await started_realtime(client)
        live = _manager(app).get(run_id)
        assert live is not None
        engine = live.engine
        await until(client, run_id, "running")
        before = engine.stats.ticks
        time.sleep(BLOCK_S)  # the service's loop (this test's) does nothing else meanwhile
        during = engine.stats.ticks - before
        if engine_thread:
            assert during > 0, "no tick while the service's loop was blocked"
        else:
            assert during == 0  # the ticks wait for the loop they share
        await client.post(f"/api/runs/{run_id}/stop")
        await until(client, run_id, "stopped")


@PLACEMENTS
async def test_a_control_checks_and_acts_in_one_step_on_the_engines_loop(
    tmp_path: Path, engine_thread: bool
) -> None:
    async with client_for(settings_for(tmp_path, engine_thread=engine_thread)) as (client, _):
        run_id = await started_realtime(client)
        paused = await asyncio.gather(*(client.post(f"/api/runs/{run_id}/pause") for _ in range(4)))
        # One pause wins; the others find the run paused already.
        assert sorted(r.status_code for r in paused) == [200, 409, 409, 409]
        assert (await client.post(f"/api/runs/{run_id}/resume")).json()["status"] == "running"
        assert (await client.post(f"/api/runs/{run_id}/stop")).json()["status"] == "stopped"


@PLACEMENTS
async def test_a_stream_reads_on_the_service_loop_what_the_engines_thread_offers(
    tmp_path: Path,
    engine_thread: bool,
) -> None:
    async with client_for(settings_for(tmp_path, engine_thread=engine_thread)) as (client, app):
        manager = _manager(app)
        run_id = await started_realtime(client)
        sub = manager.subscribe(run_id, maxsize=64, tick_hz=0.0)
        await client.post(f"/api/runs/{run_id}/pause")
        statuses: list[str] = []
        async with asyncio.timeout(30):  # a hang guard, not a timing
            while not statuses:
                event = await sub.get()
                if isinstance(event, StatusChanged):
                    statuses.append(event.status.value)
        assert statuses == ["paused"]
        await client.post(f"/api/runs/{run_id}/stop")
        seen = []
        async with asyncio.timeout(30):
            async for e in sub:  # until the run's end closes it
                seen.append(e)
        assert isinstance(seen[-1], StatusChanged) and seen[-1].status.value == "stopped"
        manager.unsubscribe(run_id, sub)


@PLACEMENTS
async def test_a_subscription_made_as_its_run_ends_is_closed_not_left_open(
    tmp_path: Path,
    engine_thread: bool,
) -> None:
    async with client_for(settings_for(tmp_path, engine_thread=engine_thread)) as (client, app):
        manager = _manager(app)
        run_id = await started_realtime(client)
        live = manager.get(run_id)
        assert live is not None
        await client.post(f"/api/runs/{run_id}/stop")
        # The run has ended on the engines' loop; a subscription attached now is closed.
        late = live.subscribe(8, 0.0)
        with pytest.raises(SubscriptionClosed):
            await asyncio.wait_for(late.get(), 30)


async def test_the_service_stops_with_no_engines_thread_left_and_its_run_resumable(
    tmp_path: Path,
) -> None:
    settings = settings_for(tmp_path, engine_thread=True)
    async with client_for(settings) as (client, app):
        run_id = await started_realtime(client)
        await until(client, run_id, "running")
        thread_id = _manager(app).loop.thread_id
        # The thread itself: once it has ended, a new thread may get its ident.
        engines = [t for t in threading.enumerate() if t.ident == thread_id]
    assert len(engines) == 1
    assert not engines[0].is_alive()
    async with client_for(settings) as (client, _):
        assert (await client.get(f"/api/runs/{run_id}")).json()["status"] == "interrupted"


@PLACEMENTS
async def test_a_view_read_sees_one_state_of_the_run(tmp_path: Path, engine_thread: bool) -> None:
    async with client_for(settings_for(tmp_path, engine_thread=engine_thread)) as (client, app):
        run_id = await started_realtime(client)
        live = _manager(app).get(run_id)
        assert live is not None

        def both(view: RunView) -> tuple[int, int]:
            return view.tick, view.snapshot.tick

        async with asyncio.timeout(30):  # a hang guard: until its first tick
            while (await client.get(f"/api/runs/{run_id}")).json()["ticks"] < 1:
                await asyncio.sleep(0.02)

        for _ in range(20):
            tick, snap_tick = await live.read(both)
            assert tick == snap_tick  # never a tick's count beside another tick's snapshot
            await asyncio.sleep(0.01)
        await client.post(f"/api/runs/{run_id}/stop")


def test_a_subscription_is_woken_from_another_thread() -> None:
    async def main() -> list[object]:
        sub = Subscription(4)
        got: list[object] = []

        async def read() -> None:
            async for e in sub:
                got.append(e)

        reader = asyncio.create_task(read())
        await asyncio.sleep(0)  # the reader waits

        def offer() -> None:
            for k in range(3):
                sub.offer(k)
            sub.close()

        thread = threading.Thread(target=offer)
        thread.start()
        await asyncio.wait_for(reader, 30)  # a hang guard: it hangs if nothing wakes it
        thread.join()
        return got

    assert asyncio.run(main()) == [0, 1, 2]
