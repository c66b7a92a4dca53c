"""viser's message buffers woken safely from other threads (server/viewer/wakeups.py).

The suite once lost a viewer to `RuntimeError: deque mutated during iteration`: viser's
push set its buffer's `asyncio.Event` from our connect handler's thread while the loop
changed the event's waiters. These tests pin where the waiters are touched, and that a
real viser server, and each client it accepts, uses the loop-safe buffers.
"""

from __future__ import annotations

import asyncio
import collections
import threading
import time
from collections.abc import Iterator

import pytest
import viser
from viser.infra import _infra
from viserpage import camera_message
from websockets.asyncio.client import connect
from websockets.typing import Subprotocol

from server.viewer.app import _listen
from server.viewer.wakeups import LoopEvent, LoopSafeBuffer, install

WAIT_S = 30.0
"""A bound for a hung loop, not a speed test."""


class Recorded(collections.deque[object]):
    """A waiters' deque that records which thread walks it."""

    walkers: set[int]

    def __iter__(self) -> Iterator[object]:
        self.walkers.add(threading.get_ident())
        return super().__iter__()


def walkers_of_a_foreign_set(make: type[asyncio.Event]) -> tuple[set[int], int]:
    """Set an event of kind `make` from this thread while its loop's thread awaits it.

    Returns the threads that walked its waiters and the loop's thread.
    """
    loop = asyncio.new_event_loop()
    runner = threading.Thread(target=loop.run_forever, daemon=True)
    runner.start()
    try:
        event = LoopEvent(loop) if make is LoopEvent else make()
        waiters = Recorded()
        waiters.walkers = set()
        event._waiters = waiters  # type: ignore[assignment]
        waiting = asyncio.run_coroutine_threadsafe(event.wait(), loop)
        deadline = time.monotonic() + WAIT_S
        while not waiters and time.monotonic() < deadline:
            time.sleep(0.001)
        assert waiters, "the loop never started waiting"
        event.set()
        # A plain event's foreign set() schedules its waiter's wake-up without waking the
        # loop (another hazard of the same call): wake it, so both kinds can be compared.
        loop.call_soon_threadsafe(lambda: None)
        assert waiting.result(timeout=WAIT_S) is True
        return waiters.walkers, runner.ident or 0
    finally:
        loop.call_soon_threadsafe(loop.stop)
        runner.join(WAIT_S)
        loop.close()


def test_a_set_from_another_thread_wakes_the_waiter_from_the_loops_own_thread() -> None:
    walkers, loop_thread = walkers_of_a_foreign_set(LoopEvent)
    assert walkers == {loop_thread}


def test_a_plain_asyncio_event_is_walked_by_the_setting_thread() -> None:
    """The hazard the fix removes, shown with the same probe (so the probe can fail)."""
    walkers, loop_thread = walkers_of_a_foreign_set(asyncio.Event)
    assert walkers == {threading.get_ident()}
    assert loop_thread not in walkers


def test_a_set_on_a_closed_loop_is_a_no_op() -> None:
    loop = asyncio.new_event_loop()
    loop.close()
    LoopEvent(loop).set()


def test_install_is_idempotent() -> None:
    install()
    install()
    assert _infra.AsyncMessageBuffer is LoopSafeBuffer  # type: ignore[attr-defined]


def test_a_real_viser_server_and_its_clients_use_loop_safe_buffers() -> None:
    server = _listen()
    try:
        broadcast = server._websock_server._broadcast_buffer
        assert isinstance(broadcast, LoopSafeBuffer)
        assert isinstance(broadcast.message_event, LoopEvent)
        assert isinstance(broadcast.flush_event, LoopEvent)

        seen: list[viser.ClientHandle] = []
        connected = threading.Event()

        def on_connect(client: viser.ClientHandle) -> None:
            seen.append(client)
            connected.set()

        server.on_client_connect(on_connect)
        url = f"ws://127.0.0.1:{server.get_port()}/"
        protocol = Subprotocol(f"viser-v{viser.__version__}")

        async def visit() -> None:
            async with connect(url, subprotocols=[protocol]) as socket:
                await socket.send(camera_message())  # viser's clients connect with it
                assert await asyncio.to_thread(connected.wait, WAIT_S)

        asyncio.run(visit())
        buffer = seen[0]._websock_connection.get_message_buffer()
        assert isinstance(buffer, LoopSafeBuffer)
        assert isinstance(buffer.message_event, LoopEvent)
    finally:
        server.stop()


def test_pushes_from_many_threads_all_reach_a_consumer() -> None:
    """Eight threads push while the loop drains: no push fails, none is lost."""
    loop = asyncio.new_event_loop()
    runner = threading.Thread(target=loop.run_forever, daemon=True)
    runner.start()
    buffer = LoopSafeBuffer(loop, persistent_messages=False)
    threads, each = 8, 200
    total = threads * each

    async def drain() -> int:
        received = 0
        windows = buffer.window_generator(client_id=1)
        async for window in windows:
            received += len(window)
            if received >= total:
                break
        await windows.aclose()
        return received

    draining = asyncio.run_coroutine_threadsafe(drain(), loop)
    failures: list[BaseException] = []

    def push(thread: int) -> None:
        try:
            for n in range(each):
                # Distinct names: viser coalesces same-named messages, and none may be.
                buffer.push(viser._messages.RemoveSceneNodeMessage(name=f"/t{thread}/{n}"))
        except BaseException as failure:
            failures.append(failure)

    pushers = [threading.Thread(target=push, args=(t,)) for t in range(threads)]
    try:
        for pusher in pushers:
            pusher.start()
        for pusher in pushers:
            pusher.join(WAIT_S)
        assert failures == []
        assert draining.result(timeout=WAIT_S) == total
    finally:
        loop.call_soon_threadsafe(loop.stop)
        runner.join(WAIT_S)
        loop.close()


@pytest.fixture(autouse=True, scope="module")
def _installed() -> None:
    install()
