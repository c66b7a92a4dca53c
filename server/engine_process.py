"""The runs in a process of their own: ticks with a GIL and a core of their own.

CPython runs one thread of Python at a time in a process. On the service's loop, ticks
wait behind every request's Python; on a thread of their own (`server.engine_loop`), they
wait for the GIL at every wake-up instead. With ``SRLAB_ENGINE_PROCESS=true`` the service
starts one **engines' process** (`main`, in a new interpreter) that runs every
run's tick, reward and writer tasks on its own event loop, with its own storage (a store
process of its own when the service has one), and the service's process keeps HTTP, the
3D view and the books of which runs tick.

The service reaches the runs through `ProcessEngines` and `RemoteRun`, which are
`server.engines.Engines` and `server.engines.Live` over a pipe: the child's stdin and
stdout carry length-prefixed pickles, in order, each way.

- A call (`start`, `read`, `reward`, `edit`, `control`, ...) is a request with an id,
  answered by its result or by the exception it raised there (re-raised here). Readers
  and actions travel pickled, so they are module-level functions, partials or
  `operator.methodcaller`s (the `Live` protocol says so).
- Before a call's answer, and before a batch of a run's events, the child sends the run's
  state (status, error, rate, and its catalogue when KP replaced it) if it changed since
  it last did, so what `RemoteRun.status` or `.catalog` says here is never older than an
  answer or an event read after it. A status change with no call or event around it
  (a run finishing its episodes) is sent as it happens.
- A subscription is made here (a `core.engine.Subscription`, capped here) and mirrored in
  the child, whose events for it come in batches; the child's copy drops the oldest when
  the pipe is behind, as any subscription does when its reader is.
- A run whose engine the child let go (its end stored) is let go here too.

The child ignores Ctrl-C (the service stops it: `shutdown`, then end of input) and stops
its runs as interrupted, resumable, when its input ends, so a killed service leaves no
engines ticking. If the child dies, every run here fails with an error that says so, every
call gets `EngineProcessError` (503) meanwhile, and the service stays up to say it and
starts a new child (after `RESPAWN_FIRST_S`, then twice as long, at least a second, after
each start that fails, up to `RESPAWN_MAX_S`): new runs tick there, and the failed ones
can be started again from their checkpoints. The new child is started by the service's
process, so it shares the service's lowered priority (`server.tuning.step_back`).

The child's own store process is started again by its supervisor when it dies
(`server.persistence.process`); the child tells the service each time it goes down and
serves again, so `outage` (and `/api/health`) says so without asking the child.
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib
import itertools
import logging
import os
import pickle
import signal
import struct
import sys
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from functools import partial
from typing import TYPE_CHECKING, Any, TypeVar

from core.brain.catalog import Catalog
from core.commands import EditAssociation, RewardSource
from core.engine import RewardAck, RunEngine, RunView, Subscription, SubscriptionClosed
from core.errors import StorageError
from core.ports import ACTIVE, NetworkPair, RunSpec, RunStatus, RunStore, RunTotals
from server.engine_loop import LiveRun
from server.engines import (
    EngineManager,
    Live,
    RunLetGo,
    StreamBook,
    create_run,
)

if TYPE_CHECKING:
    from server.persistence.process import StoreProcess

log = logging.getLogger("srlab.engines")
T = TypeVar("T")

_HEADER = struct.Struct("!I")
PIPE_LIMIT = 1 << 26
"""The largest message either side reads (64 MiB: a long run's read fits many times)."""
PRELOADED = ("server.live_reads",)
"""Modules whose functions the service sends (`LiveRun.read`, `LiveRun.control`), loaded
at the process's start: unpickling a function imports its module, which on a run's first
read would otherwise happen on the engines' loop while runs tick."""
EVENTS_HIGH_WATER = 1 << 20
"""Bytes waiting in the child's pipe above which its subscriptions wait (and drop)."""
STOP_S = 15.0
"""How long `close` waits for the child to exit after its input ends, before killing it."""
RESPAWN_FIRST_S = 1.0
"""How long after the child died a new one is started."""
RESPAWN_MAX_S = 60.0
"""The longest wait between two starts of a child that keeps failing to start."""


class EngineProcessError(StorageError):
    """The engines' process is gone: no run can tick, be read or be controlled."""


def _frame(message: object) -> bytes:
    body = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    return _HEADER.pack(len(body)) + body


async def _read(reader: asyncio.StreamReader) -> Any:
    (size,) = _HEADER.unpack(await reader.readexactly(_HEADER.size))
    return pickle.loads(await reader.readexactly(size))


@dataclass(frozen=True, slots=True)
class RunState:
    """What the service keeps of a run the child runs: read without asking the child."""

    status: RunStatus
    error: str | None
    hz: float
    catalog: Catalog | None
    """None: unchanged since the last state sent."""


def _totals(view: RunView) -> RunTotals:
    return view.totals


# --------------------------------------------------------------------------- in the service


class RemoteRun:
    """A run ticking in the engines' process, as the service reaches it (`Live`)."""

    def __init__(self, owner: ProcessEngines, run_id: int, spec: RunSpec, state: RunState) -> None:
        self._owner = owner
        self.run_id = run_id
        self.spec = spec
        assert state.catalog is not None
        self._catalog = state.catalog
        self._state = state
        self.done = asyncio.Event()
        """Set when the child's task for the run has ended."""

    def update(self, state: RunState) -> None:
        """Take the state the child sent."""
        if state.catalog is not None:
            self._catalog = state.catalog
        self._state = state

    @property
    def status(self) -> RunStatus:
        """The run's status, as the child last said."""
        return self._state.status

    @property
    def error(self) -> str | None:
        """Why the run failed (None: it has not)."""
        return self._state.error

    @property
    def hz(self) -> float:
        """The realtime tick rate."""
        return self._state.hz

    @property
    def catalog(self) -> Catalog:
        """The brain's catalogue, as of the last answer or event from the child."""
        return self._catalog

    async def read(self, reader: Callable[[RunView], T]) -> T:
        """`reader(view)` in the engines' process (pickled: no lambdas)."""
        result: T = await self._owner.call("read", self.run_id, reader)
        return result

    async def totals(self) -> RunTotals:
        """Episodes, successes and ticks so far."""
        return await self.read(_totals)

    async def reward(
        self, value: float, *, note: str = "", source: RewardSource = RewardSource.TRAINER
    ) -> RewardAck:
        """`RunEngine.reward`, there: answered once the reward is in the reward log."""
        ack: RewardAck = await self._owner.call("reward", self.run_id, value, note, source)
        return ack

    async def edit(self, command: EditAssociation) -> int:
        """`RunEngine.edit`, there."""
        edit_id: int = await self._owner.call("edit", self.run_id, command)
        return edit_id

    async def edit_all(self, commands: Sequence[EditAssociation]) -> list[int | BaseException]:
        """Edits landing at one tick boundary, in order: each one's log id or its error."""
        out: list[int | BaseException] = await self._owner.call(
            "edit_all", self.run_id, list(commands)
        )
        return out

    async def step(self) -> int:
        """`RunEngine.step`, there."""
        tick: int = await self._owner.call("step", self.run_id)
        return tick

    async def control(self, action: Callable[[RunEngine], T]) -> T:
        """`action(engine)` in the engines' process (pickled: no lambdas)."""
        result: T = await self._owner.call("control", self.run_id, action)
        return result

    def subscribe(self, maxsize: int, tick_hz: float) -> Subscription:
        """A subscription to the run's events (not counted against the stream caps)."""
        return self._owner.mirror(self.run_id, maxsize, tick_hz)

    def unsubscribe(self, sub: Subscription) -> None:
        """Stop feeding a subscription (closed here at once)."""
        self._owner.drop(sub)

    def __repr__(self) -> str:
        return f"RemoteRun(run {self.run_id}, {self.status.value})"


class ProcessEngines:
    """The service's runs, ticking in the engines' process (`Engines`).

    `await ProcessEngines.start_process(...)` starts the child; `shutdown` stops the runs
    (resumable), `close` ends the child.
    """

    def __init__(
        self, store: RunStore, *, max_streams: int = 64, max_streams_per_run: int = 16
    ) -> None:
        self.store = store
        """The service's storage: runs are created here, and failures stored when the
        child is gone (the child has its own for everything else)."""
        self._streams = StreamBook(max_streams, max_streams_per_run)
        self._proc: asyncio.subprocess.Process | None = None
        self._writer: asyncio.StreamWriter | None = None
        self._pump: asyncio.Task[None] | None = None
        self._ids = itertools.count(1)
        self._calls: dict[int, asyncio.Future[Any]] = {}
        self._runs: dict[int, RemoteRun] = {}
        self._starting: set[int] = set()
        self._subs: dict[int, Subscription] = {}
        """The subscriptions here fed from the child, by the id their copy there has."""
        self._sub_ids: dict[Subscription, int] = {}
        self._gone: EngineProcessError | None = None
        self._closing = False
        self._new: dict[int, RemoteRun] = {}
        """Runs the child has just started, until `start` takes them (they may have ended
        and been let go by then)."""
        self._config: dict[str, Any] = {}
        self._respawner: asyncio.Task[None] | None = None
        self._store_down: str | None = None
        """Why the child's store process is down, as the child last said (None: it serves)."""

    # --- the child ------------------------------------------------------------------

    async def start_process(self, config: dict[str, Any]) -> None:
        """Start the engines' process with `config` (`_ChildConfig`'s fields)."""
        self._config = dict(config)
        await self._start_child()

    async def _start_child(self) -> None:
        # What this process can import, the child can: readers and actions travel by name.
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
        proc = await asyncio.create_subprocess_exec(
            sys.executable,
            "-c",
            # Not `-m`: the module would be `__main__` there, and its classes pickled so.
            "from server.engine_process import main; main()",
            stdin=asyncio.subprocess.PIPE,
            stdout=asyncio.subprocess.PIPE,
            limit=PIPE_LIMIT,
            env=env,
        )
        assert proc.stdin is not None and proc.stdout is not None
        self._proc, self._writer = proc, proc.stdin
        self._writer.write(_frame(self._config))
        try:
            ready = await _read(proc.stdout)
        except (asyncio.IncompleteReadError, ConnectionError, EOFError):
            ready = f"it exited (code {await proc.wait()})"
        if ready != "ready":
            raise EngineProcessError(f"the engines' process did not start: {ready}")
        self._gone = None
        self._store_down = None  # a new child's store process serves: it said ready
        self._pump = asyncio.create_task(self._receive(proc.stdout), name="engines' process")

    @property
    def pid(self) -> int | None:
        """The engines' process's pid (None: not started)."""
        return self._proc.pid if self._proc is not None else None

    def _send(self, message: object) -> None:
        if self._gone is not None:
            raise self._gone
        assert self._writer is not None
        self._writer.write(_frame(message))

    async def call(self, op: str, *args: object) -> Any:
        """Run `op` in the engines' process; its result, or its exception raised here."""
        call_id = next(self._ids)
        fut: asyncio.Future[Any] = asyncio.get_running_loop().create_future()
        # Pickled apart, so arguments the child cannot rebuild fail this call only.
        self._send(("call", call_id, op, pickle.dumps(args, pickle.HIGHEST_PROTOCOL)))
        self._calls[call_id] = fut
        try:
            return await fut
        finally:
            self._calls.pop(call_id, None)

    async def _receive(self, reader: asyncio.StreamReader) -> None:
        try:
            while True:
                self._handle(await _read(reader))
        except (asyncio.IncompleteReadError, ConnectionError, EOFError):
            pass
        except Exception:
            log.exception("the engines' process's messages could not be read")
        if self._proc is not None:
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(STOP_S):
                    await self._proc.wait()  # for its exit code
        self._lost()
        for run_id in await asyncio.to_thread(self._store_failed, tuple(self._runs.values())):
            self._runs.pop(run_id, None)  # read from storage from now on
        if not self._closing:
            self._respawner = asyncio.create_task(self._respawn(), name="engines' respawn")

    async def _respawn(self) -> None:
        """Start a new child in place of the one that died, until one starts."""
        wait_s = RESPAWN_FIRST_S
        while True:
            await asyncio.sleep(wait_s)
            if self._closing:
                return
            try:
                await self._start_child()
            except Exception as e:
                wait_s = min(RESPAWN_MAX_S, max(1.0, 2 * wait_s))
                log.error("%s; trying again in %.0f s", e, wait_s)
                continue
            log.warning("the engines' process was started again (pid %s)", self.pid)
            return

    def _handle(self, message: tuple[Any, ...]) -> None:
        """Take one message from the child (in the order it sent them)."""
        match message:
            case ("result", call_id, ok, value):
                fut = self._calls.get(call_id)
                if fut is not None and not fut.done():
                    if ok:
                        fut.set_result(value)
                    else:
                        fut.set_exception(value)
            case ("run", run_id, spec, state):
                started = RemoteRun(self, run_id, spec, state)
                self._runs[run_id] = self._new[run_id] = started
                self._streams.started(run_id, started)
            case ("state", run_id, state):
                if (run := self._runs.get(run_id)) is not None:
                    run.update(state)
            case ("events", sub_id, events):
                if (sub := self._subs.get(sub_id)) is not None:
                    for event in events:
                        sub.offer(event)
            case ("closed", sub_id):
                if (sub := self._subs.get(sub_id)) is not None:
                    sub.close()
            case ("storage", down):
                self._store_down = down
            case ("ended", run_id, state, let_go):
                if (run := self._runs.get(run_id)) is not None:
                    run.update(state)
                    run.done.set()
                    if let_go:
                        del self._runs[run_id]

    def _lost(self) -> None:
        """The child is gone: fail what waits on it, end every run and stream here."""
        code = self._proc.returncode if self._proc is not None else None
        if not self._closing:
            log.error("the engines' process has exited (code %s): no run can tick", code)
        self._gone = EngineProcessError(
            f"the engines' process is gone (exit code {code}): no run can tick until the "
            "service has started a new one (see the service's log)"
        )
        for fut in self._calls.values():
            if not fut.done():
                fut.set_exception(self._gone)
        for run in self._runs.values():
            if run.status in ACTIVE:
                run.update(RunState(RunStatus.FAILED, str(self._gone), run.hz, None))
            run.done.set()
        for sub in self._subs.values():
            sub.close()
        self._calls.clear()
        self._subs.clear()
        self._sub_ids.clear()
        self._new.clear()

    def _store_failed(self, runs: tuple[RemoteRun, ...]) -> list[int]:
        """Store how the child's runs ended (it could not: it is gone); the ids stored.

        Blocking: called in a thread. The service is the runs' only other writer.
        """
        stored = []
        for run in runs:
            try:
                if self.store.load_run(run.run_id).status in ACTIVE:
                    self.store.set_status(run.run_id, run.status, run.error)
            except StorageError as e:  # says what failed; storage's own log has the rest
                log.error("run %s: its failure could not be stored: %s", run.run_id, e)
                continue
            stored.append(run.run_id)
        return stored

    async def close(self) -> None:
        """End the engines' process (after `shutdown`): its input ends, it exits."""
        self._closing = True
        if self._respawner is not None:
            self._respawner.cancel()
            await asyncio.gather(self._respawner, return_exceptions=True)
        proc, writer = self._proc, self._writer
        if proc is None or writer is None:
            return
        with contextlib.suppress(Exception):
            writer.close()
        try:
            async with asyncio.timeout(STOP_S):
                await proc.wait()
        except TimeoutError:
            log.warning("the engines' process did not exit within %.0f s: killed", STOP_S)
            proc.kill()
            await proc.wait()
        if self._pump is not None:
            await asyncio.gather(self._pump, return_exceptions=True)

    # --- Engines --------------------------------------------------------------------

    def get(self, run_id: int) -> RemoteRun | None:
        """The run ticking or paused there (or one whose end is not stored)."""
        return self._runs.get(run_id)

    def engines(self) -> Iterable[RemoteRun]:
        """Every run the engines' process has an engine for (a copy)."""
        return tuple(self._runs.values())

    def running(self) -> int:
        """How many runs are ticking, paused or starting."""
        return len(self._starting) + sum(1 for r in self._runs.values() if not r.done.is_set())

    def outage(self) -> str | None:
        """The engines' process or its store process down (None: both serve).

        Read from what is known here, without asking the child: its death is seen on the
        pipe, and the child says when its store process goes down and comes back.
        """
        if self._gone is not None:
            return str(self._gone)
        return self._store_down

    def create(self, spec: RunSpec, network: tuple[NetworkPair, ...] | None) -> int:
        """Store a new run (`create_run`; blocking: call in a thread)."""
        return create_run(self.store, spec, network)

    async def start(self, run_id: int) -> RemoteRun:
        """Start a stored run there (`EngineManager.start`: same checks, same errors)."""
        self._starting.add(run_id)
        try:
            await self.call("start", run_id)
        finally:
            self._starting.discard(run_id)
        # Made as the child said it started, before any later message about it.
        return self._new.pop(run_id)

    async def started(self, run_id: int, timeout_s: float = 5.0) -> None:
        """Wait until a started run ticks (or has already ended)."""
        if run_id in self._runs:
            await self.call("started", run_id, timeout_s)

    async def ended(self, run_id: int, timeout_s: float) -> bool:
        """Wait up to `timeout_s` for a run's task to end; whether it has."""
        run = self._runs.get(run_id)
        if run is None:
            return True
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(timeout_s):
                await run.done.wait()
        return run.done.is_set()

    def streams(self, run_id: int | None = None) -> int:
        """How many subscriptions `subscribe` gave are open (to one run, or to all)."""
        return self._streams.count(run_id)

    def followed(self, run_id: int) -> Live | None:
        """The run a stream to `run_id` follows (`Engines.followed`)."""
        return self.get(run_id) or self._streams.followed(run_id)

    def subscribe(self, run_id: int, maxsize: int, tick_hz: float) -> Subscription:
        """A run's events, now or from its next start (`EngineManager.subscribe`'s caps)."""
        self._streams.admit(run_id)
        sub = self.mirror(run_id, maxsize, tick_hz)
        self._streams.add(run_id, sub)
        return sub

    def mirror(self, run_id: int, maxsize: int, tick_hz: float) -> Subscription:
        """A subscription here fed by its copy in the child (uncapped)."""
        sub = Subscription(maxsize, tick_hz)
        if self._gone is not None:
            sub.close()
            return sub
        sub_id = next(self._ids)
        self._subs[sub_id] = sub
        self._sub_ids[sub] = sub_id
        self._send(("subscribe", sub_id, run_id, maxsize, tick_hz))
        return sub

    def drop(self, sub: Subscription) -> None:
        """Stop feeding a subscription `mirror` made, and close it."""
        sub.close()
        sub_id = self._sub_ids.pop(sub, None)
        if sub_id is None:
            return
        self._subs.pop(sub_id, None)
        if self._gone is None:
            self._send(("unsubscribe", sub_id))

    def unsubscribe(self, run_id: int, sub: Subscription) -> None:
        """Stop feeding a subscription `subscribe` gave."""
        self.drop(sub)
        self._streams.discard(run_id, sub)

    def interrupt_all(self) -> None:
        """Ask every run to end at its next tick boundary, as interrupted (resumable)."""
        if self._gone is None:
            self._send(("interrupt_all",))

    async def shutdown(self, grace_s: float = 5.0) -> None:
        """Interrupt every run there and wait for them (they stay resumable)."""
        if self._gone is None:
            with contextlib.suppress(EngineProcessError):
                await self.call("shutdown", grace_s)


# --------------------------------------------------------------------------- in the child


class _Host:
    """The child's side: an `EngineManager` on this process's loop, served over the pipe."""

    def __init__(self, manager: EngineManager, writer: asyncio.StreamWriter) -> None:
        self.manager = manager
        self.writer = writer
        self._sent: dict[int, tuple[RunStatus, str | None, float, Catalog]] = {}
        """What was last sent of each run's state (the catalogue itself: KP replaces it)."""
        self._mirrors: dict[int, asyncio.Task[None]] = {}
        self._tasks: set[asyncio.Task[None]] = set()

    def send(self, message: object) -> None:
        self.writer.write(_frame(message))

    def watch_storage(self, process: StoreProcess) -> None:
        """Tell the service each time the store process goes down or serves again."""
        loop = asyncio.get_running_loop()

        def changed(down: StorageError | None) -> None:  # on the supervisor's thread
            with contextlib.suppress(RuntimeError):  # the loop closed: we are stopping
                said = None if down is None else str(down)
                loop.call_soon_threadsafe(self.send, ("storage", said))

        process.watch(changed)

    def sync(self, run_id: int) -> None:
        """Send the run's state if it changed since it was last sent."""
        live = self.manager.get(run_id)
        if live is None:
            return
        engine = live.engine
        catalog = engine.view().catalog
        now = (engine.status, engine.error, engine.hz, catalog)
        last = self._sent.get(run_id)
        new_catalog = last is None or last[3] is not catalog
        if not new_catalog and last is not None and last[:3] == now[:3]:
            return
        self._sent[run_id] = now
        changed = catalog if new_catalog else None
        self.send(("state", run_id, RunState(now[0], now[1], now[2], changed)))

    async def serve(self, reader: asyncio.StreamReader) -> None:
        """Serve the service's messages until its input ends."""
        while True:
            try:
                message = await _read(reader)
            except (asyncio.IncompleteReadError, ConnectionError):
                return
            kind = message[0]
            if kind == "call":
                self._spawn(self._call(*message[1:]))
            elif kind == "subscribe":
                _, sub_id, run_id, maxsize, tick_hz = message
                sub = self.manager.subscribe(run_id, maxsize, tick_hz)
                self._mirrors[sub_id] = asyncio.create_task(self._forward(sub_id, run_id, sub))
            elif kind == "unsubscribe":
                task = self._mirrors.pop(message[1], None)
                if task is not None:
                    task.cancel()
            elif kind == "interrupt_all":
                self.manager.interrupt_all()

    def _spawn(self, coro: Any) -> None:
        task = asyncio.create_task(coro)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _call(self, call_id: int, op: str, blob: bytes) -> None:
        run_id = None
        try:
            args = pickle.loads(blob)
            run_id = args[0] if args and isinstance(args[0], int) else None
            value = await getattr(self, f"op_{op}")(*args)
            ok = True
        except Exception as e:
            value, ok = e, False
        if run_id is not None:
            self.sync(run_id)
        try:
            frame = _frame(("result", call_id, ok, value))
            if not ok:
                pickle.loads(frame[_HEADER.size :])  # an error the service can rebuild
        except Exception as e:  # say what it was instead
            frame = _frame(("result", call_id, False, RuntimeError(f"{op}: {e!r} ({value!r})")))
        self.writer.write(frame)

    async def _forward(self, sub_id: int, run_id: int, sub: Subscription) -> None:
        """Send a subscription's events in batches; the service's copy reads them."""
        try:
            while True:
                try:
                    first = await sub.get()
                except SubscriptionClosed:
                    break
                events = [first, *sub.drain()]
                self.sync(run_id)  # a new catalogue before the events that name it
                self.send(("events", sub_id, events))
                if self.writer.transport.get_write_buffer_size() > EVENTS_HIGH_WATER:
                    await self.writer.drain()
            self.send(("closed", sub_id))
        finally:
            self.manager.unsubscribe(run_id, sub)
            self._mirrors.pop(sub_id, None)

    def _watch(self, run_id: int) -> None:
        """Send the run's status changes as they come, and its end."""
        live = self.manager.get(run_id)
        if live is None:
            return
        engine = live.engine

        async def statuses() -> None:
            while True:
                await engine.next_status()
                self.sync(run_id)

        watcher = asyncio.create_task(statuses())

        def ended(_: object) -> None:
            watcher.cancel()
            self.sync(run_id)
            state = RunState(engine.status, engine.error, engine.hz, None)
            self._sent.pop(run_id, None)
            self.send(("ended", run_id, state, self.manager.get(run_id) is not live))

        self.manager.when_ended(run_id, ended)

    # --- the calls ------------------------------------------------------------------

    def _live(self, run_id: int) -> LiveRun:
        live = self.manager.get(run_id)
        if live is None:  # it ended, and the service has not heard yet
            raise RunLetGo(f"run {run_id} is not running here")
        return live

    async def op_start(self, run_id: int) -> None:
        live = await self.manager.start(run_id)
        engine = live.engine
        self._sent[run_id] = (engine.status, engine.error, engine.hz, live.catalog)
        state = RunState(engine.status, engine.error, engine.hz, live.catalog)
        self.send(("run", run_id, live.spec, state))
        self._watch(run_id)

    async def op_started(self, run_id: int, timeout_s: float) -> None:
        await self.manager.started(run_id, timeout_s)

    async def op_read(self, run_id: int, reader: Callable[[RunView], Any]) -> Any:
        return await self._live(run_id).read(reader)

    async def op_reward(
        self, run_id: int, value: float, note: str, source: RewardSource
    ) -> RewardAck:
        ack: RewardAck = await self._live(run_id).reward(value, note=note, source=source)
        return ack

    async def op_edit(self, run_id: int, command: EditAssociation) -> int:
        edit_id: int = await self._live(run_id).edit(command)
        return edit_id

    async def op_edit_all(
        self, run_id: int, commands: list[EditAssociation]
    ) -> list[int | BaseException]:
        out: list[int | BaseException] = await self._live(run_id).edit_all(commands)
        return out

    async def op_step(self, run_id: int) -> int:
        tick: int = await self._live(run_id).step()
        return tick

    async def op_control(self, run_id: int, action: Callable[[RunEngine], Any]) -> Any:
        return await self._live(run_id).control(action)

    async def op_shutdown(self, grace_s: float) -> None:
        await self.manager.shutdown(grace_s)


def _configure_child() -> tuple[int, int]:
    """The pipe's two ends; stdout becomes stderr, so a stray print cannot corrupt it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the service stops us
    read_fd, write_fd = os.dup(0), os.dup(1)
    os.dup2(2, 1)
    null = os.open(os.devnull, os.O_RDONLY)
    os.dup2(null, 0)
    os.close(null)
    logging.basicConfig(
        level=logging.INFO, format="%(levelname)s:     [engines] %(name)s: %(message)s"
    )
    return read_fd, write_fd


def preload() -> None:
    """Import `PRELOADED` (before any run ticks here)."""
    for name in PRELOADED:
        importlib.import_module(name)


async def _child(read_fd: int, write_fd: int) -> None:
    from core.setup import Setup
    from server.config import Settings
    from server.engine_loop import EngineLoop
    from server.persistence.storage import open_storage
    from server.tuning import configure_process, warm_up

    configure_process()
    preload()
    loop = asyncio.get_running_loop()
    reader = asyncio.StreamReader(limit=PIPE_LIMIT)
    await loop.connect_read_pipe(
        lambda: asyncio.StreamReaderProtocol(reader), os.fdopen(read_fd, "rb", 0)
    )
    transport, protocol = await loop.connect_write_pipe(
        lambda: asyncio.streams.FlowControlMixin(), os.fdopen(write_fd, "wb", 0)
    )
    writer = asyncio.StreamWriter(transport, protocol, None, loop)
    config = await _read(reader)
    try:
        settings = Settings(**config)
        storage = await asyncio.to_thread(
            partial(open_storage, settings, name="the engines' store process")
        )
    except Exception as e:
        writer.write(_frame(f"{type(e).__name__}: {e}"))
        await writer.drain()
        return
    try:
        engine_loop = EngineLoop(thread=False)
        await engine_loop.start()
        manager = EngineManager(
            storage.runs,
            Setup().catalog(),
            settings.max_runs,
            loop=engine_loop,
            # The service caps streams; these are its mirrors.
            max_streams=1 << 30,
            max_streams_per_run=1 << 30,
        )
        await warm_up()
        host = _Host(manager, writer)
        host.send("ready")
        if storage.process is not None:
            host.watch_storage(storage.process)
        try:
            await host.serve(reader)
        finally:
            await manager.shutdown()
            with contextlib.suppress(Exception):
                await writer.drain()
    finally:
        await asyncio.to_thread(storage.close)


def main() -> None:
    """The engines' process (the service starts it: `ProcessEngines.start_process`)."""
    read_fd, write_fd = _configure_child()
    asyncio.run(_child(read_fd, write_fd))
