"""Storage in a process of its own, so the service's database work runs on another core.

CPython runs one thread of Python at a time in a process. In `srlab serve` the event loop
paces every realtime run's ticks, and the storage adapters' Python (SQLAlchemy's ORM, the
rows built and read) ran in worker threads of the same process: under many runs and a
steady request load that work took the whole core, and the ticks waited for it
(`bench.service --part day`'s D4: 32 runs at 20 Hz under 200 requests/s, 107% of one core,
p99 lateness 78 ms).

`StoreProcess` starts one process that owns the database engine and the two repositories
(runs and networks) and serves their methods over a local socket (the standard library's
`multiprocessing.managers`, one thread per calling thread). The service gets proxies with
the same public methods: a call sends its arguments, the store process runs the real method
in its own transaction and sends back the result or the exception, so what was committed
when a call returns, and the errors callers see, are the adapters' own (the contract suite
runs over the proxies too). Arguments and results are the ports' plain values.

The store process opens its database before it serves (a store that cannot open it does
not start), ignores Ctrl-C (the service stops it after its last writes) and exits as soon
as the service's process is gone, so a killed service leaves no process behind.

If the store process dies (kill -9, or a SIGBUS from a truncated WAL index, which kills
the process that mapped it), a supervisor thread notices at once and starts a new one:
`RESTART_FIRST_S` after a death, twice as long after each start that fails or each death
soon after a start, up to `RESTART_MAX_S`, and back to `RESTART_FIRST_S` once a store
process has served for `RESTART_STEADY_S`. Every call in flight when it died, and every
call made until a new one serves, fails at once with a `StoreProcessError` that says so;
no call is sent twice, so the store's transaction rules are the adapters' own across a
restart. A SQLite file keeps the identity its first store process pinned
(`SqliteFileGuard`): a store process started again on a file deleted or replaced meanwhile
does not start.
"""

from __future__ import annotations

import faulthandler
import logging
import multiprocessing
import os
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from multiprocessing.connection import Connection, wait
from multiprocessing.managers import BaseManager, BaseProxy
from typing import Any, cast

from core.errors import StorageError
from server.persistence.db import (
    DatabaseCheck,
    make_engine,
    make_sessionmaker,
    sqlite_guard,
)
from server.persistence.networks import SqlAlchemyNetworkRepository
from server.persistence.sqlalchemy_repo import SqlAlchemyRunStore
from server.tuning import configure_process, freeze_heap

log = logging.getLogger("srlab.storage")

RESTART_FIRST_S = 0.1
"""How long after a store process died a new one is started."""
RESTART_MAX_S = 5.0
"""The longest wait between two starts of a store process that keeps failing."""
RESTART_STEADY_S = 10.0
"""A store process that served this long died of something new: the waits start over."""
STOP_WAIT_S = 30.0
"""How long `stop` waits for a restart under way to end."""

Identity = tuple[int, int]
"""A SQLite file's device and inode (`SqliteFileGuard.identity`)."""

# --------------------------------------------------------------------------- in the child

_stores: dict[str, object] = {}


def _open(url: str, identity: Identity | None, report: Connection) -> None:
    """The store process's start: one engine, the database opened, the objects served.

    `report` gets ("ok", the SQLite file's identity) or ("error", why); on an error the
    process exits (code 3) before it serves.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the service stops us after its last write
    faulthandler.enable()
    # A thread per calling thread serves the service: with CPython's 5 ms switch interval,
    # a reward's commit waited behind an episode's or a page's read for up to 5 ms.
    configure_process()
    try:
        engine = make_engine(url)
        guard = sqlite_guard(engine)
        if guard is not None and identity is not None:
            guard.identity = identity  # the file the service first opened, or none
        database = DatabaseCheck(engine)
        database.check()  # a store that cannot open its database does not start
    except Exception as e:
        report.send(("error", str(e) or type(e).__name__))
        report.close()
        raise SystemExit(3) from None
    sessions = make_sessionmaker(engine)
    _stores["runs"] = SqlAlchemyRunStore(sessions)
    _stores["networks"] = SqlAlchemyNetworkRepository(sessions)
    _stores["database"] = database
    report.send(("ok", guard.identity if guard is not None else None))
    report.close()
    freeze_heap()
    parent = multiprocessing.parent_process()
    if parent is not None:
        threading.Thread(target=_exit_with, args=(parent,), daemon=True).start()


def _exit_with(parent: multiprocessing.process.BaseProcess) -> None:
    """Exit as soon as the service's process is gone (killed, or crashed)."""
    parent.join()
    os._exit(0)


