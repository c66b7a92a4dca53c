"""Token buckets for reward injection: one per trainer and one per run."""

from __future__ import annotations

import hashlib
import ipaddress
import time
from collections.abc import Callable

from core.studies import Participant

IDLE_S = 60.0
"""A bucket untouched this long is full again, so it may be forgotten."""


def client_key(
    address: str | None, token: str | None = None, *, participant: Participant | None = None
) -> str:
    """Who a reward comes from, for its rate limit.

    A study's participant is their pseudonym, each with a limit of their own.
    A bearer token is the trainer's identity; without one, the address is, with an IPv6
    /64 (what one host or one home gets) as one client and every loopback address as one:
    otherwise a client spreads its rewards over 127.0.0.0/8 or its /64 and escapes the
    limit.
    """
    if participant is not None:
        return "participant:" + participant.pseudonym[:16]
    if token:
        return "token:" + hashlib.sha256(token.encode()).hexdigest()[:16]
    if not address:
        return "unknown"
    try:
        ip = ipaddress.ip_address(address)
    except ValueError:
        return address  # a name a test transport gives, e.g. "testclient"
    if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
        ip = ip.ipv4_mapped
    if ip.is_loopback:
        return "loopback"
    if isinstance(ip, ipaddress.IPv6Address):
        return str(ipaddress.IPv6Network((ip, 64), strict=False))
    return str(ip)


class _Buckets:
    def __init__(self, rate: float, burst: int, clock: Callable[[], float]) -> None:
        self.rate = rate
        self.burst = float(burst)
        self._clock = clock
        self._buckets: dict[str, tuple[float, float]] = {}

    def tokens(self, key: str, now: float) -> float:
        tokens, last = self._buckets.get(key, (self.burst, now))
        return min(self.burst, tokens + (now - last) * self.rate)

    def set(self, key: str, tokens: float, now: float) -> None:
        self._buckets[key] = (tokens, now)
        if len(self._buckets) > 10_000:  # forget idle clients
            self._buckets = {k: v for k, v in self._buckets.items() if now - v[1] < IDLE_S}


class RateLimiter:
    """`rate` events per second per client, with bursts of up to `burst`.

    With `run_rate`, each run also takes at most `run_rate` per second (bursts of
    `run_burst`) from all its clients together; an event counts against both buckets
    only when both allow it.
    """

    def __init__(
        self,
        rate: float,
        burst: int,
        clock: Callable[[], float] = time.monotonic,
        *,
        run_rate: float | None = None,
        run_burst: int | None = None,
    ) -> None:
        self.rate = rate
        self.burst = float(burst)
        self.run_rate = run_rate
        self._clock = clock
        self._clients = _Buckets(rate, burst, clock)
        self._runs = (
            None
            if run_rate is None
            else _Buckets(run_rate, run_burst if run_burst is not None else burst, clock)
        )

    def allow(self, key: str, run: int | None = None) -> float:
        """0 when the event may go ahead, else the seconds until it may."""
        now = self._clock()
        tokens = self._clients.tokens(key, now)
        wait = 0.0 if tokens >= 1.0 else (1.0 - tokens) / self.rate
        run_tokens = 0.0
        runs = self._runs if run is not None else None
        if runs is not None:
            run_tokens = runs.tokens(str(run), now)
            if run_tokens < 1.0:
                wait = max(wait, (1.0 - run_tokens) / runs.rate)
        if wait > 0:
            self._clients.set(key, tokens, now)
            if runs is not None:
                runs.set(str(run), run_tokens, now)
            return wait
        self._clients.set(key, tokens - 1.0, now)
        if runs is not None:
            runs.set(str(run), run_tokens - 1.0, now)
        return 0.0

    def limited_by_run(self, run: int) -> bool:
        """Whether the run's own bucket is what holds its rewards back now."""
        return self._runs is not None and self._runs.tokens(str(run), self._clock()) < 1.0
