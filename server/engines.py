"""The service's run engines: created, started, paused and stopped over HTTP."""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Iterable

from core.brain.catalog import Catalog
from core.brain.network import Association
from core.engine import Engine
from core.errors import RunStateError, StorageError
from core.ports import NetworkPair, RunSpec, RunStatus, RunStore
from core.setup import Setup

log = logging.getLogger("srlab.engines")

ACTIVE = (RunStatus.RUNNING, RunStatus.PAUSED)


class TooManyRunsError(RunStateError):
    """The service runs as many runs as it may."""


class EngineManager:
    """Owns one `Engine` per run that was created or started in this process."""

    def __init__(self, store: RunStore, catalog: Catalog, max_runs: int) -> None:
        self.store = store
        self.catalog = catalog
        """The shipped catalogue under the default sensor definition (names only: each
        run's engine loads its own definition's, see `core.setup.Setup`)."""
        self.max_runs = max_runs
        self._engines: dict[int, Engine] = {}
        self._tasks: dict[int, asyncio.Task[RunStatus]] = {}

    def get(self, run_id: int) -> Engine | None:
        """The engine of a run, if this process has one."""
        return self._engines.get(run_id)

    def engines(self) -> Iterable[Engine]:
        """Every engine this process has."""
        return self._engines.values()

    def running(self) -> int:
        """How many runs are ticking or paused."""
        return sum(1 for t in self._tasks.values() if not t.done())

    def create(self, spec: RunSpec, network: tuple[NetworkPair, ...] | None) -> Engine:
        """A new stored run (status created); `network` overrides the condition's.

        It runs in the spec's world preset and sensor definition (an unknown name raises
        `UnknownNameError`).
        """
        assoc = None
        if network is not None:
            cat = Setup(spec.world, spec.sensors).catalog()
            assoc = tuple(
                Association(
                    cat.stimulus(p.stimulus).id,
                    cat.behaviour(p.behaviour).id,
                    p.strength,
                    p.source,  # type: ignore[arg-type]
                    p.locked,
                )
                for p in network
            )
        engine = Engine.create(spec, self.store, network=assoc)
        self._engines[engine.run_id] = engine
        return engine

    def prepare(self, run_id: int) -> Engine:
        """Rebuild a stored run's engine from its checkpoint (blocking: call in a thread)."""
        task = self._tasks.get(run_id)
        if task is not None and not task.done():
            engine = self._engines[run_id]
            raise RunStateError(f"run {run_id} is {engine.status.value}")
        if task is not None:
            self._settle_status(self._engines[run_id])
        engine = Engine.restore(run_id, self.store)  # in its stored world and definition
        self._engines[run_id] = engine
        return engine

    def _settle_status(self, engine: Engine) -> None:
        """Store how a run this process ran ended, if storage still says it is going.

        A run that failed because storage failed often could not store that either. This
        process is the run's only writer, so its own view is the truth.
        """
        if self.store.load_run(engine.run_id).status in ACTIVE:
            final = engine.status if engine.status not in ACTIVE else RunStatus.INTERRUPTED
            self.store.set_status(engine.run_id, final, engine.error)

    def start(self, run_id: int) -> Engine:
        """Start a created or prepared run (on the event loop)."""
        engine = self._engines.get(run_id)
        task = self._tasks.get(run_id)
        if engine is None:
            raise RunStateError(f"run {run_id} is not prepared")
        if task is not None and not task.done():
            raise RunStateError(f"run {run_id} is {engine.status.value}")
        if self.running() >= self.max_runs:
            raise TooManyRunsError(
                f"{self.max_runs} runs are running already (SRLAB_MAX_RUNS): stop one first"
            )
        self._tasks[run_id] = asyncio.create_task(self._run(engine), name=f"run {run_id}")
        return engine

    async def started(self, run_id: int, timeout_s: float = 5.0) -> None:
        """Wait until a started run ticks (or has already ended)."""
        engine = self._engines[run_id]
        task = self._tasks[run_id]
        async with asyncio.timeout(timeout_s):
            while engine.status in (RunStatus.CREATED, RunStatus.INTERRUPTED, RunStatus.STOPPED):
                if task.done():
                    return
                await asyncio.sleep(0.001)

    async def _run(self, engine: Engine) -> RunStatus:
        try:
            return await engine.run()
        except asyncio.CancelledError:
            raise
        except StorageError as e:
            # An outage, not a bug: its message says what failed, a traceback adds nothing.
            log.error("run %s failed: %s", engine.run_id, e)
            return RunStatus.FAILED
        except Exception:
            log.exception("run %s failed", engine.run_id)
            return RunStatus.FAILED

    def interrupt_all(self) -> None:
        """Ask every run to end at its next tick boundary, as interrupted (resumable).

        Its event streams end with it, with a last status event; those of a run that is not
        ticking (created, finished) end at once.
        """
        for run_id, engine in self._engines.items():
            engine.interrupt()
            task = self._tasks.get(run_id)
            if task is None or task.done():
                engine.close_subscriptions()

    async def shutdown(self, grace_s: float = 5.0) -> None:
        """Interrupt every run, wait for them, cancel stragglers (runs stay resumable)."""
        self.interrupt_all()
        tasks = [t for t in self._tasks.values() if not t.done()]
        if tasks:
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(grace_s):
                    await asyncio.gather(*tasks, return_exceptions=True)
            for t in tasks:
                if not t.done():
                    t.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)
