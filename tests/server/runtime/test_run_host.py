"""The runs' host and the message set the service reaches it by (`server.runtime`).

Without timing anything: on the local link the ticks share the service's loop (a blocked
loop stops them; `test_process_link.py` pins that the process link's do not); a control
checks and acts in one step; a stream carries a run's events and ends with it; a
subscription made as its run ends is closed; a query reads one state of the run; what
crosses to the engines' process is data (no function), loads nothing there that its start
did not, and neither FastAPI nor viser.
"""

from __future__ import annotations

import asyncio
import io
import pickle
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from apphelpers import client_for, settings_for, started_realtime, until

from bench.liveserver import ROOT
from core.commands import EditAssociation, InjectReward
from core.engine import StatusChanged, Subscription, SubscriptionClosed
from core.engine.messages import (
    EditBatch,
    Latest,
    LatestTick,
    Pause,
    Resume,
    SetRate,
    Step,
    Stop,
)
from core.events import RewardApplied
from server.runtime import Runs
from server.runtime.local import LocalLink
from server.runtime.reads import InspectKp

pytestmark = pytest.mark.anyio

BLOCK_S = 0.5
"""How long a test holds the service's loop: many 50 Hz periods on any machine."""

LINKS = ["local", pytest.param("process", marks=pytest.mark.slow)]
"""Both links; the process link's tests each start an engines' process."""

SENT = (
    InjectReward(0.5, note="good"),
    EditAssociation("Corner", "leftturn90", 0.7),
    EditBatch((EditAssociation("Corner", "leftturn90", None),)),
    Pause(),
    Resume(),
    Step(),
    Stop(),
    SetRate(5.0),
    Latest(),
    InspectKp(),
)
"""Every kind of message the service sends a run."""


def _runs(app: object) -> Runs:
    runs = app.state.srlab.engines  # type: ignore[attr-defined]
    assert isinstance(runs, Runs)
    return runs


class _Recorder(pickle.Unpickler):
    """Unpickles, noting every module-level object the pickle names."""

    def __init__(self, blob: bytes) -> None:
        super().__init__(io.BytesIO(blob))
        self.named: list[object] = []

    def find_class(self, module: str, name: str) -> object:
        found = super().find_class(module, name)
        self.named.append(found)
        return found


def test_every_message_is_data_no_function_crosses() -> None:
    for message in SENT:
        recorder = _Recorder(pickle.dumps(message, pickle.HIGHEST_PROTOCOL))
        assert recorder.load() == message
        assert recorder.named, "a message names its class"
        for obj in recorder.named:
            assert isinstance(obj, type), f"{message!r} carries {obj!r}, which is not a type"


CHILD = """
import pickle, sys
from server.runtime.process import main  # what the engines' process starts from
import server.runtime.reads  # and loads before its first run
before = set(sys.modules)
for blob in pickle.loads(sys.stdin.buffer.read()):
    pickle.loads(blob)
print(" ".join(sorted(set(sys.modules) - before)) or "-")
print(" ".join(m for m in ("fastapi", "starlette", "viser") if m in sys.modules) or "-")
"""


@pytest.mark.slow  # a subprocess
def test_the_engines_process_has_loaded_what_a_message_unpickles() -> None:
    # Unpickling imports a message's module: on the engines' loop, while runs tick, a
    # route module (FastAPI with it) once held every run for 170 ms.
    blobs = pickle.dumps([pickle.dumps(m) for m in SENT])
    done = subprocess.run(
        [sys.executable, "-c", CHILD],
        input=blobs,
        capture_output=True,
        cwd=ROOT,
        check=True,
        timeout=120,
    )
    imported, web = done.stdout.decode().split("\n")[:2]
    assert imported == "-", f"unpickling imported {imported} on the engines' loop"
    assert web == "-", f"the engines' process loaded {web}"


async def test_a_blocked_service_loop_stops_the_ticks_of_the_local_host(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, app):
        runs = _runs(app)
        assert isinstance(runs.link, LocalLink)
        run_id = await started_realtime(client)
        engine = runs.link.engine(run_id)
        assert engine is not None
        await until(client, run_id, "running")
        before = engine.stats.ticks
        time.sleep(BLOCK_S)  # the service's loop (this test's) does nothing else meanwhile
        assert engine.stats.ticks == before  # the ticks wait for the loop they share
        await client.post(f"/api/runs/{run_id}/stop")
        await until(client, run_id, "stopped")


@pytest.mark.parametrize("engines", LINKS)
async def test_a_control_checks_and_acts_in_one_step(tmp_path: Path, engines: str) -> None:
    async with client_for(settings_for(tmp_path, engines=engines)) as (client, _):
        run_id = await started_realtime(client)
        paused = await asyncio.gather(*(client.post(f"/api/runs/{run_id}/pause") for _ in range(4)))
        # One pause wins; the others find the run paused already.
        assert sorted(r.status_code for r in paused) == [200, 409, 409, 409]
        assert (await client.post(f"/api/runs/{run_id}/resume")).json()["status"] == "running"
        assert (await client.post(f"/api/runs/{run_id}/stop")).json()["status"] == "stopped"


@pytest.mark.parametrize("engines", LINKS)
async def test_a_stream_carries_the_runs_events_and_ends_with_it(
    tmp_path: Path, engines: str
) -> None:
    async with client_for(settings_for(tmp_path, engines=engines)) as (client, app):
        runs = _runs(app)
        run_id = await started_realtime(client)
        sub = runs.subscribe(run_id, maxsize=64, tick_hz=0.0)
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
        runs.unsubscribe(run_id, sub)
        assert runs.streams() == 0