def _get(name: str) -> object:
    return _stores[name]


STORES = ("runs", "networks", "database")


class _Manager(BaseManager):
    pass


for _name in STORES:
    _Manager.register(_name, callable=partial(_get, _name))

# --------------------------------------------------------------------------- in the service


class StoreProcessError(StorageError):
    """The store process is gone: nothing is stored or read until a new one serves."""


@dataclass
class _Serving:
    """One store process that started, and the service's proxies for its objects."""

    manager: _Manager
    process: multiprocessing.process.BaseProcess
    pid: int
    proxies: dict[str, BaseProxy]
    started: float = field(default_factory=time.monotonic)


Watcher = Callable[[StoreProcessError | None], None]
"""Told each change: the error calls get while the store process is down, or None."""


class StoreProcess:
    """The store process, its supervisor, and the service's proxies for its repositories.

    `name` is how errors and the log call it (the service's or the engines' store process).
    """

    def __init__(self, url: str, *, name: str = "the store process") -> None:
        self.url = url
        self.name = name
        self._ctx = multiprocessing.get_context("spawn")
        self._identity: Identity | None = None
        self._lock = threading.Lock()
        self._stopping = threading.Event()
        self._watchers: list[Watcher] = []
        started = self._start()  # at the service's start a failure is the service's
        self._now: _Serving | StoreProcessError = started
        self._supervisor = threading.Thread(
            target=self._supervise, args=(started,), name=f"{name}'s supervisor", daemon=True
        )
        self._supervisor.start()
        self.runs = cast(SqlAlchemyRunStore, _Guarded("runs", self))
        self.networks = cast(SqlAlchemyNetworkRepository, _Guarded("networks", self))
        self.database = cast(DatabaseCheck, _Guarded("database", self))

    @property
    def pid(self) -> int | None:
        """The serving store process's pid (None while it is down)."""
        now = self._now
        return now.pid if isinstance(now, _Serving) else None

    def alive(self) -> bool:
        """Whether a store process serves."""
        now = self._now
        return isinstance(now, _Serving) and now.process.is_alive()

    def down(self) -> StoreProcessError | None:
        """The error calls get while no store process serves (None: one does)."""
        now = self._now
        return now if isinstance(now, StoreProcessError) else None

    def watch(self, watcher: Watcher) -> None:
        """Tell `watcher` how things stand, at once, then each change (from the supervisor)."""
        with self._lock:
            self._watchers.append(watcher)
            watcher(self.down())

    def serving(self) -> _Serving:
        """The store process that serves; its error while none does."""
        now = self._now
        if isinstance(now, StoreProcessError):
            raise now
        return now

    def stop(self) -> None:
        """Stop the store process (after the service's last write); none is started again."""
        with self._lock:  # a new one is either serving now or never will
            self._stopping.set()
            now = self._now
        if isinstance(now, _Serving):
            now.manager.shutdown()
        self._supervisor.join(STOP_WAIT_S)

    def gone(self, serving: _Serving, error: BaseException) -> StoreProcessError:
        """The error a call to `serving` gets when its store process cannot answer."""
        down = self.down()
        if down is not None:
            return down
        return StoreProcessError(
            f"{self.name} is down, restarting ({serving.pid} stopped answering: "
            f"{type(error).__name__}): nothing is stored or read until it serves again"
        )

    # --- starting and watching ------------------------------------------------------

    def _start(self) -> _Serving:
        """A new store process, serving; `StoreProcessError` saying why if it did not start."""
        reports, report = self._ctx.Pipe(duplex=False)
        manager = _Manager(ctx=self._ctx)
        try:
            manager.start(initializer=_open, initargs=(self.url, self._identity, report))
            process: multiprocessing.process.BaseProcess = manager._process  # type: ignore[attr-defined]
        except (EOFError, OSError) as e:
            failed = getattr(manager, "_process", None)
            code = _exit_code(failed) if failed is not None else None
            why = _report(reports) or (_cause(code) if failed is not None else repr(e))
            reports.close()
            raise StoreProcessError(f"{self.name} did not start: {why}") from None
        finally:
            report.close()  # ours: the store process has its own
        answer = _report(reports, full=True)
        reports.close()
        if isinstance(answer, tuple) and answer[0] == "ok":
            self._identity = self._identity or answer[1]
        try:
            proxies = {name: getattr(manager, name)() for name in STORES}
        except (EOFError, OSError) as e:  # it died as it started
            manager.shutdown()
            why = f"{_cause(process.exitcode)} as it started ({type(e).__name__})"
            raise StoreProcessError(f"{self.name} did not start: {why}") from None
        return _Serving(manager, process, process.pid or 0, proxies)

    def _supervise(self, serving: _Serving) -> None:
        """Start a new store process each time the serving one dies, until `stop`."""
        wait_s = RESTART_FIRST_S
        while True:
            wait([serving.process.sentinel])
            if self._stopping.is_set():
                return
            cause = _cause(_exit_code(serving.process))
            serving.manager.shutdown()  # its books only
            if time.monotonic() - serving.started >= RESTART_STEADY_S:
                wait_s = RESTART_FIRST_S
            log.error(
                "%s (%d) died (%s): starting it again in %g s",
                self.name,
                serving.pid,
                cause,
                wait_s,
            )
            self._change(
                StoreProcessError(
                    f"{self.name} is down, restarting ({serving.pid} died: {cause}): nothing "
                    "is stored or read until it serves again"
                )
            )
            while True:
                if self._stopping.wait(wait_s):
                    return
                wait_s = min(RESTART_MAX_S, 2 * wait_s)
                try:
                    started = self._start()
                except Exception as e:  # the supervisor goes on whatever a start did
                    if not isinstance(e, StoreProcessError):
                        log.exception("%s could not be started", self.name)
                        e = StoreProcessError(f"{self.name} did not start: {e!r}")
                    log.error("%s; trying again in %g s", e, wait_s)
                    self._change(
                        StoreProcessError(
                            f"{self.name} is down, restarting (its last start failed: "
                            f"{str(e).removeprefix(self.name + ' did not start: ')}; next try "
                            f"in {wait_s:g} s): nothing is stored or read until it serves again"
                        )
                    )
                    continue
                break
            if not self._change(started):
                started.manager.shutdown()  # `stop` came first
                return
            log.warning("%s was started again (pid %d)", self.name, started.pid)
            serving = started

    def _change(self, now: _Serving | StoreProcessError) -> bool:
        """Make `now` how things stand and tell the watchers; False once stopping."""
        with self._lock:
            if self._stopping.is_set():
                return False
            self._now = now
            down = now if isinstance(now, StoreProcessError) else None
            for watcher in self._watchers:
                try:
                    watcher(down)
                except Exception:  # a watcher's fault is not the store's
                    log.exception("%s: a watcher failed", self.name)
            return True


