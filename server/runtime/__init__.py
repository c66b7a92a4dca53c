"""Where the service's runs tick, and how the service reaches them.

- `host`: `RunHost`, every run's engine on one event loop, served by the closed message
  set of `core.engine.messages`.
- `runs`: `Runs` and `LiveRun`, the service's side: the books of which runs tick, each
  run's last `RunState`, the event streams' caps.
- `local` and `process`: the two links between them, the host on the service's loop
  (``SRLAB_ENGINES=local``) or in a process of its own (``process``).
- `reads`: what the routes read of a run (its public state, the KP inspector's query).
"""

from __future__ import annotations

import contextlib

from core.ports import RunStore
from server.config import Settings
from server.runtime.host import RunHost, RunLetGo, TooManyRunsError
from server.runtime.local import LocalLink
from server.runtime.process import EngineProcessError, ProcessLink
from server.runtime.reads import QUERIES
from server.runtime.runs import LiveRun, Runs, TooManyStreamsError


async def open_runs(settings: Settings, store: RunStore, stack: contextlib.AsyncExitStack) -> Runs:
    """The service's runs, on the host `settings.engines` names; let go with `stack`.

    `store` is the service's own storage. The engines' process opens its own from the
    settings (`database_url`).
    """
    runs = Runs(
        store,
        max_streams=settings.max_streams,
        max_streams_per_run=settings.max_streams_per_run,
        reaction_window_s=settings.reaction_window,
    )
    if settings.engines == "process":
        link = ProcessLink(runs)
        runs.link = link
        await link.start_process(settings.model_dump(include={"database_url", "max_runs"}))
        stack.push_async_callback(link.close)
    else:
        runs.link = LocalLink(runs, store, settings.max_runs, QUERIES)
    stack.push_async_callback(runs.shutdown)
    return runs


__all__ = [
    "EngineProcessError",
    "LiveRun",
    "RunHost",
    "RunLetGo",
    "Runs",
    "TooManyRunsError",
    "TooManyStreamsError",
    "open_runs",
]
