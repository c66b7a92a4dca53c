"""Slow clients are timed out: a request head and a request body each get `limit_s`.

uvicorn times out idle kept-alive connections (`timeout_keep_alive`) but not a client that
sends its request head one byte at a time, nor one that stops halfway through a body: both
held a connection (and, for a body, a request's task) open for as long as they liked.
`TimedH11Protocol` closes a connection whose request head has not arrived `limit_s` after
its first byte (or the connection's start); `BodyTimeout` answers 408 to a body that has
not arrived `limit_s` after the app began reading it.
"""

from __future__ import annotations

import asyncio
from typing import Any

from starlette.types import ASGIApp, Message, Receive, Scope, Send
from uvicorn.protocols.http.h11_impl import H11Protocol

from server.api.asgi import cut_off, send_error

DEFAULT_LIMIT_S = 10.0


class TimedH11Protocol(H11Protocol):
    """uvicorn's h11 protocol with a deadline on each request head."""

    head_timeout_s = DEFAULT_LIMIT_S

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._head_timer: asyncio.TimerHandle | None = None

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        """Start the first request's clock."""
        super().connection_made(transport)
        self._arm()

    def data_received(self, data: bytes) -> None:
        """Start the clock when a new request begins; stop it once its head is parsed."""
        before = self.cycle
        if self._head_timer is None and (before is None or before.response_complete):
            self._arm()
        super().data_received(data)
        if self.cycle is not before:
            self._disarm()

    def connection_lost(self, exc: Exception | None) -> None:
        """Forget the clock."""
        self._disarm()
        super().connection_lost(exc)

    def _arm(self) -> None:
        self._disarm()
        self._head_timer = self.loop.call_later(self.head_timeout_s, self._head_expired)

    def _disarm(self) -> None:
        if self._head_timer is not None:
            self._head_timer.cancel()
            self._head_timer = None

    def _head_expired(self) -> None:
        self._head_timer = None
        if not self.transport.is_closing():
            self.logger.warning("closed a connection whose request head was too slow")
            self.transport.close()


def timed_protocol(limit_s: float) -> type[TimedH11Protocol]:
    """`TimedH11Protocol` with its own limit (uvicorn takes a class, not an instance)."""
    return type("TimedH11Protocol", (TimedH11Protocol,), {"head_timeout_s": limit_s})


class _BodyTimedOut(Exception):
    pass


class BodyTimeout:
    """Answers 408 when a request body does not arrive within `limit_s` of the first read.

    Only the body is timed: once it is complete, the app may wait on `receive` (for the
    disconnect of an event stream) as long as it likes.
    """

    def __init__(self, app: ASGIApp, limit_s: float = DEFAULT_LIMIT_S) -> None:
        self.app = app
        self.limit_s = limit_s

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Time the body's reads."""
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        loop = asyncio.get_running_loop()
        deadline: float | None = None
        complete = False

        async def timed() -> Message:
            nonlocal deadline, complete
            if complete:
                return await receive()
            if deadline is None:
                deadline = loop.time() + self.limit_s
            try:
                async with asyncio.timeout_at(deadline):
                    message = await receive()
            except TimeoutError:
                raise _BodyTimedOut from None
            if message["type"] != "http.request" or not message.get("more_body", False):
                complete = True
            return message

        await cut_off(self.app, scope, timed, send, _BodyTimedOut, self._reject)

    async def _reject(self, send: Send) -> None:
        detail = f"the request body did not arrive within {self.limit_s:g} s"
        await send_error(send, 408, detail, [(b"connection", b"close")])
