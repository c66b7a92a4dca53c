"""The in-process link: the runs' host on the service's own event loop.

`create_app`'s default (``SRLAB_ENGINES=local``), the API tests' and benches': the same
messages as the process link carries, handed over as they are. The service's loop then
paces the ticks too, so a long pass of it (a burst of requests) delays them: `srlab serve`
runs its host in a process of its own (`server.runtime.process`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from core.brain.catalog import Catalog
from core.engine import RunEngine, Subscription
from core.engine.messages import Command, Query, RunState
from core.ports import RunSpec, RunStore
from server.runtime.host import QueryHandler, RunHost
from server.runtime.runs import Runs


class LocalLink:
    """`Runs`' link to a `RunHost` on the same loop (`server.runtime.runs.Link`)."""

    def __init__(
        self,
        runs: Runs,
        store: RunStore,
        max_runs: int,
        queries: Mapping[type[Query], QueryHandler],
    ) -> None:
        self.runs = runs
        self.host = RunHost(store, max_runs, self, queries)
        self._feeds: dict[Subscription, Any] = {}

    # --- the host's outlet ----------------------------------------------------------

    def run_started(self, run_id: int, spec: RunSpec, state: RunState, catalog: Catalog) -> None:
        """Hand the start on."""
        self.runs.heard_started(run_id, spec, state, catalog)

    def run_state(self, run_id: int, state: RunState, catalog: Catalog | None) -> None:
        """Hand the state on."""
        self.runs.heard_state(run_id, state, catalog)

    def run_ended(self, run_id: int, state: RunState, let_go: bool) -> None:
        """Hand the end on."""
        self.runs.heard_ended(run_id, state, let_go)

    # --- the link -------------------------------------------------------------------

    def engine(self, run_id: int) -> RunEngine | None:
        """A run's engine, for tests and benches that look inside it."""
        return self.host.engine(run_id)

    async def start(self, run_id: int) -> None:
        """Start a stored run."""
        await self.host.start(run_id)

    async def started(self, run_id: int, timeout_s: float) -> None:
        """Wait until a started run ticks."""
        await self.host.started(run_id, timeout_s)

    async def request(self, run_id: int, message: Command | Query) -> Any:
        """The host's answer."""
        return await self.host.request(run_id, message)

    def subscribe(
        self, run_id: int, maxsize: int, tick_hz: float, *, next_start: bool = True
    ) -> Subscription:
        """A subscription fed by the host's forwarder."""
        outer = Subscription(maxsize, tick_hz)
        inner = Subscription(maxsize, tick_hz)

        async def deliver(events: list[object]) -> None:
            for event in events:
                outer.offer(event)

        def closed(_: object) -> None:
            outer.close()
            self._feeds.pop(outer, None)

        feed = self.host.subscribe(run_id, inner, deliver, next_start=next_start)
        self._feeds[outer] = feed
        feed.add_done_callback(closed)
        return outer

    def unsubscribe(self, sub: Subscription) -> None:
        """Stop the feed and close the subscription."""
        sub.close()
        feed = self._feeds.pop(sub, None)
        if feed is not None:
            feed.cancel()

    def running(self) -> int:
        """The host's count."""
        return self.host.running()

    def outage(self) -> str | None:
        """None: the runs store through the service's storage, which health checks."""
        return None

    def interrupt_all(self) -> None:
        """Every run ends at its next boundary, as interrupted."""
        self.host.interrupt_all()

    async def shutdown(self, grace_s: float) -> None:
        """Interrupt every run and wait for them."""
        await self.host.shutdown(grace_s)

    async def close(self) -> None:
        """Nothing to let go: the host is this loop's."""
