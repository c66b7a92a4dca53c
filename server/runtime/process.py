"""The process link: the runs' host in a process of its own, with a GIL and a core of its own.

CPython runs one thread of Python at a time in a process: on the service's loop, ticks
wait behind every request's Python. With ``SRLAB_ENGINES=process`` (`srlab serve`'s
default) the service starts one **engines' process** (`main`, a new interpreter) that runs
a `RunHost` (every run's tick, reward and writer tasks) on its own event loop, with its
own storage (SQLAlchemy in its threads), and the service's process keeps HTTP, the 3D view
and the books of which runs tick (`server.runtime.runs.Runs`).

The child's stdin and stdout carry length-prefixed pickles, in order, each way, and only
the message set of `core.engine.messages` and the host's outlet: no function crosses.

- A call (`start`, `started`, `request`, `shutdown`) has an id and is answered by its
  result or by the exception it raised there (re-raised here).
- The host's outlet (a run started, its state, its end) and each subscription's events
  come in the order the host produced them: a run's state before the answer or the
  events that follow a change, so what `Runs` says of a run without asking is never older
  than an answer or an event read after it.
- A subscription is made here and mirrored in the child, whose events for it come in
  batches; the child's copy drops the oldest when the pipe is behind, as any subscription
  does when its reader is.

The child ignores Ctrl-C (the service stops it: `shutdown`, then end of input) and stops
its runs as interrupted, resumable, when its input ends, so a killed service leaves no
engines ticking. If the child dies, every run here fails with an error that says so, every
call gets `EngineProcessError` (503) meanwhile, and the service stays up to say it and
starts a new child (after `RESPAWN_FIRST_S`, then twice as long, at least a second, after
each start that fails, up to `RESPAWN_MAX_S`): new runs tick there, and the failed ones
can be started again from their checkpoints. The new child is started by the service's
process, so it shares the service's lowered priority (`server.runtime.tuning.step_back`).
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import os
import pickle
import signal
import struct
import sys
from concurrent.futures import ThreadPoolExecutor
from functools import partial
from typing import TYPE_CHECKING, Any

from core.brain.catalog import Catalog
from core.engine import Subscription
from core.engine.messages import Command, Query, RunState
from core.errors import StorageError
from core.ports import RunSpec
from server.runtime.host import RunHost
from server.runtime.runs import Runs

if TYPE_CHECKING:
    pass

log = logging.getLogger("srlab.engines")

_HEADER = struct.Struct("!I")
PIPE_LIMIT = 1 << 26
"""The largest message either side reads (64 MiB: a long run's read fits many times)."""
EVENTS_HIGH_WATER = 1 << 20
"""Bytes waiting in the child's pipe above which its subscriptions wait (and drop)."""
STOP_S = 15.0
"""How long `close` waits for the child to exit after its input ends, before killing it."""
RESPAWN_FIRST_S = 1.0
"""How long after the child died a new one is started."""
RESPAWN_MAX_S = 60.0
"""The longest wait between two starts of a child that keeps failing to start."""
SQLITE_STORAGE_THREADS = 1
"""The engines' process's storage threads on SQLite (`storage_threads`)."""


class EngineProcessError(StorageError):
    """The engines' process is gone: no run can tick, be read or be controlled."""


def _frame(message: object) -> bytes:
    body = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    return _HEADER.pack(len(body)) + body


async def _read(reader: asyncio.StreamReader) -> Any:
    (size,) = _HEADER.unpack(await reader.readexactly(_HEADER.size))
    return pickle.loads(await reader.readexactly(size))


# --------------------------------------------------------------------------- in the service


class ProcessLink:
    """`Runs`' link to a `RunHost` in the engines' process (`server.runtime.runs.Link`).

    `await start_process(...)` starts the child; `shutdown` stops the runs (resumable),
    `close` ends the child.
    """

    def __init__(self, runs: Runs) -> None:
        self.runs = runs
        self._proc: asyncio.subprocess.Process | None = None
        self._writer: asyncio.StreamWriter | None = None
        self._pump: asyncio.Task[None] | None = None
        self._ids = itertools.count(1)
        self._calls: dict[int, asyncio.Future[Any]] = {}
        self._starting: set[int] = set()
        self._subs: dict[int, Subscription] = {}
        """The subscriptions here fed from the child, by the id their copy there has."""
        self._sub_ids: dict[Subscription, int] = {}
        self._gone: EngineProcessError | None = None
        self._closing = False
        self._config: dict[str, Any] = {}
        self._respawner: asyncio.Task[None] | None = None

    # --- the child ------------------------------------------------------------------

    async def start_process(self, config: dict[str, Any]) -> None:
        """Start the engines' process with `config` (`server.config.Settings`' fields)."""
        self._config = dict(config)
        await self._start_child()

    async def _start_child(self) -> None:
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
        proc = await asyncio.create_subprocess_exec(
            sys.executable,
            "-c",
            # Not `-m`: the module would be `__main__` there, and its classes pickled so.
            "from server.runtime.process import main; main()",
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

    async def _call(self, op: str, *args: object) -> Any:
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
        await self._lost()
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
            case ("started", run_id, spec, state, catalog):
                self.runs.heard_started(run_id, spec, state, catalog)
            case ("state", run_id, state, catalog):
                self.runs.heard_state(run_id, state, catalog)
            case ("ended", run_id, state, let_go):
                self.runs.heard_ended(run_id, state, let_go)
            case ("events", sub_id, events):
                if (sub := self._subs.get(sub_id)) is not None:
                    for event in events:
                        sub.offer(event)
            case ("closed", sub_id):
                if (sub := self._subs.get(sub_id)) is not None:
                    sub.close()
            case ("batch", messages):
                for each in messages:
                    self._handle(each)

    async def _lost(self) -> None:
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
        for sub in self._subs.values():
            sub.close()
        self._calls.clear()
        self._subs.clear()
        self._sub_ids.clear()
        await self.runs.heard_lost(str(self._gone))

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

    # --- the link -------------------------------------------------------------------

    async def start(self, run_id: int) -> None:
        """Start a stored run there (heard of as started before the answer)."""
        self._starting.add(run_id)
        try:
            await self._call("start", run_id)
        finally:
            self._starting.discard(run_id)

    async def started(self, run_id: int, timeout_s: float) -> None:
        """Wait until a started run ticks (or has already ended)."""
        await self._call("started", run_id, timeout_s)

    async def request(self, run_id: int, message: Command | Query) -> Any:
        """The host's answer to a command or query."""
        return await self._call("request", run_id, message)

    def running(self) -> int:
        """How many runs are ticking, paused or starting there, as known here."""
        return len(self._starting) + sum(1 for r in self.runs.engines() if not r.done.is_set())

    def outage(self) -> str | None:
        """The engines' process gone (None: it serves), seen on the pipe without asking."""
        return None if self._gone is None else str(self._gone)

    def subscribe(
        self, run_id: int, maxsize: int, tick_hz: float, *, next_start: bool = True
    ) -> Subscription:
        """A subscription here fed by its copy in the child (`Link.subscribe`)."""
        sub = Subscription(maxsize, tick_hz)
        if self._gone is not None:
            sub.close()
            return sub
        sub_id = next(self._ids)
        self._subs[sub_id] = sub
        self._sub_ids[sub] = sub_id
        self._send(("subscribe", sub_id, run_id, maxsize, tick_hz, next_start))
        return sub

    def unsubscribe(self, sub: Subscription) -> None:
        """Stop feeding a subscription `subscribe` made, and close it."""
        sub.close()
        sub_id = self._sub_ids.pop(sub, None)
        if sub_id is None:
            return
        self._subs.pop(sub_id, None)
        if self._gone is None:
            self._send(("unsubscribe", sub_id))

    def interrupt_all(self) -> None:
        """Ask every run to end at its next tick boundary, as interrupted (resumable)."""
        if self._gone is None:
            self._send(("interrupt_all",))

    async def shutdown(self, grace_s: float) -> None:
        """Interrupt every run there and wait for them (they stay resumable)."""
        if self._gone is None:
            with contextlib.suppress(EngineProcessError):
                await self._call("shutdown", grace_s)


# --------------------------------------------------------------------------- in the child


class _Serve:
    """The child's side: a `RunHost` on this process's loop, served over the pipe.

    It is the host's outlet too: what the host says goes into the pipe as it happens.
    """

    OPS = frozenset({"start", "started", "request", "shutdown"})

    def __init__(self, writer: asyncio.StreamWriter) -> None:
        self.writer = writer
        self.host: RunHost
        self._outbox: list[object] = []
        """What was sent during this turn of the loop: one frame at its end."""
        self._mirrors: dict[int, asyncio.Task[None]] = {}
        self._tasks: set[asyncio.Task[None]] = set()

    def send(self, message: object) -> None:
        """Send `message` at the end of this turn of the loop, with what else was sent in it.

        Many runs publish events and states in one turn: one frame (one pickling, one write
        to the pipe) carries them all, in the order they were sent.
        """
        if not self._outbox:
            asyncio.get_running_loop().call_soon(self.flush)
        self._outbox.append(message)

    def flush(self) -> None:
        """Write what waits to be sent now."""
        messages, self._outbox = self._outbox, []
        if messages:
            self.writer.write(_frame(messages[0] if len(messages) == 1 else ("batch", messages)))

    # --- the host's outlet ----------------------------------------------------------

    def run_started(self, run_id: int, spec: RunSpec, state: RunState, catalog: Catalog) -> None:
        self.send(("started", run_id, spec, state, catalog))

    def run_state(self, run_id: int, state: RunState, catalog: Catalog | None) -> None:
        self.send(("state", run_id, state, catalog))

    def run_ended(self, run_id: int, state: RunState, let_go: bool) -> None:
        self.send(("ended", run_id, state, let_go))

    # --- the service's messages -----------------------------------------------------

    async def serve(self, reader: asyncio.StreamReader) -> None:
        """Serve the service's messages until its input ends."""
        while True:
            try:
                message = await _read(reader)
            except (asyncio.IncompleteReadError, ConnectionError):
                return
            match message:
                case ("call", call_id, op, blob):
                    task = asyncio.create_task(self._call(call_id, op, blob))
                    self._tasks.add(task)
                    task.add_done_callback(self._tasks.discard)
                case ("subscribe", sub_id, run_id, maxsize, tick_hz, next_start):
                    self._mirrors[sub_id] = self.host.subscribe(
                        run_id,
                        Subscription(maxsize, tick_hz),
                        partial(self._deliver, sub_id),
                        next_start=next_start,
                    )
                    self._mirrors[sub_id].add_done_callback(partial(self._closed, sub_id))
                case ("unsubscribe", sub_id):
                    mirror = self._mirrors.pop(sub_id, None)
                    if mirror is not None:
                        mirror.cancel()
                case ("interrupt_all",):
                    self.host.interrupt_all()

    async def _call(self, call_id: int, op: str, blob: bytes) -> None:
        try:
            if op not in self.OPS:
                raise ValueError(f"no such call: {op!r}")
            value = await getattr(self.host, op)(*pickle.loads(blob))
            ok = True
        except Exception as e:
            value, ok = e, False
        try:
            frame = _frame(("result", call_id, ok, value))
            if not ok:
                pickle.loads(frame[_HEADER.size :])  # an error the service can rebuild
        except Exception as e:  # say what it was instead
            frame = _frame(("result", call_id, False, RuntimeError(f"{op}: {e!r} ({value!r})")))
        self.flush()  # what was sent before the result goes before it
        self.writer.write(frame)

    async def _deliver(self, sub_id: int, events: list[object]) -> None:
        self.send(("events", sub_id, events))
        if self.writer.transport.get_write_buffer_size() > EVENTS_HIGH_WATER:
            await self.writer.drain()

    def _closed(self, sub_id: int, _: object) -> None:
        self._mirrors.pop(sub_id, None)
        with contextlib.suppress(Exception):  # the pipe may be gone: we are stopping
            self.send(("closed", sub_id))


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


def storage_threads(database_url: str) -> int | None:
    """How many threads the engines' process's storage calls run on (None: asyncio's default).

    Every run's writes (`core.engine.writer`: a reward's log entry, its learning, the
    episodes) go through `asyncio.to_thread`. SQLite takes one writer at a time, so on a
    SQLite file they share one thread (`SQLITE_STORAGE_THREADS`): each write queued
    behind another is taken without waking a thread, and no thread waits for SQLite's
    write lock or its turn in `server.persistence.grouping`. Fewer threads waking each
    want the GIL less often, and the event loop loses it at every call into pymunk while
    one does. 32 runs at 10 Hz with 200 rewards a second: 0.77-0.92 -> 0.50-0.65 ms of the
    process's CPU a reward. PostgreSQL, with a network round trip a write, keeps asyncio's
    pool, whose writes `GroupedWrites` shares.
    """
    from server.persistence.db import parse_database_url

    if parse_database_url(database_url).get_backend_name() == "sqlite":
        return SQLITE_STORAGE_THREADS
    return None


async def _child(read_fd: int, write_fd: int) -> None:
    from server.config import Settings
    from server.persistence.storage import open_storage
    from server.runtime.reads import QUERIES
    from server.runtime.tuning import configure_process, warm_up

    configure_process()
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
        threads = storage_threads(settings.database_url)
        if threads is not None:
            loop.set_default_executor(
                ThreadPoolExecutor(threads, thread_name_prefix="srlab-storage")
            )
        storage = await asyncio.to_thread(open_storage, settings)
    except Exception as e:
        writer.write(_frame(f"{type(e).__name__}: {e}"))
        await writer.drain()
        return
    try:
        serve = _Serve(writer)
        serve.host = RunHost(storage.runs, settings.max_runs, serve, QUERIES)
        await warm_up()
        writer.write(_frame("ready"))
        try:
            await serve.serve(reader)
        finally:
            await serve.host.shutdown()
            with contextlib.suppress(Exception):
                serve.flush()
                await writer.drain()
    finally:
        await asyncio.to_thread(storage.close)


def main() -> None:
    """The engines' process (the service starts it: `ProcessLink.start_process`)."""
    read_fd, write_fd = _configure_child()
    asyncio.run(_child(read_fd, write_fd))
