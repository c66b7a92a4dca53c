"""The Ray backend: experiment and sweep tasks on a Ray cluster (the optional `srlab[ray]`).

Tasks are the core's pure `run_task` calls, shipped to Ray workers as they are, so a
task gives the same result on Ray as in a local process. Without an address a private
local Ray instance with `jobs` CPUs is started (and stopped afterwards); with one
(``auto``, ``host:6379``, ``ray://host:10001``, or ``RAY_ADDRESS``) an existing cluster is
joined. A driver that is already connected (a notebook, a test) is used as it is.
"""

from __future__ import annotations

import logging
import os
import socket
from collections.abc import Iterator, Sequence
from pathlib import Path
from types import ModuleType, TracebackType
from typing import Any
from urllib.parse import urlsplit

import core
from core.lab.experiment import Task, TaskFunction, TaskResult, run_task
from server.backends.errors import BackendError

RAY_EXTRA = "pip install 'srlab[ray]'"
CONNECT_TIMEOUT_S = 5.0
OBJECT_STORE_BYTES = 128 * 1024 * 1024
"""A private local instance's object store: results are small, so keep /dev/shm free."""


def import_ray() -> ModuleType:
    """The `ray` module, or a BackendError that says how to install it."""
    try:
        import ray
    except ImportError:
        raise BackendError(
            f"the ray backend needs Ray: {RAY_EXTRA} (or `uv sync --extra ray`)"
        ) from None
    return ray


def _host_port(address: str) -> tuple[str, int] | None:
    """The (host, port) a concrete address names; None for ``auto`` and ``local``."""
    if address in ("auto", "local"):
        return None
    url = urlsplit(address if "://" in address else f"//{address}")
    if url.scheme not in ("", "ray"):
        raise BackendError(f"Ray address {address!r}: use auto, HOST:PORT or ray://HOST:PORT")
    try:
        port = url.port
    except ValueError:
        port = None
    if not url.hostname or port is None:
        raise BackendError(f"Ray address {address!r}: use auto, HOST:PORT or ray://HOST:PORT")
    return url.hostname, port


def check_reachable(address: str, timeout_s: float = CONNECT_TIMEOUT_S) -> None:
    """Fail fast on an address nothing listens on (Ray itself would retry for minutes)."""
    target = _host_port(address)
    if target is None:
        return
    try:
        with socket.create_connection(target, timeout=timeout_s):
            pass
    except OSError as e:
        reason = e.strerror or type(e).__name__
        raise BackendError(
            f"cannot reach the Ray cluster at {address!r}: {reason} (is `ray start --head` "
            "running there, and is the port open?)"
        ) from None


class RayBackend:
    """Runs tasks as Ray tasks, one CPU each, as a context manager that owns the connection.

    Args:
        address: ``None`` starts a private local instance, unless ``RAY_ADDRESS`` is set;
            ``auto``, ``HOST:PORT`` or ``ray://HOST:PORT`` joins an existing cluster.
        jobs: CPUs of a private local instance (a cluster uses all of its own).
        ship_code: upload this checkout's `core` package with the job (Ray's runtime_env
            ``py_modules``), so the workers need srlab's dependencies but not srlab itself.
    """

    def __init__(self, address: str | None = None, jobs: int = 1, ship_code: bool = False):
        if jobs < 1:
            raise ValueError("jobs must be >= 1")
        self.address = address or os.environ.get("RAY_ADDRESS") or None
        self.jobs = jobs
        self.ship_code = ship_code
        self._ray: ModuleType | None = None
        self._owned = False

    @property
    def where(self) -> str:
        """Where the tasks run, for people."""
        connected = self._ray is not None and self._ray.is_initialized()
        if connected and not self._owned:
            return f"the Ray this process was connected to ({self.cpus()} CPUs)"
        if self.address is None:
            return f"a local Ray instance with {self.jobs} CPUs"
        return f"Ray at {self.address}" + (f" ({self.cpus()} CPUs)" if connected else "")

    def __enter__(self) -> RayBackend:
        ray = import_ray()
        self._ray = ray
        if ray.is_initialized():
            return self
        if self.address is not None:
            check_reachable(self.address)
        kwargs: dict[str, Any] = {
            "include_dashboard": False,
            "log_to_driver": False,
            "configure_logging": True,
        }
        if self.ship_code:
            kwargs["runtime_env"] = {"py_modules": [str(Path(core.__file__).parent)]}
        try:
            if self.address is None:
                # A private instance: address="local" never joins a cluster left running here.
                # Its token-authentication notice is for clusters people share, not this one.
                ray.init(
                    address="local",
                    num_cpus=self.jobs,
                    object_store_memory=OBJECT_STORE_BYTES,
                    logging_level=logging.ERROR,
                    **kwargs,
                )
            else:
                ray.init(address=self.address, logging_level=logging.WARNING, **kwargs)
        except (ConnectionError, TimeoutError, OSError) as e:
            hint = (
                ""
                if os.environ.get("RAY_AUTH_MODE")
                else " (if the cluster uses token authentication, as `ray start` does by "
                "default, set RAY_AUTH_MODE=token and RAY_AUTH_TOKEN to what "
                "`ray get-auth-token` prints on its head)"
            )
            raise BackendError(f"cannot connect to Ray at {self.address!r}: {e}{hint}") from None
        except RuntimeError as e:  # e.g. the cluster runs another Ray or Python version
            raise BackendError(f"Ray: {e}") from None
        self._owned = True
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if self._owned and self._ray is not None:
            self._ray.shutdown()
        self._owned = False

    def cpus(self) -> int:
        """The CPUs of the cluster (at least 1)."""
        ray = self._connected()
        return max(1, int(ray.cluster_resources().get("CPU", 1)))

    def _connected(self) -> ModuleType:
        if self._ray is None or not self._ray.is_initialized():
            raise BackendError("the Ray backend is used outside its `with` block")
        return self._ray

    def run(self, tasks: Sequence[Task], fn: TaskFunction = run_task) -> Iterator[TaskResult]:
        """Run `fn` on every task, at most a few per CPU in flight, yielding results as done.

        A task that raises or whose worker dies (after Ray's retries of a lost worker, which
        are safe since tasks are pure) comes back as a failed result with its error.
        """
        ray = self._connected()
        remote = ray.remote(num_cpus=1)(fn)
        window = max(8, 4 * self.cpus())
        queue = list(reversed(tasks))
        in_flight: dict[Any, Task] = {}
        try:
            while queue or in_flight:
                while queue and len(in_flight) < window:
                    t = queue.pop()
                    in_flight[remote.remote(t)] = t
                done, _ = ray.wait(list(in_flight), num_returns=1)
                for ref in done:
                    task = in_flight.pop(ref)
                    try:
                        result = ray.get(ref)
                    except Exception as e:  # the task's or its worker's failure, kept with it
                        result = TaskResult(task, error=f"{type(e).__name__}: {e}")
                    yield result
        finally:
            # Interrupted (Ctrl-C, an error downstream): do not leave work on a shared cluster.
            for ref in in_flight:
                ray.cancel(ref, force=True)
