"""Who may open the 3D view, and on what: one-time tickets, exchanged for a view cookie.

A browser's websocket carries no `Authorization` header (the WebSocket API sets none, and
viser's page opens its socket from a worker, on its own URL's path, without the query),
but it does carry the view's cookies. So the API hands whoever may watch a run a ticket
(`issue`: the organiser for any run, a participant for their own), the view's page is
opened at `/run/<id>?ticket=<ticket>`, and the gate `redeem`s it once for a cookie that
the page's request and every socket it opens from then on (a reconnect included) bring
back: `session` tells what that cookie may watch.

A ticket lives `TICKET_S` and is good once; a cookie (`SESSION_S`) as long as a study's
session may take. Both live in this process only: after a restart the page asks for a
new ticket (a participant's page with its "3D view" link again). Shared by the service's
event loop (`issue`) and the gate's thread (`redeem`, `session`), hence the lock.
"""

from __future__ import annotations

import secrets
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from http import HTTPStatus

TICKET_S = 60.0
"""How long a ticket waits to be used."""
SESSION_S = 12 * 3600.0
"""How long the cookie a ticket was exchanged for stays good."""
MAX_PASSES = 10_000
"""Tickets or cookies held at once, at most: the oldest go first past it."""
PER_RUN = 8
"""Tickets, and cookies, for one run alone held at once, at most: the oldest of that run's
go first past it, so a participant asking again and again pushes out only their own."""


@dataclass(frozen=True, slots=True)
class Pass:
    """What a ticket, and the cookie it became, allows.

    Attributes:
        run: the one run it may watch; None for every run (the organiser's).
        organiser: its holder may reward and re-pace runs from the panel.
    """

    run: int | None
    organiser: bool


class PassRefused(Exception):
    """A ticket the gate does not take: its status (401, 403) and why."""

    def __init__(self, status: HTTPStatus, detail: str) -> None:
        super().__init__(detail)
        self.status = status
        self.detail = detail


class Passes:
    """The view's tickets and cookies (`clock` is monotonic seconds; tests pass their own)."""

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self.clock = clock
        self._lock = threading.Lock()
        self._tickets = _Table()
        self._sessions = _Table()

    def issue(self, granted: Pass) -> str:
        """A new ticket for `granted`, good once within `TICKET_S`."""
        ticket = secrets.token_urlsafe(24)
        with self._lock:
            self._tickets.put(ticket, granted, self.clock() + TICKET_S)
        return ticket

    def redeem(self, ticket: str, run: int | None) -> tuple[str, Pass]:
        """A cookie's value for `ticket` on the view of `run` (None: `/`), and what it allows.

        A ticket for one run is refused on another's URL and stays good (nothing changes).

        Raises:
            PassRefused: 401 for a ticket unknown, used or expired; 403 for another run's.
        """
        now = self.clock()
        with self._lock:
            held = self._tickets.get(ticket)
            if held is None or held[1] <= now:
                self._tickets.pop(ticket)
                raise PassRefused(
                    HTTPStatus.UNAUTHORIZED,
                    "this 3D view ticket is not good (used already, expired after "
                    f"{TICKET_S:g} s, or never issued here): ask for a new one",
                )
            granted = held[0]
            if granted.run is not None and granted.run != run:
                where = "/" if run is None else f"run {run}"
                raise PassRefused(
                    HTTPStatus.FORBIDDEN,
                    f"this 3D view ticket is for run {granted.run} only, not {where}",
                )
            self._tickets.pop(ticket)
            cookie = secrets.token_urlsafe(32)
            self._sessions.put(cookie, granted, now + SESSION_S)
        return cookie, granted

    def session(self, cookie: str | None) -> Pass | None:
        """What the view cookie `cookie` allows, or None (absent, unknown or expired)."""
        if not cookie:
            return None
        with self._lock:
            held = self._sessions.get(cookie)
            if held is None:
                return None
            if held[1] <= self.clock():
                self._sessions.pop(cookie)
                return None
            return held[0]


class _Table:
    """Passes by key, each with its end, bounded: `MAX_PASSES` in all, `PER_RUN` a run."""

    def __init__(self) -> None:
        self._held: dict[str, tuple[Pass, float]] = {}
        self._by_run: dict[int, list[str]] = {}

    def get(self, key: str) -> tuple[Pass, float] | None:
        return self._held.get(key)

    def pop(self, key: str) -> None:
        self._held.pop(key, None)  # its run's list keeps the key until it is next looked at

    def put(self, key: str, granted: Pass, until: float) -> None:
        if granted.run is not None:
            keys = [k for k in self._by_run.get(granted.run, ()) if k in self._held]
            while len(keys) >= PER_RUN:
                self._held.pop(keys.pop(0))
            self._by_run[granted.run] = [*keys, key]
        while len(self._held) >= MAX_PASSES:
            del self._held[next(iter(self._held))]  # the oldest (dicts keep their order)
        self._held[key] = (granted, until)


__all__ = ["PER_RUN", "SESSION_S", "TICKET_S", "Pass", "PassRefused", "Passes"]
