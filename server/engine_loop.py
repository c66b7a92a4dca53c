"""Where the service's runs tick: the service's own event loop, or one in a thread of its own.

The engines' loop runs every run's tick task, reward task and writer tasks. By default it
is the service's loop, which also answers HTTP; with ``SRLAB_ENGINE_THREAD=true`` it is a
loop of its own in a thread of its own. What each costs (`bench/service.py --part
engines`, docs/benchmarks.md): on the service's loop, a burst of requests (500 stream
connections to refuse) is one pass of the loop and a tick due meanwhile waits for all of
it (hundreds of milliseconds); on their own thread, a due tick takes the GIL within about
the interpreter's switch interval (`server.tuning`) even then, but under steady load the
engines' thread waits for the GIL at every wake-up, and ticks and answers run later than
on one loop. CPython has one GIL per process: only a process of their own would give the
engines both.

Two rules keep the two loops apart:

1. **A run's state belongs to the engines' loop.** The service calls a run through its
   `LiveRun`: every call (`reward`, `edit`, `pause`, `read`, ...) runs on the engines' loop
   and is awaited from the service's; reads go through `LiveRun.read`, which runs the
   reader there, between two steps of the run's tasks, so it sees one consistent state.
   The only attributes read from the service's thread are single references the engine
   replaces whole (`status`, `hz`, `error`, the catalogue).
2. **The manager's books belong to the service's loop.** `server.engines.EngineManager`
   changes its dicts of runs, tasks and streams only there; a run's end reaches it as the
   completion of a future on that loop.

Events cross the other way through `core.engine.bus.Subscription`, which an engine fills
from its thread and the service reads on its own loop.

With ``thread=False`` the engines tick on the service's own loop through the same calls,
which then run directly (no hop).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import logging
import threading
from collections.abc import Callable, Coroutine, Sequence
from typing import Any, TypeVar

from core.brain.catalog import Catalog
from core.commands import EditAssociation, RewardSource
from core.engine import RewardAck, RunEngine, RunView, Subscription
from core.ports import RunSpec, RunStatus, RunTotals

log = logging.getLogger("srlab.engines")
T = TypeVar("T")

STOP_GRACE_S = 5.0
"""How long stopping the loop waits for the tasks still on it after cancelling them."""


class EngineLoop:
    """An asyncio event loop for the engines, in a daemon thread (or the caller's loop).

    `start` it from the service's loop; `run` and `call` then carry work onto it and are
    awaited from the service's loop; `stop` ends whatever is left on it and joins the
    thread.
    """

    def __init__(self, *, thread: bool = True) -> None:
        self.threaded = thread
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None

    @property
    def loop(self) -> asyncio.AbstractEventLoop:
        """The engines' loop (`RuntimeError` before `start`)."""
        if self._loop is None:
            raise RuntimeError("the engines' loop has not started")
        return self._loop

    async def start(self) -> None:
        """Start the loop's thread (or take the running loop, unthreaded)."""
        if not self.threaded:
            self._loop = asyncio.get_running_loop()
            return
        loop = asyncio.new_event_loop()
        ready = threading.Event()

        def main() -> None:
            asyncio.set_event_loop(loop)
            loop.call_soon(ready.set)
            try:
                loop.run_forever()
            finally:
                with contextlib.suppress(Exception):
                    loop.run_until_complete(loop.shutdown_default_executor())
                loop.close()

        self._thread = threading.Thread(target=main, name="srlab engines", daemon=True)
        self._thread.start()
        await asyncio.to_thread(ready.wait)
        self._loop = loop

    @property
    def thread_id(self) -> int | None:
        """The engines' thread's id (None: unthreaded, or not started)."""
        return self._thread.ident if self._thread is not None else None

    def submit(self, coro: Coroutine[Any, Any, T]) -> concurrent.futures.Future[T]:
        """Schedule `coro` on the engines' loop; its result as a thread-safe future."""
        return asyncio.run_coroutine_threadsafe(coro, self.loop)

    async def run(self, coro: Coroutine[Any, Any, T]) -> T:
        """Run `coro` on the engines' loop and await its result here.

        Cancelling the caller cancels it there too. Unthreaded, it is awaited directly.
        """
        if not self.threaded:
            return await coro
        return await asyncio.wrap_future(self.submit(coro))

    async def call(self, fn: Callable[..., T], *args: object) -> T:
        """Call `fn(*args)` on the engines' loop, between two steps of its tasks.

        Unthreaded, it is called directly: the caller runs between two steps already.
        """
        if not self.threaded:
            return fn(*args)

        async def there() -> T:
            return fn(*args)

        return await self.run(there())

    def post(self, fn: Callable[..., object], *args: object) -> None:
        """Call `fn(*args)` on the engines' loop soon, without waiting (in order of posting).

        Nothing happens once the loop has closed (the service is stopping).
        """
        loop = self._loop
        if loop is None or loop.is_closed():
            return
        with contextlib.suppress(RuntimeError):  # closed between the check and the call
            loop.call_soon_threadsafe(fn, *args)

    async def stop(self, grace_s: float = STOP_GRACE_S) -> None:
        """Cancel what is still on the loop, let it finish, then end the loop's thread."""
        if not self.threaded or self._loop is None or self._thread is None:
            return
        loop, thread = self._loop, self._thread

        async def settle() -> None:
            here = asyncio.current_task()
            tasks = [t for t in asyncio.all_tasks() if t is not here]
            for t in tasks:
                t.cancel()
            if tasks:
                await asyncio.wait(tasks, timeout=grace_s)

        if loop.is_running():
            with contextlib.suppress(Exception):
                await self.run(settle())
            loop.call_soon_threadsafe(loop.stop)
        await asyncio.to_thread(thread.join, grace_s + 5.0)
        if thread.is_alive():
            log.warning("the engines' thread did not end within %.0f s", grace_s + 5.0)
        self._thread = None
        self._loop = None


class LiveRun:
    """A run ticking on the engines' loop, as the service's loop calls and reads it.

    Every method runs on the engines' loop and is awaited here (see the module's rules).
    """

    __slots__ = ("_engine", "_loop", "run_id", "spec")

    def __init__(self, engine: RunEngine, loop: EngineLoop) -> None:
        self._engine = engine
        self._loop = loop
        self.run_id = engine.run_id
        self.spec: RunSpec = engine.spec
        """What the run was started with (its mode as it runs)."""

    @property
    def engine(self) -> RunEngine:
        """The engine itself: touch it only on the engines' loop (tests, the manager)."""
        return self._engine

    @property
    def status(self) -> RunStatus:
        """The run's status as last set (one reference, replaced whole)."""
        return self._engine.status

    @property
    def error(self) -> str | None:
        """Why the run failed (None: it has not)."""
        return self._engine.error

    @property
    def hz(self) -> float:
        """The realtime tick rate."""
        return self._engine.hz

    @property
    def catalog(self) -> Catalog:
        """The brain's catalogue of now (immutable: KP's growth replaces it whole)."""
        return self._engine.view().catalog

    async def read(self, reader: Callable[[RunView], T]) -> T:
        """`reader(view)` on the engines' loop: one consistent state of the run.

        Keep it short and make it return copies or values: it runs between two steps of
        the run's tasks, and what it returns is read on another thread.
        """
        return await self._loop.call(lambda: reader(self._engine.view()))

    async def totals(self) -> RunTotals:
        """Episodes, successes and ticks so far."""
        return await self.read(lambda v: v.totals)

    async def reward(
        self, value: float, *, note: str = "", source: RewardSource = RewardSource.TRAINER
    ) -> RewardAck:
        """`RunEngine.reward`: answered once the reward is in the reward log."""
        return await self._loop.run(self._engine.reward(value, note=note, source=source))

    async def edit(self, command: EditAssociation) -> int:
        """`RunEngine.edit`: answered with the edit's log id once it is applied and stored."""
        return await self._loop.run(self._engine.edit(command))

    async def edit_all(self, commands: Sequence[EditAssociation]) -> list[int | BaseException]:
        """Edits queued together, so they land at the same tick boundary, in order.

        Each answers its log id, or the error that refused it.
        """

        async def there() -> list[int | BaseException]:
            edits = (self._engine.edit(c) for c in commands)
            return await asyncio.gather(*edits, return_exceptions=True)

        return await self._loop.run(there())

    async def step(self) -> int:
        """`RunEngine.step`: one tick of a paused realtime run; the tick it ran."""
        return await self._loop.run(self._engine.step())

    async def control(self, action: Callable[[RunEngine], T]) -> T:
        """`action(engine)` on the engines' loop (pause, resume, stop, a rate change, ...)."""
        return await self._loop.call(action, self._engine)

    def subscribe(self, maxsize: int, tick_hz: float) -> Subscription:
        """A subscription to the run's events, fed from the engines' loop's next turn.

        Read it on this loop; `unsubscribe` it when done.
        """
        sub = Subscription(maxsize, tick_hz)
        self.attach(sub)
        return sub

    def attach(self, sub: Subscription) -> None:
        """Feed an existing subscription from the engines' loop's next turn on."""
        self._loop.post(self._engine.attach, sub)

    def unsubscribe(self, sub: Subscription) -> None:
        """Stop feeding a subscription (closed here at once)."""
        sub.close()
        self._loop.post(self._engine.unsubscribe, sub)

    def __repr__(self) -> str:
        return f"LiveRun(run {self.run_id}, {self.status.value})"


__all__ = ["EngineLoop", "LiveRun"]