def _report(reports: Connection, *, full: bool = False) -> Any:
    """What the store process reported of its start (its error's text unless `full`)."""
    try:
        if not reports.poll():
            return None
        answer = reports.recv()
    except (EOFError, OSError):
        return None
    if full:
        return answer
    return answer[1] if answer[0] == "error" else None


def _exit_code(process: multiprocessing.process.BaseProcess) -> int | None:
    """A dead process's exit code, reaped (None if another thread's reaping hides it)."""
    process.join(STOP_WAIT_S)
    for _ in range(100):
        if (code := process.exitcode) is not None:
            return code
        time.sleep(0.01)
    return None


def _cause(code: int | None) -> str:
    """An exit code as the log and errors say it."""
    if code is None:
        return "exit status unknown"
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit code {code}"


class _Guarded:
    """A proxy whose calls go to the serving store process, or fail with its error."""

    def __init__(self, store: str, owner: StoreProcess) -> None:
        self._store = store
        self._owner = owner

    def __getattr__(self, name: str) -> Callable[..., Any]:
        if name.startswith("_"):
            raise AttributeError(name)
        method = partial(self._call, name)
        setattr(self, name, method)
        return method

    def _call(self, name: str, *args: Any, **kwargs: Any) -> Any:
        serving = self._owner.serving()
        try:
            return serving.proxies[self._store]._callmethod(name, args, kwargs)
        except (EOFError, ConnectionError) as e:
            raise self._owner.gone(serving, e) from None
