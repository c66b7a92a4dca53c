"""Storage in a process of its own, so the service's database work runs on another core.

CPython runs one thread of Python at a time in a process. In `srlab serve` the event loop
paces every realtime run's ticks, and the storage adapters' Python (SQLAlchemy's ORM, the
rows built and read) ran in worker threads of the same process: under many runs and a
steady request load that work took the whole core, and the ticks waited for it (issue 17's
D4: 32 runs at 20 Hz under 200 requests/s, 107% of one core, p99 lateness 78 ms).

`StoreProcess` starts one process that owns the database engine and the two repositories
(runs and networks) and serves their methods over a local socket (the standard library's
`multiprocessing.managers`, one thread per calling thread). The service gets proxies with
the same public methods: a call sends its arguments, the store process runs the real method
in its own transaction and sends back the result or the exception, so what was committed
when a call returns, and the errors callers see, are the adapters' own (the contract suite
runs over the proxies too). Arguments and results are the ports' plain values.

The store process ignores Ctrl-C (the service stops it after its last writes) and exits as
soon as the service's process is gone, so a killed service leaves no process behind. If the
store process dies (a SIGBUS from a truncated WAL index kills the process that mapped it),
every call fails with a `StorageError` that says so, and the service stays up to say it.
"""

from __future__ import annotations

import faulthandler
import multiprocessing
import os
import signal
import threading
from collections.abc import Callable
from functools import partial
from multiprocessing.managers import BaseManager, BaseProxy
from typing import Any, cast

from core.errors import StorageError
from server.persistence.db import DatabaseCheck, make_engine, make_sessionmaker
from server.persistence.networks import SqlAlchemyNetworkRepository
from server.persistence.sqlalchemy_repo import SqlAlchemyRunStore
from server.tuning import configure_process, freeze_heap

# --------------------------------------------------------------------------- in the child

_stores: dict[str, object] = {}


def _open(url: str) -> None:
    """The store process's start: one engine and the objects the service calls."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the service stops us after its last write
    faulthandler.enable()
    # A thread per calling thread serves the service: with CPython's 5 ms switch interval,
    # a reward's commit waited behind an episode's or a page's read for up to 5 ms.
    configure_process()
    engine = make_engine(url)
    sessions = make_sessionmaker(engine)
    _stores["runs"] = SqlAlchemyRunStore(sessions)
    _stores["networks"] = SqlAlchemyNetworkRepository(sessions)
    _stores["database"] = DatabaseCheck(engine)
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


class _Manager(BaseManager):
    pass


for _name in ("runs", "networks", "database"):
    _Manager.register(_name, callable=partial(_get, _name))

# --------------------------------------------------------------------------- in the service


class StoreProcessError(StorageError):
    """The store process is gone: nothing more can be stored or read."""


class StoreProcess:
    """The store process and the service's proxies for its repositories."""

    def __init__(self, url: str) -> None:
        self.url = url
        self._manager = _Manager(ctx=multiprocessing.get_context("spawn"))
        self._manager.start(initializer=_open, initargs=(url,))
        self._process: multiprocessing.process.BaseProcess = self._manager._process  # type: ignore[attr-defined]
        self.pid: int = self._process.pid
        self.runs = cast(SqlAlchemyRunStore, self._proxy("runs"))
        self.networks = cast(SqlAlchemyNetworkRepository, self._proxy("networks"))
        self.database = cast(DatabaseCheck, self._proxy("database"))

    def _proxy(self, name: str) -> _Guarded:
        proxy: BaseProxy = getattr(self._manager, name)()
        return _Guarded(proxy, self)

    def alive(self) -> bool:
        """Whether the store process still runs."""
        return self._process.is_alive()

    def stop(self) -> None:
        """Stop the store process (after the service's last write)."""
        self._manager.shutdown()

    def gone(self, error: BaseException) -> StoreProcessError:
        """The error a call gets when the store process cannot answer."""
        code = self._process.exitcode
        how = f"exit code {code}" if code is not None else f"{type(error).__name__}: {error}"
        return StoreProcessError(
            f"the store process ({self.pid}) is gone ({how}): nothing more is stored "
            "(see the service's log, then restart the service)"
        )


class _Guarded:
    """A proxy whose calls fail with `StoreProcessError` when the store process is gone."""

    def __init__(self, proxy: BaseProxy, owner: StoreProcess) -> None:
        self._proxy = proxy
        self._owner = owner

    def __getattr__(self, name: str) -> Callable[..., Any]:
        if name.startswith("_"):
            raise AttributeError(name)
        method = partial(self._call, name)
        setattr(self, name, method)
        return method

    def _call(self, name: str, *args: Any, **kwargs: Any) -> Any:
        try:
            return self._proxy._callmethod(name, args, kwargs)
        except (EOFError, ConnectionError) as e:
            raise self._owner.gone(e) from None
