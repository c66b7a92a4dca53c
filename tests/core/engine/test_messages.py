"""`perform`: each command with the status check that goes with it."""

from __future__ import annotations

import asyncio

import pytest
from enginehelpers import CATALOG, drive, fast
from fakes import InMemoryRunStore

from core.engine import RunEngine
from core.engine.messages import Pause, SetRate, Stop, perform
from core.errors import RunStateError


def test_a_fast_run_refuses_a_rate_and_a_control_outside_its_statuses() -> None:
    engine = RunEngine.create(fast("kp", 1, 10_000), InMemoryRunStore(CATALOG), catalog=CATALOG)
    seen: list[str] = []

    async def script(e: RunEngine) -> None:
        with pytest.raises(RunStateError, match="is created"):
            await perform(e, Pause())  # not running yet: refused by its status
        while e.status.value != "running":
            await asyncio.sleep(0.001)
        with pytest.raises(RunStateError, match="is fast: it has no rate"):
            await perform(e, SetRate(5.0))
        seen.append("refused")
        await perform(e, Stop())

    assert asyncio.run(drive(engine, script)).value == "stopped"
    assert seen == ["refused"]
