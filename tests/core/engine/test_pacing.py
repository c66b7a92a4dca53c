"""The realtime pacer's sleep: cut short by a wake-up, ended by its timer, leaving nothing."""

from __future__ import annotations

import asyncio

from core.engine import MonotonicPacer, Wake

LONG_S = 60.0
"""A sleep no test waits out: if it ends, something ended it."""


def test_a_wake_up_ends_a_long_sleep_and_leaves_no_waiter() -> None:
    async def main() -> int:
        wake = Wake()
        sleeping = asyncio.create_task(MonotonicPacer().sleep(LONG_S, wake))
        await asyncio.sleep(0)  # it sleeps
        wake.set()
        await asyncio.wait_for(sleeping, 30)  # a hang guard: only the wake-up ends it
        return len(wake._waiters)

    assert asyncio.run(main()) == 0


def test_a_sleep_ends_by_its_timer_and_forgets_its_waiter() -> None:
    async def main() -> tuple[bool, int]:
        wake = Wake()
        for _ in range(100):
            await MonotonicPacer().sleep(0.0, wake)
        return wake.is_set(), len(wake._waiters)

    assert asyncio.run(main()) == (False, 0)


def test_a_set_wake_ends_the_next_sleep_at_once_until_cleared() -> None:
    async def main() -> bool:
        wake = Wake()
        wake.set()
        await asyncio.wait_for(MonotonicPacer().sleep(LONG_S, wake), 30)
        wake.clear()
        sleeping = asyncio.create_task(MonotonicPacer().sleep(LONG_S, wake))
        await asyncio.sleep(0.01)
        pending = not sleeping.done()
        sleeping.cancel()
        return pending

    assert asyncio.run(main())


def test_a_cancelled_sleep_forgets_its_waiter() -> None:
    async def main() -> int:
        wake = Wake()
        sleeping = asyncio.create_task(MonotonicPacer().sleep(LONG_S, wake))
        await asyncio.sleep(0)
        sleeping.cancel()
        await asyncio.gather(sleeping, return_exceptions=True)
        return len(wake._waiters)

    assert asyncio.run(main()) == 0
