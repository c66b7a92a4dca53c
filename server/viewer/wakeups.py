"""viser's message buffers, woken safely when a scene message comes from another thread.

viser (1.1) lets any thread send scene messages, and srlab's do: each viewer's renderer
thread, and viser's own thread pool running our connect handler (a new client's scene).
`AsyncMessageBuffer.push` then calls the buffer's `asyncio.Event.set()` right there, on the
sending thread, and once more through the loop's `call_soon_threadsafe`. An `asyncio.Event`
is not thread-safe: `set()` walks the event's waiters while the loop's thread may be adding
or removing one, and in the suite that raised `RuntimeError: deque mutated during
iteration` in a connect handler, so the connecting browser got no view and the log a
traceback.

`LoopEvent` is an `asyncio.Event` whose `set()` from any thread but its loop's is handed to
the loop (`call_soon_threadsafe`), the one place its waiters are touched. Nothing reads the
buffers' events synchronously (viser's consumer waits, clears, then reads its counters),
and push's own thread-safe call wakes the waiters as before, so only the unsafe half of
the double set changes. `install()` makes viser build its buffers with these events; it
runs before the first `ViserServer` is made (`server/viewer/app.py`).
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import logging

from viser.infra import _infra
from viser.infra._async_message_buffer import AsyncMessageBuffer

log = logging.getLogger("srlab.viewer")


class LoopEvent(asyncio.Event):
    """An `asyncio.Event` any thread may set; its waiters are only ever touched on `loop`."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        super().__init__()
        self._home = loop

    def set(self) -> None:
        """Set the event: here if on its loop's thread, else handed to that loop."""
        try:
            running: asyncio.AbstractEventLoop | None = asyncio.get_running_loop()
        except RuntimeError:
            running = None
        if running is self._home:
            super().set()
            return
        # A closed loop has nobody left waiting: the same tolerance as viser's own calls.
        with contextlib.suppress(RuntimeError):
            self._home.call_soon_threadsafe(super().set)


@dataclasses.dataclass
class LoopSafeBuffer(AsyncMessageBuffer):
    """viser's message buffer with events its pushing threads cannot corrupt."""

    def __post_init__(self) -> None:
        self.message_event = LoopEvent(self.event_loop)
        self.flush_event = LoopEvent(self.event_loop)


def install() -> None:
    """Have viser build its message buffers as `LoopSafeBuffer`s (idempotent)."""
    current = getattr(_infra, "AsyncMessageBuffer", None)
    if current is LoopSafeBuffer:
        return
    if current is not AsyncMessageBuffer:
        # Another viser builds its buffers elsewhere: tests/server/viewer/test_viewer_wakeups.py
        # fails, and the view runs with viser's own events meanwhile.
        log.warning("viser's message buffers are not where srlab expects them")
        return
    _infra.AsyncMessageBuffer = LoopSafeBuffer  # type: ignore[attr-defined]


__all__ = ["LoopEvent", "LoopSafeBuffer", "install"]