@pytest.mark.parametrize("engines", LINKS)
async def test_a_subscription_made_as_its_run_ends_is_closed_not_left_open(
    tmp_path: Path, engines: str
) -> None:
    async with client_for(settings_for(tmp_path, engines=engines)) as (client, app):
        runs = _runs(app)
        run_id = await started_realtime(client)
        live = runs.get(run_id)
        assert live is not None
        await client.post(f"/api/runs/{run_id}/stop")
        # The run has ended where it ticks; a subscription attached now is closed.
        late = live.subscribe(8, 0.0)
        with pytest.raises(SubscriptionClosed):
            await asyncio.wait_for(late.get(), 30)


@pytest.mark.parametrize("engines", LINKS)
async def test_a_query_reads_one_state_of_the_run(tmp_path: Path, engines: str) -> None:
    async with client_for(settings_for(tmp_path, engines=engines)) as (client, app):
        run_id = await started_realtime(client)
        live = _runs(app).get(run_id)
        assert live is not None
        async with asyncio.timeout(30):  # a hang guard: until its first tick
            while (await client.get(f"/api/runs/{run_id}")).json()["ticks"] < 1:
                await asyncio.sleep(0.02)
        for _ in range(20):
            now: LatestTick | None = await live.ask(Latest())
            assert now is not None
            # Never a tick's count beside another tick's snapshot.
            assert now.totals.ticks == now.snapshot.tick
            await asyncio.sleep(0.01)
        await client.post(f"/api/runs/{run_id}/stop")


@pytest.mark.parametrize("engines", LINKS)
async def test_an_answer_comes_after_the_state_it_changed(tmp_path: Path, engines: str) -> None:
    # What the service says of a run without asking is never older than an answer.
    async with client_for(settings_for(tmp_path, engines=engines)) as (client, app):
        run_id = await started_realtime(client)
        live = _runs(app).get(run_id)
        assert live is not None
        await live.send(Pause())
        assert live.status.value == "paused"
        tick = await live.send(Step())
        assert live.state.tick == tick
        await live.send(SetRate(7.0))
        assert live.hz == 7.0
        await live.send(Stop())


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


@pytest.mark.parametrize("engines", LINKS)
async def test_a_reward_keeps_the_id_it_got_on_arrival(tmp_path: Path, engines: str) -> None:
    # The trainer's answer, the stream's event and the log name the reward alike, and a run
    # resumed from its log keeps it: nothing has to match rewards by what they look like.
    async with client_for(settings_for(tmp_path, engines=engines)) as (client, app):
        run_id = await started_realtime(client)
        sub = _runs(app).subscribe(run_id, maxsize=512, tick_hz=0.0)
        answers = [
            (await client.post(f"/api/runs/{run_id}/rewards", json={"value": 1.0})).json()
            for _ in range(2)
        ]
        uids = [a["uid"] for a in answers]
        assert len(set(uids)) == 2 and all(len(u) == 32 for u in uids)  # alike but two
        streamed: dict[str, int] = {}
        async with asyncio.timeout(30):  # a hang guard: both come within a few ticks
            while len(streamed) < 2:
                event = await sub.get()
                if isinstance(event, RewardApplied) and event.source == "trainer":
                    streamed[event.uid] = event.tick
        assert set(streamed) == set(uids)
        _runs(app).unsubscribe(run_id, sub)
        await client.post(f"/api/runs/{run_id}/stop")
        log = (await client.get(f"/api/runs/{run_id}/rewards")).json()["data"]
        mine = {r["uid"]: r["id"] for r in log if r["source"] == "trainer"}
        assert mine == {a["uid"]: a["id"] for a in answers}
        own = [r["uid"] for r in log if r["source"] != "trainer"]
        assert all(own) and len(set(own)) == len(own)  # the run's own rewards have theirs


async def test_a_followed_run_sends_its_figures_on_their_clock_not_with_each_event(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Before each batch of a stream's events the host publishes the run's catalogue if it
    # changed, not the whole state: with hundreds of followed runs that doubled what
    # crossed to the service. The figures follow every STATE_PERIOD_S (here: never).
    from server.runtime import host

    monkeypatch.setattr(host, "STATE_PERIOD_S", 3600.0)
    states: list[int] = []
    heard = LocalLink.run_state

    def counted(self: LocalLink, run_id: int, *args: object) -> None:
        states.append(run_id)
        heard(self, run_id, *args)  # type: ignore[arg-type]

    monkeypatch.setattr(LocalLink, "run_state", counted)
    async with client_for(settings_for(tmp_path, engines="local")) as (client, app):
        runs = _runs(app)
        run_id = await started_realtime(client)
        sub = runs.subscribe(run_id, maxsize=64, tick_hz=50.0)
        ticks = 0
        async with asyncio.timeout(30):  # a hang guard, not a timing
            while ticks < 2:  # the stream is fed
                ticks += type(await sub.get()).__name__ == "TickPublished"
            before = len(states)
            while ticks < 12:
                ticks += type(await sub.get()).__name__ == "TickPublished"
        assert len(states) == before  # ten ticks' events, no state with them
        await client.post(f"/api/runs/{run_id}/stop")
        runs.unsubscribe(run_id, sub)
