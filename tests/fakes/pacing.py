"""`ManualPacer`: a realtime engine's clock that moves only when the test says."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

import numpy as np

from core.engine.pacing import Wake

FloatArray = np.ndarray[Any, np.dtype[np.float64]]


class ManualPacer:
    """A realtime engine's clock that moves only when the test says (`Pacer`).

    A sleep ends when the clock is advanced past its end or when the engine's wake event
    is set, never by itself: a test of waking up cannot pass by waiting long enough.
    """

    def __init__(self, start: float = 0.0) -> None:
        self.time = start
        self._sleepers: list[tuple[float, asyncio.Event]] = []
        self._changed = asyncio.Event()

    def now(self) -> float:
        return self.time

    @property
    def sleeping(self) -> int:
        """How many sleeps are going on."""
        return len(self._sleepers)

    async def sleep(self, seconds: float, wake: Wake) -> None:
        if wake.is_set() or seconds <= 0:
            return
        entry = (self.time + seconds, asyncio.Event())
        self._sleepers.append(entry)
        self._changed.set()
        waits = [asyncio.ensure_future(wake.wait()), asyncio.ensure_future(entry[1].wait())]
        try:
            await asyncio.wait(waits, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for w in waits:
                w.cancel()
            self._sleepers.remove(entry)
            self._changed.set()

    def advance(self, seconds: float) -> None:
        """Move the clock on, ending the sleeps that are over."""
        self.time += seconds
        for until, done in self._sleepers:
            if until <= self.time + 1e-12:
                done.set()

    async def until(self, check: Callable[[], bool]) -> None:
        """Wait (without moving the clock) until `check()` holds after a sleep began or ended."""
        while not check():
            self._changed.clear()
            await self._changed.wait()
